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
