"""`tdoa-workbench calibrate`: CSV parsing (delimiters, comments, headers, gaps, defects), options
checked before computing, JSON keys, plot, exit codes."""
import dataclasses
import importlib
import io
import json
import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from solvers.calibrate_io import MeasurementFileError, parse_measurements, read_measurements
from solvers.cli import main
from solvers.synthetic import random_network

ROOT = Path(__file__).resolve().parents[1]


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def network_csv(tmp_path, header=True, gaps=((1, 2),)):
    net = random_network(8, 6, np.random.default_rng(2))
    F = net.measurements()
    for i, j in gaps:
        F[i, j] = np.nan
    lines = ["rx," + ",".join(f"s{j + 1}" for j in range(6))] if header else []
    for i, row in enumerate(F):
        cells = ["" if np.isnan(x) else repr(float(x)) for x in row]
        lines.append((f"r{i + 1}," if header else "") + ",".join(cells))
    path = tmp_path / "meas.csv"
    path.write_text("\n".join(lines) + "\n")
    return str(path), F


def test_headers_and_gaps_are_read(tmp_path):
    path, F = network_csv(tmp_path)
    meas = read_measurements(path)
    assert meas.receivers[0] == "r1" and meas.transmitters[-1] == "s6"
    assert np.array_equal(np.isnan(meas.F), np.isnan(F)) and np.allclose(meas.F[~np.isnan(F)], F[~np.isnan(F)])
    path, _ = network_csv(tmp_path, header=False)
    meas = read_measurements(path)
    assert meas.F.shape == (8, 6) and meas.receivers[0] == "1"


def test_json_output_has_the_documented_keys(capsys, tmp_path):
    path, _ = network_csv(tmp_path)
    out_file = tmp_path / "out.json"
    code, out, _ = run(capsys, "calibrate", path, "--json", "--out", str(out_file), "--seed", "3")
    report = json.loads(out)
    assert code == 0 and report == json.loads(out_file.read_text())
    for key in ("receivers", "transmitters", "offsets", "inliers", "rms", "warnings", "status", "sigma",
                "receiver_std", "transmitter_std", "offset_std", "receiver_names", "transmitter_names"):
        assert key in report
    assert len(report["receivers"]) == 8 and report["inliers"][1][2] is False and report["rms"] < 1e-8


def test_plot_is_written(capsys, tmp_path):
    path, _ = network_csv(tmp_path)
    png = tmp_path / "map.png"
    code, out, _ = run(capsys, "calibrate", path, "--plot", str(png))
    assert code == 0 and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.startswith("ok:")


@pytest.mark.parametrize("text, fragment", [
    ("1,2,3\n4,abc,6\n7,8,9\n", "line 2, column 2: 'abc' is not a number"),
    ("rx,a,b\nr1,1,2\nr2,1\n", "line 3 has 2 cells, expected 3"),
    ("", "no data (empty file)"),
    ("\n\n", "no data (empty file)"),
    ("# only\n  # comments\n", "no data (only comments)"),
    ("1,2\n3,inf\n", "line 2, column 2: infinite value"),
    ("1,2\n3,4\n# note\n5,1e400\n", "line 4, column 2: '1e400' overflows"),
    ("rx,s1,s2\nr1,1.5,-1e999\n", "line 2, column 3: '-1e999' overflows"),
    ("1,2\n3,\"4\n5,6\n", "line 2: unexpected end of data"),
    ("1;2;3\n4;5,5.5;6\n", "line 2, column 2: '5,5.5' is not a number"),
    ("1,2,3\n4,5,6 7\n", "line 2, column 3: '6 7' is not a number"),
    ("rx,1,2,3\nr1,4,5,6\nr2,7,8,9\n", "line 1 ('rx', then integers) could be transmitter names"),
    ("a,b,c\n", "no measurements"),
])
def test_malformed_csv_is_one_line_with_status_2(capsys, tmp_path, text, fragment):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    code, out, err = run(capsys, "calibrate", str(path))
    assert code == 2 and out == "" and fragment in err and str(path) in err
    assert err.count("\n") == 1 and "Traceback" not in err


def test_missing_file_and_unwritable_output(capsys, tmp_path):
    code, _, err = run(capsys, "calibrate", str(tmp_path / "nope.csv"))
    assert code == 2 and "cannot read" in err and "nope.csv" in err and err.count("\n") == 1
    path, _ = network_csv(tmp_path)
    bad_out = str(tmp_path / "no_such_dir" / "out.json")
    code, _, err = run(capsys, "calibrate", path, "--out", bad_out)
    assert code == 2 and f"cannot write {bad_out}" in err and err.count("\n") == 1


