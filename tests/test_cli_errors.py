"""Every bad input a user can give the command line ends in one line on stderr with exit status 2,
never a traceback; a reader that closes the pipe early (| head) stops the command quietly."""
import subprocess
import sys
from pathlib import Path

import pytest

from solvers.cli import main

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = str(ROOT / "examples" / "katsura4.ms")


def run(capsys, argv):
    try:
        code = main(argv)
    except SystemExit as e:  # argparse errors
        code = e.code
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture
def files(tmp_path):
    (tmp_path / "utf16.ms").write_text("x,y\n0\nx-1,y-1\n", encoding="utf-16")
    (tmp_path / "binary.ms").write_bytes(bytes(range(256)))
    (tmp_path / "huge.ms").write_text("x\n0\nx^2147483648-1\n")
    (tmp_path / "meas.csv").write_text("rx;s1;s2;s3\nr1;1;2;3,5\n# r2 pending\nr2;4;5;1e400\n")
    (tmp_path / "ambiguous.csv").write_text("rx,1,2,3\nr1,4,5,6\n")
    return tmp_path


BAD = [
    (["degree", EXAMPLE, "--export", "msolve", "{tmp}/no/such/dir/x.ms"], "cannot write"),
    (["degree", EXAMPLE, "--export", "m2", "{tmp}"], "is a directory"),
    (["degree", EXAMPLE, "--export", "maple", "{tmp}/x"], "unknown format 'maple'"),
    (["degree", "{tmp}/utf16.ms"], "utf16.ms: UTF-16 text"),
    (["degree", "{tmp}/binary.ms"], "binary.ms: not UTF-8 text"),
    (["degree", "{tmp}/huge.ms"], "exponent 2147483648 too large"),
    (["degree", "{tmp}/missing.ms"], "cannot read"),
    (["degree", EXAMPLE, "--max-memory", "1K"], "above the memory cap of 1 KiB"),
    (["degree", EXAMPLE, "--max-memory", "lots"], "argument --max-memory"),
    (["degree", EXAMPLE, "--basis", "--basis-limit", "3"], "give --basis-limit 16"),
    (["degree", EXAMPLE, "--tdoa", "6r4s"], "either FILE or --tdoa"),
    (["degree", "--tdoa", "6r4s", "--equations", "C2-C6", "--seed", "-1"], "argument --seed: must be an integer >= 0"),
    (["degree", "--tdoa", "6r4s", "--equations", ""], "--equations is empty"),
    (["degree", "--tdoa", "6r4s", "--equations", "C2,"], "empty token"),
    (["degree", "--tdoa", "3r3s"], "m (receivers) must be >= 4"),
    (["tables", "--jobs", "0"], "--jobs must be at least 1"),
    (["generate", "5r6s"], "the following arguments are required: --out"),
    (["generate", "5r6s", "--out", "{tmp}/gen"], "no committed solver for 5r6s"),
    (["generate", "9r3s", "--out", "{tmp}/gen", "--start", "{tmp}/start.json"], "--start is for a system FILE"),
    (["template-check", "nonsense"], "neither a file nor a formulation"),
    (["template-check", "9r3s:C2-C9", "--seed", "-3"], "argument --seed"),
    (["calibrate", "{tmp}/meas.csv"], "meas.csv: line 4, column 4: '1e400' overflows"),
    (["calibrate", "{tmp}/ambiguous.csv"], "could be transmitter names or the measurements of a receiver 'rx'"),
    (["calibrate", "{tmp}/meas.csv", "--sigma", "0"], "--sigma must be a finite number > 0"),
    (["calibrate", "{tmp}/meas.csv", "--sigma", "lots"], "argument --sigma: invalid float value"),
    (["calibrate", "{tmp}/meas.csv", "--header", "maybe"], "argument --header: invalid choice"),
    (["calibrate", "{tmp}/meas.csv", "--plot", "{tmp}/map.txt"], "extension .txt"),
    (["calibrate", "{tmp}/missing.csv"], "cannot read"),
]


@pytest.mark.parametrize("argv, fragment", BAD, ids=[" ".join(a[:2]) + f" #{k}" for k, (a, _) in enumerate(BAD)])
def test_bad_input_is_one_line_with_status_2(capsys, files, argv, fragment):
    code, _, err = run(capsys, [a.replace("{tmp}", str(files)) for a in argv])
    assert code == 2, err
    assert "Traceback" not in err
    last = err.strip().splitlines()[-1]
    assert "error:" in last and fragment in last, err


