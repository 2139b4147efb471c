"""Root counts of the 3D TDOA minimal cells by monodromy alone (numerical evidence, no GF(p) certificate);
writes tables/monodromy3d.{csv,md} (results) and prints the seconds.

Per cell and seed: the cell's square formulation (10r/4s: compaction A, B2-B4, C2-C10, 13 unknowns, every
measurement used, det H saturated; 7r/5s, 6r/6s, 5r/9s: the direct parametrization, see CELLS; 10r4s-direct:
10r/4s in the direct parametrization as well, its second formulation), a generic
complex start network (solvers.generate.complex_instance, seeded) and its root, then monodromy loops (solvers.continuation.monodromy.monodromy_count: triangles through
random complex parameters, all known roots tracked in one batch on the compiled tape tracker) until
--stall loops bring no new root or --loops loops are done. Checkpoints (resumable) go to
$TDOA_WORKBENCH_CACHE/monodromy/<cell>-seed<k>.json. The compaction unknowns are invariant under the
Euclidean group, so each root is one network up to rotation, reflection and translation (group order 1);
the direct roots are counted one per orbit of the gauge frame's 8 reflections (group order 8), which
counts the same networks.

A count is reported as "settled" (stopped growing for --stall loops; two seeds should agree) or as a
lower bound ("not settled": at least N after L loops). With two settled seeds, the second seed's roots are
carried to each seed's instance and pooled with its roots (column union, cached in <cell>-union-seed<k>.json):
equal counts are then equal sets, and a pool larger than either count shows a "settled" count was short. A settled count then gets the trace test
(solvers.continuation.trace: the pencil on the coordinates of TRACE_COORDINATES, a second seeded complex network
for the witnesses' start, their monodromy checkpointed in <cell>-seed<k>-witnesses.json, the outcome kept
in <cell>-seed<k>-trace.json so that a rerun reads it): its status (passed / failed / inconclusive), the
relative residual of the affine fit, the number of witnesses and the paths it tracked.

Usage: python scripts/monodromy_counts.py [10r4s 10r4s-direct 7r5s 6r6s 5r9s] [--seeds 0 1] [--loops 60] [--stall 10]
       [--seconds 1800] [--trace-seconds 3600] [--trace-stall 3] [--threads N]
       [--dask ADDRESS|local [--dask-chunk 2000]]
(--threads: the batches of each tracking call side by side on N threads, the same results; --seconds 0 --trace-seconds 0: read the checkpoints only, no loop and no trace test run.)
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import csv  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import numpy as np  # noqa: E402

from analysis.formulations.tdoa import Formulation  # noqa: E402
from analysis.formulations.parametric import from_formulation  # noqa: E402
from analysis.sweeps.paths import cache_dir  # noqa: E402
from solvers.generate import complex_instance, gauge_reflections  # noqa: E402
from solvers.continuation import monodromy as md  # noqa: E402
from solvers.continuation import tape_kernel, trace  # noqa: E402
from solvers.continuation import tracking as tk  # noqa: E402
from solvers.continuation.dask_tracks import DaskTracks  # noqa: E402

TABLES = os.path.join(ROOT, "tables")

#: The minimal 3D TDOA cells with a square formulation counted here. 10r/4s: the compaction formulation (every
#: measurement, det H saturated). The other three have none without minors; they run on the direct
#: parametrization (receivers in the gauge frame r_1 = 0, r_2 on x, r_3 in the xy-plane, transmitters,
#: offsets: 3m + 4n - 6 = mn unknowns, one equation d_ij^2 = |r_i - s_j|^2 per measurement), whose roots come
#: in orbits of the 8 reflections of that frame (x, y, z -> -x, -y, -z): one root per orbit is tracked and
#: counted, so its counts are networks up to the Euclidean group, like the compaction counts. "10r4s-direct":
#: 10r/4s in the direct parametrization too (40 unknowns), a second formulation of the same cell.
CELLS = {"10r4s": "10r4s-tdoa3d:A,B2,B3,B4,C2-C10", "10r4s-direct": "10r4s-tdoa3d-direct:all",
         "7r5s": "7r5s-tdoa3d-direct:all", "6r6s": "6r6s-tdoa3d-direct:all", "5r9s": "5r9s-tdoa3d-direct:all"}
#: Seeds (start networks) per cell by default: two for every settled cell (the second seed's count from
#: another start network must agree), three for 6r/6s, whose first two settled one root apart (3919, 3920);
#: one for 5r/9s, whose first seed has not settled yet, and one for 10r4s-direct (a second formulation).
SEEDS = {"10r4s": (0, 1), "10r4s-direct": (0,), "7r5s": (0, 1), "6r6s": (0, 1, 2), "5r9s": (0,)}
#: Unknowns the trace test's pencil uses (indices into the formulation's unknowns). 10r/4s: b1, b2, b3. b
#: (like H) goes to infinity whenever a root escapes along the line of data, so the pencil has no base point
#: on the curve; the offsets do not (2D 9r/3s: every root's path lost with the pencil on o), and all 13
#: unknowns need more witnesses (9r/3s: 2045 with all, 1290 with b or with H, for 75 roots). The compaction
#: unknowns have no symmetry (group order 1), so no two roots share their b.
TRACE_COORDINATES = {"10r4s": (6, 7, 8)}
#: |t1| = |t2| of the trace test's pencil (trace.TraceOptions.step, 0.5 by default). 10r/4s: 0.2. At 0.3 and 0.5
#: one track of 284,132 (at 0.5 a witness of norm 11) is lost on every route, straight, around and by
#: continuation, and the test is inconclusive; at 0.2 none is (docs/minimal-3d.md, section 4).
TRACE_STEP = {"10r4s": 0.2}
COLUMNS = ["cell", "formulation", "unknowns", "seed", "roots", "status", "loops", "paths", "loops_without_new",
           "group_order", "trace_test", "trace_residual", "witnesses", "trace_paths", "union"]


def count(cell: str, seed: int, loops: int, stall: int, seconds: float, trace_stall: int = 3,
          trace_seconds: float = 3600.0, dask: str | None = None, dask_chunk: int = 2000) -> tuple[dict, float]:
    """One row of monodromy3d.csv and the seconds it took (checkpointed, resumable). ``dask``: a scheduler
    address or "local": the loops' paths are tracked on that cluster (solvers.continuation.dask_tracks), in chunks
    of ``dask_chunk``, with the same results."""
    label = CELLS[cell]
    form = Formulation.parse(label)
    config = form.config
    direct = config.parametrization == "direct"
    system = from_formulation(label, saturate_det_h=not direct)
    F, x0 = complex_instance(config.m, config.n, np.random.default_rng(seed), config.dim, config.model,
                             config.parametrization)
    q0 = F.ravel()
    solver, x0 = md.start_solver(system, q0, x0, seed)
    group = gauge_reflections(system.unknowns) if direct else None
    options = tk.HomotopyOptions(seed=seed, max_loops=loops, stall_loops=stall)
    path = cache_dir("monodromy")
    path.mkdir(parents=True, exist_ok=True)
    tracks = DaskTracks(dask, label, not direct, q0, x0, chunk=dask_chunk) if dask and seconds > 0 else None
    try:
        result = md.monodromy_count(solver, q0, x0, options, seconds, str(path / f"{cell}-seed{seed}.json"),
                                    progress=lambda msg: print(f"  {cell} seed {seed}: {msg}", file=sys.stderr,
                                                               flush=True),
                                    excluded=md._excluded(system, q0), group=group, track=tracks)
    finally:
        if tracks is not None:
            tracks.close()
    status = "settled" if result.stall >= stall else "not settled"
    row = {"cell": cell, "formulation": label, "unknowns": len(system.unknowns), "seed": seed,
           "roots": len(result.roots), "status": status, "loops": result.loops, "paths": result.paths,
           "loops_without_new": result.stall, "group_order": 1 if group is None else len(group),
           "trace_test": "not run", "trace_residual": "",
           "witnesses": "", "trace_paths": ""}
    if status == "settled" and group is None:  # (with one root per orbit the trace needs the orbits: not done)
        test = trace_test(system, q0, result.roots, path / f"{cell}-seed{seed}", TRACE_COORDINATES.get(cell), seed,
                          trace_stall, trace_seconds, TRACE_STEP.get(cell, trace.TraceOptions.step))
        residual = "" if np.isnan(test["residual"]) else f"{test['residual']:.0e}"
        row.update({"trace_test": test["status"], "trace_residual": residual,
                    "witnesses": test["witnesses"], "trace_paths": test["paths"]})
    return row, result.seconds


def union(cell: str, seeds: list[int]) -> dict | None:
    """The roots of every other seed's checkpoint carried to the first seed's parameters by one parameter
    homotopy each, and pooled with the first seed's roots (one per orbit of the gauge reflections for the
    direct cells): {"union": size of the pool, "new": roots no checkpoint but one had, "lost": paths that
    failed}. Equal counts from two seeds can still be two different sets; a pool larger than every seed's
    count shows that a "settled" count was incomplete (6r/6s: 3919 and 3920, pool 3920). Kept in
    <cell>-union-seed<k>.json (k: the first seed) for the checkpoints' root counts; None when a checkpoint is
    missing."""
    path = cache_dir("monodromy")
    files = [path / f"{cell}-seed{seed}.json" for seed in seeds]
    if len(seeds) < 2 or not all(f.exists() for f in files):
        return None
    saved = [json.loads(f.read_text(encoding="utf-8")) for f in files]
    key = {"seeds": list(seeds), "roots": [len(d["roots"]) for d in saved]}
    record = path / f"{cell}-union-seed{seeds[0]}.json"
    if record.exists():
        stored = json.loads(record.read_text(encoding="utf-8"))
        if stored.get("key") == key:
            return stored
    label = CELLS[cell]
    config = Formulation.parse(label).config
    direct = config.parametrization == "direct"
    system = from_formulation(label, saturate_det_h=not direct)
    group = gauge_reflections(system.unknowns) if direct else None
    q0, pool = tk._complex_array(saved[0]["q0"]), tk._complex_array(saved[0]["roots"])
    _, x0 = complex_instance(config.m, config.n, np.random.default_rng(seeds[0]), config.dim, config.model,
                             config.parametrization)
    solver, _ = md.start_solver(system, q0, x0, seeds[0])
    excluded = md._excluded(system, q0)
    new = lost = 0
    for d in saved[1:]:
        xs, _ = solver.track(tk._complex_array(d["q0"])[None], q0[None], tk._complex_array(d["roots"]))
        roots = md.accepted(solver, xs, q0, excluded)  # (the monodromy loops' own test of a root)
        lost += len(xs) - len(roots)
        before = len(pool)
        pool = md.add_new(pool, roots, group)
        new += len(pool) - before
    out = {"union": len(pool), "new": new, "lost": lost, "key": key}
    record.write_text(json.dumps(out), encoding="utf-8")
    return out


def trace_test(system, q0: np.ndarray, roots: np.ndarray, stem, coordinates, seed: int, stall: int,
               seconds: float, step: float = trace.TraceOptions.step) -> dict:
    """The trace test's record for a settled count, read from <stem>-trace.json when it was run on the same
    roots and options (an inconclusive one only when ``seconds`` is 0), else run and stored (the witnesses
    resume from <stem>-witnesses.json; ``seconds`` 0: no new witness loop, only what that checkpoint holds)."""
    config = Formulation.parse(system.name).config
    F2, x2 = complex_instance(config.m, config.n, np.random.default_rng(1000 + seed), config.dim, config.model)
    options = trace.TraceOptions(seed=seed, stall=stall, seconds=seconds, step=step,
                                 coordinates=tuple(coordinates) if coordinates else None)
    key = {"roots": len(roots), "seed": seed, "stall": stall, "coordinates": list(coordinates or []),
           "step": step, "test": trace.TEST_VERSION}
    stored = trace.load_record(f"{stem}-trace.json")
    if stored and stored.get("key") == key and (stored["status"] != "inconclusive" or seconds <= 0):
        return stored
    if seconds <= 0 and not os.path.exists(f"{stem}-witnesses.json"):
        return {"status": "not run", "residual": float("nan"), "witnesses": "", "paths": ""}
    test = trace.trace_test_system(system, q0, roots, (F2.ravel(), x2), options, checkpoint=f"{stem}-witnesses.json",
                                   progress=lambda msg: print(f"  {stem.name} trace: {msg}", file=sys.stderr, flush=True))
    record = {**test.record(), "key": key}
    with open(f"{stem}-trace.json", "w", encoding="utf-8") as fh:
        json.dump(record, fh)
    print(f"{stem.name}: trace test {test.status}, residual {test.residual:.1e}, {test.witnesses} witnesses, "
          f"{test.paths} paths, {test.seconds:.0f} s", flush=True)
    return record


def markdown(rows: list[dict]) -> str:
    lines = ["<!-- Regenerate: python scripts/monodromy_counts.py; numerical evidence only (no GF(p) certificate) -->", "",
             "**3D TDOA minimal cells: root counts by monodromy** (up to rotation, reflection and translation; "
             "'settled': no new root in the last loops, else a lower bound; trace test: solvers.continuation.trace, "
             f"'passed' when the affine fit's relative residual is <= {trace.PASS_TOL:.0e}, 'inconclusive' when its "
             "witness set was not settled (its size then a lower bound, no residual) or a path was lost, 'failed' "
             "when the roots and witnesses together fall short of the whole fibre (a root or a witness missing: "
             "witnesses settled after only a few loops can still lack some); group order "
             "8: direct parametrization, roots counted one per orbit of the gauge frame's reflections; union of the "
             "seeds: the other seeds' roots carried to this seed's network and pooled with its own)", "",
             "| cell | formulation | unknowns | group order | seed | roots | status | loops | paths tracked "
             "| loops without a new root | trace test | residual | witnesses | trace paths | union of the seeds |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        bound = "" if r["status"] == "settled" else "at least "
        lines.append(f"| {r['cell']} | {r['formulation']} | {r['unknowns']} | {r['group_order']} | {r['seed']} | "
                     f"{bound}{r['roots']} | "
                     f"{r['status']} | {r['loops']} | {r['paths']} | {r['loops_without_new']} | {r['trace_test']} | "
                     f"{r['trace_residual']} | {r['witnesses']} | {r['trace_paths']} | {r.get('union', '')} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("cells", nargs="*", default=list(CELLS), help=f"any of {', '.join(CELLS)} (default: all)")
    parser.add_argument("--seeds", type=int, nargs="+", default=None,
                        help="seeds of every cell (default: SEEDS, per cell)")
    parser.add_argument("--loops", type=int, default=60, help="loop budget per seed (default 60)")
    parser.add_argument("--stall", type=int, default=10, help="loops without a new root that settle a count")
    parser.add_argument("--seconds", type=float, default=1800.0, help="time cap per seed (then a lower bound)")
    parser.add_argument("--trace-seconds", type=float, default=3600.0,
                        help="time cap of the trace test's witness monodromy per seed (0: the checkpoints only)")
    parser.add_argument("--trace-stall", type=int, default=3, help="witness loops without a new one before the trace")
    parser.add_argument("--threads", type=int, default=None, metavar="N",
                        help="track each call's batches on N threads, same results (default $TDOA_WORKBENCH_THREADS or 1)")
    parser.add_argument("--dask", metavar="ADDRESS", help="track the loops' paths on a Dask cluster: a scheduler "
                        "address, or 'local' for a LocalCluster of one process per core (same results)")
    parser.add_argument("--dask-chunk", type=int, default=2000, metavar="N", help="paths per Dask task (default 2000)")
    args = parser.parse_args(argv)
    unknown = [c for c in args.cells if c not in CELLS]
    if unknown:
        parser.error(f"unknown cell {unknown[0]!r}; valid: {', '.join(CELLS)}")
    try:
        tape_kernel.set_threads(args.threads)
    except ValueError:
        parser.error(f"--threads must be a positive integer, not {args.threads}")
    rows = []
    for cell in args.cells:
        seeds = args.seeds if args.seeds is not None else SEEDS[cell]
        cell_rows = []
        for seed in seeds:
            try:
                row, seconds = count(cell, seed, args.loops, args.stall, args.seconds, args.trace_stall,
                                     args.trace_seconds, args.dask, args.dask_chunk)
            except ValueError as e:  # a bad --dask address, one line
                if not args.dask:
                    raise
                print(f"monodromy_counts: {e}", file=sys.stderr)
                return 2
            cell_rows.append(row)
            print(f"{cell} seed {seed}: {row['roots']} roots, {row['status']}, {row['loops']} loops, "
                  f"{row['paths']} paths, {seconds:.0f} s", flush=True)
        settled = all(r["status"] == "settled" for r in cell_rows)
        for row in cell_rows:  # the pool at each seed's own instance: the other seeds' roots carried there
            first = [row["seed"]] + [s_ for s_ in seeds if s_ != row["seed"]]
            pooled = union(cell, first) if settled else None
            row["union"] = "" if pooled is None else (f"{pooled['union']}" +
                                                      (f" ({pooled['lost']} paths lost)" if pooled["lost"] else ""))
            if pooled is not None:
                print(f"{cell}: union of seeds {first} at seed {row['seed']}: {pooled['union']} ({pooled['new']} new, "
                      f"{pooled['lost']} paths lost)", flush=True)
        rows += cell_rows
    with open(os.path.join(TABLES, "monodromy3d.csv"), "w", newline="", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, fieldnames=COLUMNS, lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    with open(os.path.join(TABLES, "monodromy3d.md"), "w", encoding="utf-8", newline="\n") as fh:
        fh.write(markdown(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