def test_too_small_network_is_refused_before_the_work(capsys, tmp_path):
    """A shape no calibration can use is a malformed input (exit 2, one line naming what is needed), said
    before any computing (issue 55); the pipeline's own 'too few measurements' remains for entries missing."""
    path = tmp_path / "small.csv"
    path.write_text("1,2,3\n4,5,6\n")
    code, out, err = run(capsys, "calibrate", str(path))
    assert code == 2 and out == "" and err.count("\n") == 1
    assert ("small.csv: 2 rows (receivers) x 3 columns (transmitters) cannot be calibrated in 2D: too few receivers "
            "(2): each transmitter is placed from >= 4 receivers, so a 2D network needs >= 4 receivers and >= 3 "
            "transmitters") in err


def cells(meas):
    """(receivers, transmitters, F as a list of lists with None for NaN) for exact comparisons."""
    return meas.receivers, meas.transmitters, [[None if math.isnan(x) else x for x in row] for row in meas.F.tolist()]


MATRIX = (("r1", "r2"), ("s1", "s2", "s3"), [[1.5, None, -2.25], [3.0, 4e-3, 12.0]])


@pytest.mark.parametrize("text, delimiter", [
    ("rx,s1,s2,s3\nr1,1.5,,-2.25\nr2,3,4e-3,12\n", ","),
    ("rx;s1;s2;s3\nr1;1,5;;-2,25\nr2;3;4e-3;12\n", ";"),            # decimal commas with ;
    ("rx\ts1\ts2\ts3\nr1\t1.5\tNaN\t-2.25\nr2\t3\t0.004\t12\n", "\t"),
    ("rx  s1  s2  s3\nr1  1.5 nan -2.25\nr2    3  4e-3  12\n", " "),   # savetxt-style spaces
    ("\ufeffrx,s1,s2,s3\r\nr1,1.5,N/A,-2.25\r\nr2,3,4e-3,12\r\n", ","),  # BOM, CRLF
    ('"rx","s1","s2","s3"\n"r1",1.5,"",-2.25\n"r2",3,4e-3,12\n', ","),   # quoted cells
    ("rx,s1,s2,s3,\nr1,1.5,,-2.25,\nr2,3,4e-3,12,\n", ","),           # a delimiter ending every line
])
def test_delimiters_are_detected_and_cells_read(text, delimiter):
    meas = parse_measurements(text, "m.csv")
    assert cells(meas) == MATRIX and meas.delimiter == delimiter


def test_comments_are_skipped_and_lines_counted():
    text = ("# campaign 3, room B\n"
            "rx,s1,s2,s3   # transmitter names\n"
            "\n"
            "   # a note between rows\n"
            "r1,1.5,#N/A,-2.25\n"
            "r2,3,4e-3,12 # receiver 2 moved; remeasured\n")
    assert cells(parse_measurements(text, "m.csv")) == MATRIX
    with pytest.raises(MeasurementFileError, match=r"m\.csv: line 5, column 3: 'x' is not a number"):
        parse_measurements(text.replace("#N/A", "x"), "m.csv")
    # a # inside a quoted cell is part of the cell, not a comment
    quoted = parse_measurements('rx,"s#1",s2,s3\nr1,1.5,,-2.25\nr2,3,4e-3,12\n', "m.csv")
    assert quoted.transmitters == ("s#1", "s2", "s3")