def test_no_traceback_in_a_real_process(tmp_path):
    """The installed entry point, not just main(): an unwritable export and a closed pipe."""
    cmd = [sys.executable, "-m", "solvers.cli", "degree", EXAMPLE]
    done = subprocess.run(cmd + ["--export", "m2", str(tmp_path)], capture_output=True, text=True, cwd=ROOT)
    assert done.returncode == 2 and "Traceback" not in done.stderr and "is a directory" in done.stderr
    big = tmp_path / "big.ms"
    big.write_text("x,y\n0\nx^200-1,y^200-1\n")  # 40000 standard monomials: more than a pipe buffer
    cmd = [sys.executable, "-m", "solvers.cli", "degree", str(big), "--basis", "--basis-limit", "40000"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=ROOT)
    proc.stdout.readline()
    proc.stdout.close()  # as `| head -1` does
    err = proc.stderr.read().decode()
    proc.wait()
    assert "Traceback" not in err and "BrokenPipe" not in err


# -- every check before the work (issue 55): numbers, shapes and output paths refused at reading -----------

def _network_csv(path: Path, cell: str | None = None) -> None:
    """A consistent 8 x 5 network's measurements (seeded), with the entry of line 4, column 3 replaced by cell."""
    import numpy as np

    from solvers.synthetic import random_network

    F = random_network(8, 5, rng=np.random.default_rng(3)).measurements()
    rows = ["rx," + ",".join(f"s{j + 1}" for j in range(5))]
    rows += [f"r{i + 1}," + ",".join(f"{v:.6f}" for v in row) for i, row in enumerate(F)]
    if cell is not None:
        cells = rows[3].split(",")
        cells[2] = cell
        rows[3] = ",".join(cells)
    path.write_text("\n".join(rows) + "\n")


@pytest.fixture
def never_calibrated(monkeypatch):
    """Fails the test if the calibration starts: the error must come before any computing."""
    import solvers.calibration

    def refuse(*args, **kwargs):
        raise AssertionError("the calibration ran before the error")

    monkeypatch.setattr(solvers.calibration, "calibrate", refuse)


@pytest.mark.parametrize("cell, fragment", [
    ("1e300", "e.csv: line 4, column 3: '1e300' is out of range: a measurement's square summed over the 8 x 5 matrix"),
    ("-1e200", "e.csv: line 4, column 3: '-1e200' is out of range"),
    ("1e20", "e.csv: line 4, column 3: '1e20' is absurd next to the other measurements"),
])
def test_calibrate_refuses_a_huge_cell_at_reading(capsys, tmp_path, never_calibrated, cell, fragment):
    _network_csv(tmp_path / "e.csv", cell)
    code, _, err = run(capsys, ["calibrate", str(tmp_path / "e.csv")])
    assert code == 2 and fragment in err and len(err.strip().splitlines()) == 1, err


def test_a_gross_error_is_still_left_to_the_calibration(tmp_path):
    """1e4 among distances of tens is a gross error the robust calibration rejects, not an absurd value."""
    from solvers.calibrate_io import read_measurements

    _network_csv(tmp_path / "e.csv", "1e4")
    assert read_measurements(str(tmp_path / "e.csv")).F[2, 1] == 1e4


def test_too_few_receivers_is_said_before_the_work(capsys, tmp_path, never_calibrated):
    (tmp_path / "one.csv").write_text("rx," + ",".join(f"s{j}" for j in range(8)) + "\nr1," + ",".join(["1.5"] * 8) + "\n")
    code, _, err = run(capsys, ["calibrate", str(tmp_path / "one.csv")])
    assert code == 2 and ("one.csv: 1 row (receivers) x 8 columns (transmitters) cannot be calibrated in 2D: too few "
                          "receivers (1): each transmitter is placed from >= 4 receivers") in err, err


def test_an_empty_file_is_the_same_words_in_tdoa_and_calibrate(capsys, tmp_path):
    (tmp_path / "empty.csv").write_bytes(b"")
    said = []
    for verb in ("tdoa", "calibrate"):
        code, _, err = run(capsys, [verb, str(tmp_path / "empty.csv")])
        assert code == 2, err
        said.append(err.split("error: ", 1)[1].strip())
    assert said == [f"{tmp_path / 'empty.csv'}: no data (empty file)"] * 2


UNWRITABLE = "/proc/tdoa-workbench-test"  # writing there fails even for root, whom permissions do not stop


@pytest.mark.skipif(not Path("/proc/self").exists(), reason="needs Linux's /proc")
@pytest.mark.parametrize("argv, option", [
    (["calibrate", "{csv}", "--out", UNWRITABLE + ".json"], "--out"),
    (["calibrate", "{csv}", "--plot", UNWRITABLE + ".png"], "--plot"),
    (["calibrate", "{csv}", "--csv", UNWRITABLE + ".csv"], "--csv"),
    (["degree", EXAMPLE, "--export", "msolve", UNWRITABLE + ".ms"], "--export"),
    (["generate", "{tmp}/par.txt", "--out", UNWRITABLE], "--out"),
    (["count", "{tmp}/par.txt", "--json", UNWRITABLE + ".json"], "--json"),
    (["count", "{tmp}/par.txt", "--checkpoint", UNWRITABLE], "--checkpoint"),
    (["tables", "--quick", "--out", UNWRITABLE], "--out"),
])
def test_an_unwritable_output_fails_before_the_work(capsys, tmp_path, never_calibrated, monkeypatch, argv, option):
    """Every verb that writes tries its output paths first (one check, solvers.calibrate_io.check_output_path)."""
    import solvers.count
    import solvers.generate

    for module, name in ((solvers.count, "count"), (solvers.generate, "generate")):
        monkeypatch.setattr(module, name, lambda *a, **k: pytest.fail("the work ran before the error"))
    _network_csv(tmp_path / "m.csv")
    (tmp_path / "par.txt").write_text("unknowns: x\nparameters: a\nequations:\nx^2 - a\n")
    code, _, err = run(capsys, [a.replace("{csv}", str(tmp_path / "m.csv")).replace("{tmp}", str(tmp_path))
                                for a in argv])
    path = argv[argv.index(option) + (2 if option == "--export" else 1)]
    assert code == 2 and f"cannot write {path} ({option}): " in err and len(err.strip().splitlines()) == 1, err


