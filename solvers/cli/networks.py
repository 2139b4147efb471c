"""The verbs of sensor networks: calibrate and tdoa (measurement files and recordings)."""
from __future__ import annotations

import argparse
import json
import math
import sys

from solvers.cli.common import UserError, _check_outputs, _integer_at_least


def _positive_float(option: str):
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{option} takes a number, got {text!r}") from None
        if not (value > 0 and value < float("inf")):
            raise argparse.ArgumentTypeError(f"{option} must be a finite number > 0, got {text}")
        return value
    return parse


def _add_recording_options(p: argparse.ArgumentParser) -> None:
    """The options of a recording's analysis (solvers.audio.TdoaOptions), the same for every verb."""
    from solvers.audio import TdoaOptions

    d = TdoaOptions()
    g = p.add_argument_group("recordings (WAV, FLAC, ...: solvers.audio)")
    g.add_argument("--speed", type=_positive_float("--speed"), default=d.speed, metavar="M/S",
                   help=f"speed of sound in m/s; the matrix is in metres (default {d.speed:g})")
    g.add_argument("--max-distance", type=_positive_float("--max-distance"), default=d.max_distance, metavar="M",
                   help=f"largest distance between two microphones in m: the lags searched (default {d.max_distance:g})")
    g.add_argument("--threshold", type=_positive_float("--threshold"), default=d.threshold_db, metavar="DB",
                   help=f"an event starts this many dB above the background (default {d.threshold_db:g})")
    g.add_argument("--min-support", type=_integer_at_least("--min-support", 1), default=d.min_support, metavar="N",
                   help="an entry is kept when at least N other channels agree with its arrival time "
                   f"(default {d.min_support})")
    g.add_argument("--signal", metavar="FILE", help="the emitted sound (one channel, the recording's rate; a sweep, "
                   "say): every channel is first correlated with it (a matched filter), so that long sounds' arrivals "
                   "are compressed into pulses; each channel's arrival is then its own earliest strong pulse, and no guided "
                   "pass follows (default: none, the sound is not known)")
    g.add_argument("--no-guide", action="store_true", help="keep the first pass's matrix: no calibration of it "
                   "guiding a second pass (solvers.audio_guided)")


def _tdoa_options(args: argparse.Namespace):
    from solvers.audio import TdoaOptions
    from solvers.recording import read_signal

    signal, rate = read_signal(args.signal) if args.signal else (None, None)
    return TdoaOptions(speed=args.speed, max_distance=args.max_distance, threshold_db=args.threshold,
                       min_support=args.min_support, signal=signal, signal_rate=rate)


def _guide(args: argparse.Namespace):
    """The guided pass's options (None with --no-guide)."""
    from solvers.audio_guided import GuideOptions

    return None if args.no_guide else GuideOptions()


def _recording_reader(args: argparse.Namespace):
    """How `calibrate` turns a recording into its matrix: the first pass, then (unless --no-guide) the pass guided
    by a calibration in --dim with --seed (solvers.audio_guided.tdoa_guided)."""
    from solvers.audio_guided import tdoa_guided

    options = _tdoa_options(args)  # --signal read before the recording's analysis

    def analyse(recording):
        return tdoa_guided(recording, options, dim=args.dim, seed=args.seed, guide=_guide(args),
                           progress=_progress).matrix

    return analyse


