"""First call in a fresh environment: the seconds of a new process's first 9r/3s solve and 10r/6s calibrate,
and of a user's own systems: ``generate`` in one new process, then the first ``solve()`` of the generated
module in another (issue 46: together <= 10 s; the solve <= 1 s once the caches are warm).

Each case runs in a new Python process whose caches are empty temporary directories
(``TDOA_WORKBENCH_CACHE``: the tapes' C libraries; ``NUMBA_CACHE_DIR``: numba's compiled functions;
``XDG_CACHE_HOME``: where the F4 kernels go when the source tree is read-only), so
it pays everything a new machine, container or CI run pays: imports, compiling, the first call, then a
second call (the steady state) for comparison. (Neither call loads the F4 kernels, whose library sits in
``analysis/__pycache__``, nor any numba function: checked in a fresh process.) Every phase's
seconds are printed and written to ``tables/first_call.timing.json`` (untracked: seconds are facts of
the run, not results): wall seconds, and CPU seconds of the process and the compilers it ran (on a shared,
loaded machine the wall time stretches; the CPU time is what the work costs). Target (issue 34): first
call <= 3 s.

    python scripts/bench_first_call.py [--repeat 2] [--native on|off] [--cases all|committed|user] [--clone]

``--native off`` sets ``TDOA_WORKBENCH_NATIVE=off`` (no C compiler: the numba kernels only). The user
systems (:data:`USER_SYSTEMS`: examples/circle.sys and two more) share one fresh cache between their two
processes (the second process finds what the first compiled, as a user's machine would); their third
phase, a second process's solve with every cache warm, is the steady state. ``--clone``: the user systems run
the code of a fresh ``git clone`` of HEAD, so that ``generate`` also compiles the F4 kernels (a new checkout has
none in its ``analysis/engine/__pycache__``).
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


#: A user's own systems in examples/ (name -> (parameter values of the instance solved, monodromy seed)): 4, 9 and
#: 27 roots.
USER_SYSTEMS = {
    "circle.sys": ([5.0, 1.0, 1.5], 0),
    "two_cubics.sys": ([0.5, 1.0, -0.7, 0.3], 0),
    "three_cubics.sys": ([0.5, 1.0, -0.7, 0.3, 1.1, -0.4], 0),
}

#: generate into ./gen (a new process); the module's solve (the next process, twice: first and steady state).
GENERATE = CLOCK + """
import sys
t0 = clock()
from solvers.generate import generate
from analysis.formulations.parametric import parse
t1 = clock()
built = generate(parse(open(sys.argv[1]).read(), sys.argv[1]), "homotopy", out="gen", seed=int(sys.argv[2]))
t2 = clock()
phases([t0, t1, t2], ["import", "generate"], [built.module, built.degree])
"""
SOLVE = CLOCK + """
import glob, importlib.util, json, sys
t0 = clock()
import numpy as np
path = glob.glob("gen/*.py")[0]
spec = importlib.util.spec_from_file_location("user_solver", path)
module = importlib.util.module_from_spec(spec)
spec.loader.exec_module(module)
t1 = clock()
q = np.array(json.loads(sys.argv[1]))
first = module.solve(q)
t2 = clock()
second = module.solve(q * 1.01)
t3 = clock()
phases([t0, t1, t2, t3], ["import", "first solve", "second solve"], [int(np.isfinite(first).all(axis=1).sum())])
"""


def _env(tmp: str, native: str, root: Path = ROOT) -> dict:
    env = dict(os.environ, TDOA_WORKBENCH_CACHE=str(Path(tmp) / "cache"), NUMBA_CACHE_DIR=str(Path(tmp) / "numba"),
               XDG_CACHE_HOME=str(Path(tmp) / "xdg"),
               PYTHONPATH=os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep))
    if native == "off":
        env["TDOA_WORKBENCH_NATIVE"] = "off"
    return env


def _child(argv: list[str], tmp: str, env: dict) -> dict:
    import time

    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", *argv], cwd=tmp, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if done.returncode:
        raise RuntimeError(f"the child failed:\n{done.stderr}")
    record = json.loads(done.stdout.strip().splitlines()[-1])
    record["process wall"] = wall
    return record


def run_case(program: str, native: str) -> dict:
    """Run `program` in a new process with empty caches; return its timings (and its wall time)."""
    with tempfile.TemporaryDirectory(prefix="first-call-") as tmp:
        return _child([program], tmp, _env(tmp, native))


def run_user_case(name: str, native: str, clone: bool = False) -> dict:
    """A user's system in a fresh environment: ``generate`` in a new process, then the generated module's first
    solve in another (the same caches), then a third process's solve (every cache warm). ``clone``: the code of a
    fresh ``git clone`` of HEAD (no compiled F4 kernels in its analysis/engine/__pycache__, as a new checkout)."""
    values, seed = USER_SYSTEMS[name]
    with tempfile.TemporaryDirectory(prefix="first-call-") as tmp:
        root = ROOT
        if clone:
            root = Path(tmp) / "clone"
            subprocess.run(["git", "clone", "-q", str(ROOT), str(root)], check=True)
        env = _env(tmp, native, root)
        Path(tmp, name).write_text((ROOT / "examples" / name).read_text())
        gen = _child([GENERATE, name, str(seed)], tmp, env)
        first = _child([SOLVE, json.dumps(values)], tmp, env)
        warm = _child([SOLVE, json.dumps(values)], tmp, env)
    record = {f"generate {k}": v for k, v in gen.items() if k != "results"}
    record.update({f"new process {k}": v for k, v in first.items() if k != "results"})
    record["warm process first solve wall"] = warm["first solve wall"]
    record["generate + first solve process wall"] = gen["process wall"] + first["process wall"]
    record["results"] = gen["results"] + first["results"]
    return record


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=1, help="runs of each case (each in a fresh environment)")
    parser.add_argument("--native", choices=("on", "off"), default="on",
                        help="off: TDOA_WORKBENCH_NATIVE=off (the fallback without a C compiler)")
    parser.add_argument("--cases", choices=("all", "committed", "user"), default="all",
                        help="the committed solvers' cases, the user systems', or both (default)")
    parser.add_argument("--clone", action="store_true",
                        help="user systems: run the code of a fresh git clone of HEAD (its F4 kernels compiled too)")
    args = parser.parse_args(argv)
    cases = {**({name: (run_case, program) for name, program in CHILD.items()} if args.cases != "user" else {}),
             **({f"user {name}": (run_user_case, name) for name in USER_SYSTEMS} if args.cases != "committed" else {})}
    runs: dict[str, list[dict]] = {name: [] for name in cases}
    for k in range(args.repeat):
        for name, (run, what) in cases.items():  # interleaved: a slow phase of the machine hits every case
            record = run(what, args.native, args.clone) if run is run_user_case else run(what, args.native)
            runs[name].append(record)
            print(f"{name} (run {k + 1}, native {args.native}): " + ", ".join(
                f"{key} {value:.2f} s" for key, value in record.items() if isinstance(value, float))
                + f"; results {record['results']}; load average {os.getloadavg()[0]:.1f}", flush=True)
    OUT.write_text(json.dumps({"native": args.native, "clone": args.clone, "runs": runs}, indent=2) + "\n",
                   encoding="utf-8")
    print(f"wrote {OUT.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