@pytest.mark.parametrize("text, receivers, transmitters, F", [
    # numeric transmitter names under a text corner: names, and the first column names the receivers
    ("rx,1,2,3\nr1,0.5,1.5,2.5\nr2,1,,3.5\n", ("r1", "r2"), ("1", "2", "3"), [[0.5, 1.5, 2.5], [1.0, None, 3.5]]),
    ("rx,1,2,3\n10,0.5,1.5,2.5\n20,1,,3.5\n", ("10", "20"), ("1", "2", "3"), [[0.5, 1.5, 2.5], [1.0, None, 3.5]]),
    # pandas: an empty corner, integer column labels, a 0, 1, ... index
    (",1,2,3\n0,0.5,1.5,2.5\n1,1,,3.5\n", ("0", "1"), ("1", "2", "3"), [[0.5, 1.5, 2.5], [1.0, None, 3.5]]),
    (",s1,s2,s3\n0,0.5,1.5,2.5\n1,1,,3.5\n", ("0", "1"), ("s1", "s2", "s3"), [[0.5, 1.5, 2.5], [1.0, None, 3.5]]),
    ("rx,s1,s2,s3\n1,0.5,1.5,2.5\n2,1,,3.5\n", ("1", "2"), ("s1", "s2", "s3"), [[0.5, 1.5, 2.5], [1.0, None, 3.5]]),
    # text names on the first row only: every column is a transmitter
    ("s1,s2,s3\n0.5,1.5,2.5\n1,,3.5\n", ("1", "2"), ("s1", "s2", "s3"), [[0.5, 1.5, 2.5], [1.0, None, 3.5]]),
    # names in the first column only; a first row of integers with a named receiver is data when its
    # integers repeat (names are distinct)
    ("r1,3,3,4\nr2,1.5,2,2.5\n", ("r1", "r2"), ("1", "2", "3"), [[3.0, 3.0, 4.0], [1.5, 2.0, 2.5]]),
    ("r1,0.5,1.5,2.5\nr2,1,,3.5\n", ("r1", "r2"), ("1", "2", "3"), [[0.5, 1.5, 2.5], [1.0, None, 3.5]]),
    # no names: a first row of integers that starts with a number is data (--header row says otherwise)
    ("1,2,3\n4,5,6\n", ("1", "2"), ("1", "2", "3"), [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]),
])
def test_names_are_found_by_the_documented_rules(text, receivers, transmitters, F):
    assert cells(parse_measurements(text, "m.csv")) == (receivers, transmitters, F)


@pytest.mark.parametrize("header, receivers, transmitters, F", [
    ("both", ("r1", "r2"), ("1", "2", "3"), [[4.0, 5.0, 6.0], [7.0, 8.0, 9.0]]),
    ("column", ("rx", "r1", "r2"), ("1", "2", "3"), [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 9.0]]),
])
def test_header_option_settles_an_ambiguous_first_row(header, receivers, transmitters, F):
    text = "rx,1,2,3\nr1,4,5,6\nr2,7,8,9\n"
    with pytest.raises(MeasurementFileError, match="--header both"):
        parse_measurements(text, "m.csv")
    assert cells(parse_measurements(text, "m.csv", header=header)) == (receivers, transmitters, F)


def test_header_row_and_none_and_delimiter_options():
    text = "1;2;3\n4;5;6\n"
    assert cells(parse_measurements(text, "m.csv", header="row")) == (("1",), ("1", "2", "3"), [[4.0, 5.0, 6.0]])
    assert cells(parse_measurements(text, "m.csv", header="none"))[2] == [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]
    # forced: with a comma delimiter the semicolons stay inside the cells
    with pytest.raises(MeasurementFileError, match=r"m\.csv: one cell per line \(read with comma as delimiter\)"):
        parse_measurements(text, "m.csv", delimiter="comma")
    assert parse_measurements("1\t2,5\n3\t4\n", "m.csv", delimiter="tab").F.tolist() == [[1.0, 2.5], [3.0, 4.0]]
    with pytest.raises(MeasurementFileError, match="unknown delimiter 'pipe'; give one of comma, semicolon, tab, space"):
        parse_measurements(text, "m.csv", delimiter="pipe")


def test_encodings(tmp_path):
    utf16 = tmp_path / "u16.txt"  # a spreadsheet's "Unicode text": UTF-16 with a BOM, TAB-separated
    utf16.write_bytes("rx\ts1\ts2\ts3\nr1\t1,5\t\t-2,25\nr2\t3\t4e-3\t12\n".encode("utf-16"))
    assert cells(read_measurements(str(utf16))) == MATRIX
    latin = tmp_path / "latin1.csv"
    latin.write_bytes("rx,s1,s2\nr1,1,2\nr\xe9,3,4\n".encode("latin-1"))
    with pytest.raises(MeasurementFileError, match=r"latin1\.csv: line 3: not UTF-8 text \(byte 0xe9\)"):
        read_measurements(str(latin))


def test_transposed_measurements_swap_names():
    meas = parse_measurements("rx,s1,s2,s3\nr1,1.5,,-2.25\nr2,3,4e-3,12\n", "m.csv").transposed()
    assert cells(meas) == (("s1", "s2", "s3"), ("r1", "r2"), [[1.5, 3.0], [None, 4e-3], [-2.25, 12.0]])


# -- the command: options checked first, stdin, transposed files, units, exit status --------------

def calibrate_module():
    """The package solvers.calibration, whose `calibrate` the command calls."""
    return importlib.import_module("solvers.calibration")


