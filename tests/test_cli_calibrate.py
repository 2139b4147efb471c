"""`tdoa-workbench calibrate`: CSV parsing (headers, gaps, defects), JSON keys, plot, exit codes."""
import json

import numpy as np
import pytest

from solvers.calibrate_io import read_measurements
from solvers.cli import main
from solvers.synthetic import random_network


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
    ("1,2\n3,inf\n", "line 2, column 2: infinite value"),
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


def test_too_small_network_fails_with_exit_status_1(capsys, tmp_path):
    path = tmp_path / "small.csv"
    path.write_text("1,2,3\n4,5,6\n")
    code, out, _ = run(capsys, "calibrate", str(path))
    assert code == 1 and out.startswith("too few measurements")
