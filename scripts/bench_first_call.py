"""First call in a fresh environment: the seconds of a new process's first 9r/3s solve and 10r/6s calibrate.

Each case runs in a new Python process whose caches are empty temporary directories
(``TDOA_WORKBENCH_CACHE``: the tapes' C libraries; ``NUMBA_CACHE_DIR``: numba's compiled functions), so
it pays everything a new machine, container or CI run pays: imports, compiling, the first call, then a
second call (the steady state) for comparison. (Neither call loads the F4 kernels, whose library sits in
``analysis/__pycache__``, nor any numba function: checked in a fresh process.) Every phase's
seconds are printed and written to ``tables/first_call.timing.json`` (untracked: seconds are facts of
the run, not results): wall seconds, and CPU seconds of the process and the compilers it ran (on a shared,
loaded machine the wall time stretches; the CPU time is what the work costs). Target (issue 34): first
call <= 3 s.

    python scripts/bench_first_call.py [--repeat 2] [--native on|off]

``--native off`` sets ``TDOA_WORKBENCH_NATIVE=off`` (no C compiler: the numba kernels only).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "tables" / "first_call.timing.json"

#: Timing of the child's phases: wall seconds, and CPU seconds of the process and of the compilers it ran
#: (a shared machine's load stretches the wall time; the CPU time is what the work costs).
CLOCK = """
import json, os, resource, time
def clock():
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.perf_counter(), time.process_time() + r.ru_utime + r.ru_stime
def phases(marks, names, extra):
    out = {n + " wall": b[0] - a[0] for n, a, b in zip(names, marks, marks[1:])}
    out.update({n + " cpu": b[1] - a[1] for n, a, b in zip(names, marks, marks[1:])})
    out["results"] = extra
    print(json.dumps(out))
"""

#: The child's programs: imports, first call, second call; one JSON line on stdout.
CHILD = {
    "solve_network 9r/3s": CLOCK + """
t0 = clock()
import numpy as np
from solvers.api import solve_network
from solvers.synthetic import random_network
t1 = clock()
F = random_network(9, 3, np.random.default_rng(0)).measurements()
first = solve_network(F)
t2 = clock()
F = random_network(9, 3, np.random.default_rng(1)).measurements()
second = solve_network(F)
t3 = clock()
phases([t0, t1, t2, t3], ["import", "first call", "second call"], [len(first), len(second)])
""",
    "calibrate 10r/6s": CLOCK + """
t0 = clock()
import numpy as np
from solvers import calibrate
from solvers.synthetic import random_network
t1 = clock()
rng = np.random.default_rng(0)
first = calibrate(random_network(10, 6, rng).measurements(0.01, rng), seed=0)
t2 = clock()
rng = np.random.default_rng(1)
second = calibrate(random_network(10, 6, rng).measurements(0.01, rng), seed=0)
t3 = clock()
phases([t0, t1, t2, t3], ["import", "first call", "second call"], [first.status, second.status])
""",
}


def run_case(program: str, native: str) -> dict:
    """Run `program` in a new process with empty caches; return its timings (and its wall time)."""
    import time

    with tempfile.TemporaryDirectory(prefix="first-call-") as tmp:
        env = dict(os.environ, TDOA_WORKBENCH_CACHE=str(Path(tmp) / "cache"), NUMBA_CACHE_DIR=str(Path(tmp) / "numba"),
                   PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep))
        if native == "off":
            env["TDOA_WORKBENCH_NATIVE"] = "off"
        t0 = time.perf_counter()
        done = subprocess.run([sys.executable, "-c", program], cwd=tmp, env=env, capture_output=True, text=True)
        wall = time.perf_counter() - t0
    if done.returncode:
        raise RuntimeError(f"the child failed:\n{done.stderr}")
    record = json.loads(done.stdout.strip().splitlines()[-1])
    record["process wall"] = wall
    return record


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=1, help="runs of each case (each in a fresh environment)")
    parser.add_argument("--native", choices=("on", "off"), default="on",
                        help="off: TDOA_WORKBENCH_NATIVE=off (the fallback without a C compiler)")
    args = parser.parse_args(argv)
    runs: dict[str, list[dict]] = {name: [] for name in CHILD}
    for k in range(args.repeat):
        for name, program in CHILD.items():  # interleaved: a slow phase of the machine hits both cases
            record = run_case(program, args.native)
            runs[name].append(record)
            print(f"{name} (run {k + 1}, native {args.native}): " + ", ".join(
                f"{key} {value:.2f} s" for key, value in record.items() if isinstance(value, float))
                + f"; results {record['results']}; load average {os.getloadavg()[0]:.1f}", flush=True)
    OUT.write_text(json.dumps({"native": args.native, "runs": runs}, indent=2) + "\n", encoding="utf-8")
    print(f"wrote {OUT.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