@pytest.fixture
def no_calibration(monkeypatch):
    """calibrate must not run: the command has to refuse before any computing."""

    def refuse(*args, **kwargs):
        raise AssertionError("calibrate ran before the options were checked")

    monkeypatch.setattr(calibrate_module(), "calibrate", refuse)


@pytest.mark.parametrize("options, fragment", [
    (["--sigma", "0"], "--sigma must be a finite number > 0, got 0: the noise of real measurements is never zero; omit --sigma"),
    (["--sigma", "-0.01"], "--sigma must be a finite number > 0, got -0.01"),
    (["--sigma", "nan"], "--sigma must be a finite number > 0, got nan"),
    (["--sigma", "inf"], "--sigma must be a finite number > 0, got inf"),
    (["--out", "{tmp}/no/such/dir/out.json"], "cannot write {tmp}/no/such/dir/out.json (--out): no directory"),
    (["--out", "{tmp}"], "cannot write {tmp} (--out): it is a directory"),
    (["--out", "{csv}"], "--out {csv} is the measurement file"),
    (["--out", "-"], "--out -: give a file name (--json prints the JSON)"),
    (["--plot", "{tmp}/map.xyz"], "--plot {tmp}/map.xyz: extension .xyz; give one of"),
    (["--plot", "{tmp}/map"], "--plot {tmp}/map: no extension; give one of"),
    (["--plot", "{tmp}/nodir/map.png"], "cannot write {tmp}/nodir/map.png (--plot): no directory"),
    (["--out", "{tmp}/a.png", "--plot", "{tmp}/a.png"], "--out and --plot name the same file"),
    (["--units", ""], "--units '': give a printable name"),
    (["--delimiter", "|"], "unknown delimiter '|'"),
])
def test_bad_options_are_refused_before_computing(capsys, tmp_path, no_calibration, options, fragment):
    path, _ = network_csv(tmp_path)
    fill = {"{tmp}": str(tmp_path), "{csv}": path}
    for key, value in fill.items():
        options = [o.replace(key, value) for o in options]
        fragment = fragment.replace(key, value)
    code, out, err = run(capsys, "calibrate", path, *options)
    assert code == 2 and out == "" and err.count("\n") == 1 and fragment in err, err


def test_transposed_file_is_refused_with_the_hint_and_read_with_transpose(capsys, tmp_path):
    net = random_network(8, 3, np.random.default_rng(2))
    path = tmp_path / "t.csv"
    path.write_text("\n".join(",".join(repr(float(x)) for x in row) for row in net.measurements().T) + "\n")
    code, out, err = run(capsys, "calibrate", str(path))
    assert code == 2 and out == "" and err.count("\n") == 1
    assert "3 rows (receivers) x 8 columns (transmitters) cannot be calibrated" in err
    assert "8 receivers x 3 transmitters can: the file looks transposed" in err and "give --transpose" in err
    code, out, err = run(capsys, "calibrate", str(path), "--transpose", "--json")
    report = json.loads(out)
    assert len(report["receivers"]) == 8 and report["receiver_names"] == [str(k) for k in range(1, 9)]
    assert report["rms"] < 1e-8 and code == (0 if report["status"] == "ok" else 1)  # read the right way round


def test_standard_input_and_units(capsys, tmp_path, monkeypatch):
    path, _ = network_csv(tmp_path)
    data = Path(path).read_bytes()
    monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(io.BytesIO(data)))
    code, out, err = run(capsys, "calibrate", "-", "--units", "m", "--seed", "3")
    from_file = run(capsys, "calibrate", path, "--units", "m", "--seed", "3")
    lines = out.splitlines()
    assert (code, lines[0], lines[2:]) == (from_file[0], *(lambda x: (x[0], x[2:]))(from_file[1].splitlines()))
    assert re.match(r"sigma \S+ m \((estimated|given)\)", lines[1])
    assert lines[2].startswith("adjustment: ") and "degrees of freedom" in lines[2]
    assert lines[3].split() == ["node", "x", "[m]", "y", "[m]", "offset", "[m]", "std", "[m]", "reliab.", "[m]"]
    assert lines[4].split()[:2] == ["r", "r1"] and lines[4 + 8 + 5].split()[:2] == ["s", "s6"]
    monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(io.BytesIO(data)))
    code, out, _ = run(capsys, "calibrate", "-", "--json", "--units", "mm", "--seed", "3")
    assert json.loads(out)["units"] == "mm" and json.loads(out)["transmitter_names"][0] == "s1"