def test_the_unwritable_check_leaves_no_file_behind(tmp_path):
    from solvers.calibrate_io import check_output_path

    check_output_path(str(tmp_path / "new.json"), "--out")
    check_output_path(str(tmp_path / "a" / "b"), "--out", directory=True)
    assert list(tmp_path.iterdir()) == []
    (tmp_path / "old.json").write_text("kept")
    check_output_path(str(tmp_path / "old.json"), "--out")
    assert (tmp_path / "old.json").read_text() == "kept"


@pytest.mark.parametrize("verb", [["degree"], ["solve"], ["count"], ["generate", "--out", "{tmp}/g"],
                                  ["template-check"], ["tdoa"], ["calibrate"]])
def test_the_same_words_for_the_same_input_problem_in_every_verb(capsys, tmp_path, verb):
    """A missing file, a directory and a 0-byte file: one wording, whatever the verb reads (a system, a
    measurement CSV or a recording)."""
    (tmp_path / "empty").write_bytes(b"")
    (tmp_path / "adir").mkdir()
    said = {}
    for name in ("empty", "adir", "missing"):
        argv = [verb[0], str(tmp_path / name)] + [a.replace("{tmp}", str(tmp_path)) for a in verb[1:]]
        code, _, err = run(capsys, argv)
        assert code == 2, err
        said[name] = err.split("error: ", 1)[1].strip()
    assert said["empty"] == f"{tmp_path / 'empty'}: no data (empty file)"
    assert said["adir"] == f"cannot read {tmp_path / 'adir'}: it is a directory"
    if verb[0] not in ("generate", "template-check"):  # those take a label too: 'no such file (and not a label)'
        assert said["missing"] == f"cannot read {tmp_path / 'missing'}: no such file"


def test_anchor_coordinates_are_not_judged_by_a_network_spread():
    """Near-collinear anchors (y spread 1e-6 beside x spread 5) are coordinates, not a measurement matrix."""
    from solvers.calibrate_io import parse_measurements

    text = "node,x,y,std\nr1,0,0,0.01\nr2,5,0.000001,0.01\nr3,10,0.000002,0.01\n"
    assert parse_measurements(text, "a.csv", header="both", network=False).F[2, 0] == 10
    with pytest.raises(Exception, match="is absurd next to the other measurements"):
        parse_measurements(text, "a.csv", header="both")


def test_the_absurd_value_test_passes_hard_real_shapes():
    """Seeded networks with far transmitters (up to 1e6 times the array), offsets up to 1e12 (absolute
    timestamps), 20 % missing and 1 mm noise: none is refused at reading; one cell 1e6 spreads off is."""
    import numpy as np

    from solvers.calibrate_io import MeasurementFileError, _check_magnitudes

    rng = np.random.default_rng(55)
    for _ in range(300):
        m, n, dim = int(rng.integers(4, 20)), int(rng.integers(3, 20)), int(rng.choice([2, 3]))
        R = rng.normal(size=(m, dim)) * rng.choice([1, 10])
        far = rng.random(n) < rng.random()
        S = rng.normal(size=(n, dim)) * np.where(far, 10 ** rng.uniform(2, 6, n), 1)[:, None]
        F = np.linalg.norm(R[:, None] - S[None], axis=2) + rng.normal(size=n) * 10 ** rng.uniform(0, 12)
        F = F + rng.normal(size=(m, n)) * 1e-3
        F[rng.random(F.shape) < 0.2] = np.nan
        cells = [[repr(v) for v in row] for row in F]
        _check_magnitudes(F, list(range(1, m + 1)), 1, cells, "sim")
    F = np.arange(40.0).reshape(8, 5) % 7
    F[2, 1] = 1e8
    with pytest.raises(MeasurementFileError, match="line 3, column 3: '1e8' is absurd"):
        _check_magnitudes(F, list(range(1, 9)), 1, [["1e8" if (i, j) == (2, 1) else "x" for j in range(5)]
                                                    for i in range(8)], "sim")