def _progress(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def _add_tdoa(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "tdoa", help="the measurement matrix of a recording: sound events, GCC-PHAT time differences",
        description="Detect the sound events of RECORDING (one multichannel WAV/FLAC file, or one file per "
        "microphone) by their energy onsets and measure each channel's arrival time against the event's loudest "
        "channel by GCC-PHAT of every channel pair (sub-sample), without knowing the emitted sound; an arrival "
        "fewer than --min-support other channels agree with is left missing. Then (unless --no-guide) calibrates that "
        "matrix (--dim, sigma estimated) and, when the calibration places every receiver with status ok or "
        "uncontrolled, measures again with each pair's peaks searched within a few samples of the difference its "
        "positions predict (solvers.audio_guided). Writes the matrix calibrate reads: "
        "one row per channel, one column per event, arrival time x speed of sound in metres (solvers.audio).")
    p.add_argument("recording", nargs="+", metavar="RECORDING", help="a multichannel audio file, or one file per channel")
    p.add_argument("--out", metavar="FILE.csv", help="write the matrix to FILE.csv (default: standard output)")
    p.add_argument("--confidence", metavar="FILE.csv", help="also write each entry's support (how many other channels "
                   "agree with it) in the same layout")
    p.add_argument("--dim", type=int, choices=(2, 3), default=3, help="dimension of the calibration that guides the "
                   "second pass: 3 (default; microphones in a room) or 2")
    _add_recording_options(p)
    p.set_defaults(func=cmd_tdoa)


def cmd_tdoa(args: argparse.Namespace) -> int:
    import numpy as np

    from solvers.recording import read_recording
    from solvers.audio_guided import tdoa_guided
    from solvers.calibrate_io import Measurements, format_matrix, recording_measurements

    _check_outputs({"--out": (args.out, None), "--confidence": (args.confidence, None)}, args.recording)
    options = _tdoa_options(args)
    recording = read_recording(args.recording)
    with _progress_on_stderr("solvers.calibration", after=2.0 if sys.stderr.isatty() else 30.0):
        tm = tdoa_guided(recording, options, dim=args.dim, guide=_guide(args), progress=_progress).matrix
    for note in tm.notes:  # the reader's and the analysis's
        _progress(f"tdoa: {note}")
    meas = recording_measurements(tm)
    kept = int(np.isfinite(tm.F).sum())
    about = (f"tdoa-workbench tdoa {recording.source}: {len(tm.channels)} channels at {tm.rate} Hz, "
             f"{recording.seconds:.1f} s, {len(tm.events)} events, speed of sound {tm.speed:g} m/s; values in m")
    summary = (f"{kept}/{tm.F.size} entries, {tm.F.size - kept} left missing (support < {args.min_support}, or an "
               "event whose channels disagree)")
    text = format_matrix(meas, (about, summary))
    try:
        if args.out:
            with open(args.out, "w", encoding="utf-8") as handle:
                handle.write(text)
        else:
            sys.stdout.write(text)
        if args.confidence:
            with open(args.confidence, "w", encoding="utf-8") as handle:
                handle.write(format_matrix(Measurements(tm.confidence, tm.channels, tm.events, tm.source),
                                           (about, "support: how many other channels agree with each arrival")))
    except OSError as e:
        raise UserError(f"cannot write {e.filename}: {e.strerror}") from None
    _progress(f"tdoa: {len(tm.events)} events, {summary}" + (f"; wrote {args.out}" if args.out else ""))
    return 0


def _add_calibrate(sub: argparse._SubParsersAction) -> None:
    from solvers.calibrate_io import DELIMITERS, HEADERS

    p = sub.add_parser(
        "calibrate", help="calibrate a network from a CSV of TDOA measurements (missing entries, outliers)",
        description="Calibrate receivers, transmitters and transmitter offsets from MEAS.csv ('-': standard input): "
        "one row per receiver, one column per transmitter (--transpose for the other way round), f_ij = |r_i - s_j| + "
        "o_j: distances, i.e. arrival times or time differences multiplied by the propagation speed, all in one unit "
        "(name it with --units); o_j is transmitter j's unknown offset. An empty cell, NaN, NA, N/A or #N/A is a "
        "missing measurement; # starts a comment; the delimiter (TAB, ';', ',' or spaces) is detected; a first row / "
        "column of names is detected (transmitter names may be numbers: 'rx,1,2,3'; --header overrides). "
        "LO-RANSAC over the minimal solvers, extension and robust refinement, a least-squares adjustment with its tests (solvers.calibration). Exit status 0 "
        "when the status is ok (every check passed), 1 for any other status (partial, uncontrolled, inconsistent, "
        "ambiguous, unconverged, failed: the first line says why), 2 for a malformed file or option.")
    p.add_argument("file", nargs="+", metavar="MEAS.csv", help="measurement matrix (CSV; - reads standard input), or a "
                   "recording: one multichannel audio file or one file per channel, analysed as tdoa does")
    p.add_argument("--sigma", type=float, help="noise standard deviation of the measurements, > 0, in the unit of "
                   "the file (default: estimated)")
    p.add_argument("--units", metavar="NAME", help="name of the file's distance unit (m, mm, ...), printed with the "
                   "numbers (default: none)")
    p.add_argument("--delimiter", metavar="D", help=f"cell delimiter: {', '.join(DELIMITERS)} (default: detected)")
    p.add_argument("--header", choices=HEADERS, default="auto", help="which of the first row (transmitter names) and "
                   "first column (receiver names) hold names (default: auto: names when the first row / column holds text, an "
                   "empty corner cell, distinct integers as transmitter names or a row index; docs/calibrate.md)")
    p.add_argument("--transpose", action="store_true", help="the file has one row per transmitter and one column "
                   "per receiver")
    p.add_argument("--oriented", action="store_true", help="the rows are receivers as stated (with --transpose: "
                   "the columns; --transpose implies it): a transposed matrix that fits about as well is a note, not "
                   "status ambiguous")
    p.add_argument("--dim", type=int, choices=(2, 3), default=2, help="2: a network in the plane (default); 3: in "
                   "space (gauge r1 = 0, r2 on +x, r3 in the xy half-plane y > 0; the mirror z -> -z is undecidable)")
    p.add_argument("--seed", type=int, default=0, help="seed of the random sampling (default 0)")
    p.add_argument("--json", action="store_true", help="print the result as one JSON object")
    p.add_argument("--out", metavar="FILE.json", help="also write the JSON result to FILE.json")
    p.add_argument("--plot", metavar="FILE.png", help="draw the map (rejected measurements dashed red; 3D: three "
                   "projections) to FILE.png (or .pdf, .svg, ...)")
    p.add_argument("--anchors", metavar="FILE.csv", help="known positions of some nodes with their std (a header "
                   "node,x,y[,z],std, then one row per node: a receiver or transmitter name, r:NAME or s:NAME when both "
                   "have it): the result is given in their frame, its uncertainty carried (solvers.calibration.frame)")
    p.add_argument("--anchor-fit", choices=("rigid", "similarity"), default="rigid", help="with --anchors: the "
                   "transform fitted to them, rigid (default) or similarity (also a scale: a wrong speed or unit)")
    p.add_argument("--csv", metavar="FILE.csv", help="also write the nodes (coordinates, offsets, standard deviations "
                   "per coordinate) to FILE.csv")
    _add_recording_options(p)
    p.set_defaults(func=cmd_calibrate)


class _progress_on_stderr:
    """Show a library logger's INFO records on stderr, with the elapsed time, once a call has run `after`
    seconds (a quick call prints nothing); the handler is removed again on exit."""

    def __init__(self, name: str, after: float = 2.0):
        import logging
        import time

        self.logger, self.after, self.start = logging.getLogger(name), after, time.time()
        start = self.start

        class Elapsed(logging.Formatter):
            def format(self, record) -> str:
                return f"[{record.created - start:6.1f} s] {super().format(record)}"

        self.handler = logging.StreamHandler(sys.stderr)
        self.handler.setFormatter(Elapsed("%(message)s"))
        self.handler.addFilter(lambda record: record.created - start >= after)

    def __enter__(self):
        import logging

        self.level = self.logger.level
        self.logger.setLevel(logging.INFO)
        self.logger.addHandler(self.handler)
        return self

    def __exit__(self, *exc) -> None:
        self.logger.removeHandler(self.handler)
        self.logger.setLevel(self.level)


def cmd_calibrate(args: argparse.Namespace) -> int:
    import numpy as np

    from solvers.recording import is_recording
    from solvers.calibrate_io import (MeasurementFileError, plot_calibration, plot_formats, read_input, report_dict,
                                      write_json, write_nodes_csv)

    if args.sigma is not None and not (args.sigma > 0 and math.isfinite(args.sigma)):
        why = "the noise of real measurements is never zero" if args.sigma == 0 else "it is a standard deviation"
        raise UserError(f"--sigma must be a finite number > 0, got {args.sigma:g}: {why}; omit --sigma to estimate it")
    if args.units is not None and (not args.units.strip() or not args.units.isprintable()):
        raise UserError(f"--units {args.units!r}: give a printable name such as m or mm")
    _check_outputs({"--out": (args.out, None), "--plot": (args.plot, plot_formats() if args.plot else None),
                    "--csv": (args.csv, None)}, args.file + ([args.anchors] if args.anchors else []))
    try:
        with _progress_on_stderr("solvers.calibration", after=2.0 if sys.stderr.isatty() else 30.0):
            meas = read_input(args.file, delimiter=args.delimiter, header=args.header, analyse=_recording_reader(args),
                              progress=_progress)
    except MeasurementFileError as e:
        raise UserError(str(e)) from None
    # the solvers and the pipeline only now: options, outputs and the file are checked first (a second, not three)
    from solvers.api import select_solver
    from solvers.calibration import CalibrationOptions, calibrate
    from solvers.calibration.adjustment import enough_data
    from solvers.calibration.frame import anchor_frame, read_anchors

    if args.transpose:
        meas = meas.transposed()
    recorded = is_recording(args.file[0])
    if args.units is None and recorded:
        args.units = "m"  # tdoa_matrix's unit
    m, n = meas.F.shape

    def solvable(rows: int, cols: int) -> bool:
        if args.dim == 3:  # enough nodes and entries for the unknowns (the 3D pipeline needs no fixed block)
            return enough_data(rows, cols, rows * cols, 3)
        try:
            select_solver(rows, cols)
        except ValueError:
            return False
        return True

    def count(k: int, what: str) -> str:
        return f"{k} {what}" + ("" if k == 1 else "s")

    layout = (f"{count(m, 'row')} (receivers) x {count(n, 'column')} (transmitters)" if not args.transpose else
              f"with --transpose, {count(m, 'column')} (receivers) x {count(n, 'row')} (transmitters)")
    short = _too_few(m, n, int(np.isfinite(meas.F).sum()), args.dim)
    # a file's shape is refused before any computing; a recording's matrix is what its analysis found (too few
    # events is a result: the calibration says "failed" and why, exit 1, as tdoa's guided pass does)
    if short and not recorded and not solvable(n, m):
        raise UserError(f"{meas.source}: {layout} cannot be calibrated in {args.dim}D: {short}")
    if not solvable(m, n) and solvable(n, m):
        advice = ("the file looks transposed: if its rows are transmitters, give --transpose" if not args.transpose
                  else "drop --transpose if the file's rows are receivers")
        raise UserError(f"{meas.source}: {layout} cannot be calibrated (too few receivers or transmitters for every "
                        f"solver), but {n} receivers x {m} transmitters can: {advice}")
    anchors = read_anchors(args.anchors, meas.receivers, meas.transmitters, args.dim) if args.anchors else None
    options = CalibrationOptions(orientation_given=bool(args.oriented or args.transpose))
    # progress after 2 s on a terminal; into a pipe or a log only for a call that is long by any measure
    with _progress_on_stderr("solvers.calibration", after=2.0 if sys.stderr.isatty() else 30.0):
        result = calibrate(meas.F, sigma=args.sigma, dim=args.dim, seed=args.seed, options=options)
    if anchors is not None and result.status != "failed":
        result = anchor_frame(result, anchors, args.anchor_fit)
    report = report_dict(result, meas, args.units)
    if args.csv and result.status != "failed":
        try:
            write_nodes_csv(result, args.csv, meas, args.units)
        except OSError as e:
            raise UserError(f"cannot write {args.csv}: {e.strerror}") from None
    if args.out:
        try:
            write_json(report, args.out)
        except OSError as e:
            raise UserError(f"cannot write {args.out}: {e.strerror}") from None
    if args.plot:
        if result.status == "failed":
            print(f"no plot: {result.message}", file=sys.stderr)
        else:
            try:
                plot_calibration(result, args.plot, meas, units=args.units)
            except OSError as e:
                raise UserError(f"cannot write {args.plot}: {e.strerror}") from None
    if args.json:
        print(json.dumps(report))
    else:
        _print_calibration(result, meas, args.units)
    return 0 if result.status == "ok" else 1


def _too_few(m: int, n: int, entries: int, dim: int) -> str:
    """What an m x n measurement matrix with this many measured entries lacks for any calibration in dim
    dimensions ('' when nothing: solvers.calibration.adjustment.enough_data), in the pipeline's words."""
    from solvers.calibration.adjustment import min_measurements, n_unknowns

    need_r, need_t = min_measurements(dim)
    if m < need_t:
        return (f"too few receivers ({m}): each transmitter is placed from >= {need_t} receivers, so a {dim}D network "
                f"needs >= {need_t} receivers and >= {need_r} transmitters")
    if n < need_r:
        return (f"too few transmitters ({n}): each receiver is placed from >= {need_r} transmitters, so a {dim}D network "
                f"needs >= {need_t} receivers and >= {need_r} transmitters")
    if entries < n_unknowns(m, n, dim):
        return f"too few measurements ({entries}) for the {n_unknowns(m, n, dim)} unknowns of the network"
    return ""


def _print_calibration(result, meas, units: str | None = None) -> None:
    print(result.message)
    unit = f" {units}" if units else ""
    if result.frame is not None:
        fr = result.frame
        test = ("not tested (no redundancy)" if fr["critical"] is None else
                f"{fr['statistic']:.4g} vs {fr['critical']:.4g} ({fr['dof']} degrees of freedom): "
                f"{'passed' if fr['passed'] else 'FAILED'}")
        worst = max(fr["anchors"], key=lambda a: a["residual_std"])
        print(f"frame: {len(fr['anchors'])} anchors of {fr['source']}, {fr['fit']} fit (scale {fr['scale']:.6g}); test "
              f"{test}; largest anchor residual {worst['name']} {worst['residual_std']:.2g} std")
    if result.status != "failed":
        print(f"sigma {result.sigma:.3g}{unit} ({'estimated' if result.sigma_estimated else 'given'}); "
              f"hypotheses from {result.solver}: {result.samples} samples, {result.hypotheses} hypotheses, "
              f"{result.seconds:.2f} s")
        gt = result.global_test
        why = "sigma estimated" if result.sigma_estimated else "no degree of freedom"
        test = (f"global test not run ({why})" if gt is None else
                f"global test SSR/sigma^2 {gt[0]:.4g} vs {gt[1]:.4g}: {'passed' if gt[2] else 'FAILED'}")
        n_unc = int(result.uncontrolled.sum()) if result.uncontrolled is not None else 0
        print(f"adjustment: {result.dof} degrees of freedom; {test}; outlier test |w| <= {result.critical_value:.3g}; "
              f"{n_unc} measurement(s) uncontrolled (redundancy number < 0.01)")
        bracket = f" [{units}]" if units else ""
        axes = "xyz"[: result.dim]
        print(f"{'node':<12} " + " ".join(f"{a + bracket:>12}" for a in axes) + f" {'offset' + bracket:>12} "
              f"{'std' + bracket:>10} {'reliab.' + bracket:>10}")
        rel_r = result.receiver_reliability if result.receiver_reliability is not None else [float('nan')] * result.m
        rel_t = result.transmitter_reliability if result.transmitter_reliability is not None else [float('nan')] * result.n
        for k, name in enumerate(meas.receivers):
            xyz = " ".join(f"{v:12.5g}" for v in result.receivers[k])
            print(f"{'r ' + name:<12} {xyz} {'':>12} {result.receiver_std[k]:10.3g} {rel_r[k]:10.3g}")
        for k, name in enumerate(meas.transmitters):
            xyz = " ".join(f"{v:12.5g}" for v in result.transmitters[k])
            print(f"{'s ' + name:<12} {xyz} {result.offsets[k]:12.5g} {result.transmitter_std[k]:10.3g} "
                  f"{rel_t[k]:10.3g}")
    for w in result.warnings:
        print(f"warning: {w}")