def test_standard_input_errors_name_stdin_in_a_real_process():
    bad = "rx,s1,s2\nr1,1,2\n# comment\nr2,3,1e400\n"
    done = subprocess.run([sys.executable, "-m", "solvers.cli", "calibrate", "-"], input=bad, capture_output=True,
                          text=True, cwd=ROOT)
    assert done.returncode == 2 and done.stdout == "" and "Traceback" not in done.stderr
    assert done.stderr.strip().splitlines() == [
        "tdoa-workbench calibrate: error: stdin: line 4, column 3: '1e400' overflows (beyond 1.8e+308); check the units"]


@pytest.fixture(scope="module")
def one_result(tmp_path_factory):
    from solvers.calibration import calibrate

    path, _ = network_csv(tmp_path_factory.mktemp("one"))
    return path, calibrate(read_measurements(path).F, seed=3)


@pytest.mark.parametrize("status", ["ok", "partial", "uncontrolled", "inconsistent", "ambiguous", "unconverged"])
def test_exit_status_is_0_only_for_ok_and_the_message_comes_first(capsys, monkeypatch, one_result, status):
    path, result = one_result
    fake = dataclasses.replace(result, status=status, message=f"{status}: what calibrate says")
    monkeypatch.setattr(calibrate_module(), "calibrate", lambda *a, **k: fake)
    code, out, _ = run(capsys, "calibrate", path)
    assert code == (0 if status == "ok" else 1) and out.splitlines()[0] == f"{status}: what calibrate says"
    code, out, _ = run(capsys, "calibrate", path, "--json")
    assert code == (0 if status == "ok" else 1) and json.loads(out)["status"] == status


def test_dim_3_from_a_csv(capsys, tmp_path):
    """calibrate --dim 3: x, y, z columns, a JSON with dim 3 and three coordinates, three projections drawn."""
    from solvers.synthetic import room_network

    net = room_network(12, 8, np.random.default_rng(3))
    F = net.measurements(1e-3, np.random.default_rng(4))
    path = tmp_path / "room.csv"
    path.write_text("\n".join(",".join(f"{v:.6f}" for v in row) for row in F) + "\n")
    plot = tmp_path / "room.png"
    code, out, _ = run(capsys, "calibrate", str(path), "--dim", "3", "--sigma", "0.001", "--plot", str(plot))
    assert code == 0, out
    assert re.search(r"node\s+x\s+y\s+z\s+offset", out)
    assert plot.stat().st_size > 10_000
    code, out, _ = run(capsys, "calibrate", str(path), "--dim", "3", "--sigma", "0.001", "--json")
    report = json.loads(out)
    assert report["dim"] == 3 and len(report["receivers"][0]) == 3 and len(report["gauge"]) == 3
    with pytest.raises(SystemExit) as exc:
        main(["calibrate", str(path), "--dim", "4"])
    assert exc.value.code == 2


@pytest.mark.parametrize("flags, given", [((), False), (("--oriented",), True), (("--transpose",), True)])
def test_oriented_and_transpose_give_the_orientation(capsys, monkeypatch, one_result, flags, given):
    path, result = one_result
    seen = {}

    def fake(F, **kwargs):
        seen.update(kwargs)
        return result

    monkeypatch.setattr(calibrate_module(), "calibrate", fake)
    if "--transpose" in flags:  # a file with transmitters as rows
        F = read_measurements(path).F
        text = "\n".join(",".join(repr(float(x)) if np.isfinite(x) else "" for x in row) for row in F.T)
        path = str(Path(path).with_name("transposed.csv"))
        Path(path).write_text(text + "\n")
    run(capsys, "calibrate", path, *flags)
    assert seen["options"].orientation_given is given


def test_plane_wave_route_prints_reliabilities_not_nan(capsys, tmp_path):
    """Issue 52: the far-field route left the reliabilities out and the table printed nan for every node."""
    from solvers.synthetic import array_network

    _, F, _ = array_network(np.random.default_rng(0), per_cone=30)
    path = tmp_path / "array.csv"
    np.savetxt(path, F, delimiter=",")
    code, out, _ = run(capsys, "calibrate", str(path), "--dim", "3", "--seed", "0")
    table = [line.split() for line in out.splitlines() if line.startswith(("r ", "s "))]
    assert "hypotheses from factorization" in out and len(table) == F.shape[0] + F.shape[1]
    assert not any("nan" in row[-1] for row in table)
    assert all(float(row[-1]) < math.inf for row in table if row[0] == "r")
