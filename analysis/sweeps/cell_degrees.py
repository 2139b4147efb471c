"""Degree of one formulation of any model and dimension, checked on two primes, for the TOA and 3D tables.

This module owns the computation behind ``tables/toa.*`` and ``tables/table3d.*``: a formulation
(:class:`analysis.formulations.tdoa.Formulation` of any :class:`~analysis.formulations.tdoa.TDOAConfig`) becomes a
system over GF(p) on a consistent instance whose known root is checked (:func:`check_root`), the Jacobian
rank at that root decides at once whether the root is isolated, and otherwise
:func:`analysis.engine.degree.analyse` computes the degree modulo each prime (:class:`PrimeDisagreement` unless
they agree). An msolve run on the first prime can confirm the degree (:class:`EngineDisagreement`
otherwise). :func:`cell_degree_capped` runs one formulation in a child process under a wall-time cap.

Degree counted. Compaction formulations multiply A and B by det H, which adds spurious solutions (in 3D
even positive-dimensional ones: adj H = 0 when rank H <= 1). The degree reported is that of
I + (t g - 1) in grevlex with one more unknown t, g = det H (times det D~[:3, :3] when 3D TDOA's B_j,
j >= 5, are used: :func:`analysis.formulations.kd.nonzero_conditions`): the number of solutions with
g != 0, counted with multiplicity (Rabinowitsch; equal to deg I : g^inf). Each such solution is one network up to
rotation, reflection and translation. Direct formulations need no saturation; their degree is divided by
the gauge group's order 2^K (:attr:`TDOAConfig.gauge_group_order`), which must divide it.
"""
from __future__ import annotations

import dataclasses
import multiprocessing
import time
from dataclasses import dataclass
from typing import Callable, Sequence

from .complexity import jacobian_rank
from ..engine.degree import DEFAULT_PRIMES, EngineDisagreement, PrimeDisagreement, analyse
from ..engine.f4 import F4Options
from ..formulations.tdoa import (Formulation, as_formulation, check_root, equation_names, gf_equations,
                           sample_gf_instance)
from ..formulations.kd import nonzero_conditions
from ..engine.linalg import MatrixTooLarge
from ..engine.ring import Poly, Ring

__all__ = ["CellDegree", "NotDivisible", "cell_degree", "cell_degree_capped", "formulation_system"]

SATURATION_VARIABLE = "t_"
"""The extra unknown t of t det H - 1 (its name cannot clash: unknown names have no underscore)."""


class NotDivisible(ArithmeticError):
    """A direct formulation's degree is not a multiple of its gauge group's order (the group does not act
    freely, or the instance is not generic)."""


@dataclass(frozen=True)
class CellDegree:
    """One formulation's degree, as a table row.

    status: ``ok`` (zero-dimensional, degree agreed by every prime), ``positive-dimensional`` (the Jacobian
    at the known root has rank below the number of unknowns; no Gröbner basis computed), ``cap`` (an F4
    matrix exceeded ``max_cells``), ``timeout`` (the wall-time cap of :func:`cell_degree_capped`).
    degree: solutions with det H != 0 (compaction) or all solutions (direct), with multiplicity.
    up_to_gauge: degree / group_order: the number of networks up to rotation, reflection and translation.
    tangent_dim: unknowns minus the Jacobian rank at the known root (0: the root is isolated).
    msolve_degree: msolve's degree on the first prime ("" when not run).
    """

    formulation: str
    config: str
    model: str
    dim: int
    parametrization: str
    m: int
    n: int
    excess: int
    unknowns: int
    equations: int
    status: str
    degree: int | None
    up_to_gauge: int | None
    group_order: int
    tangent_dim: int | None
    primes: str
    seed: int
    max_matrix: str
    seconds: float
    msolve_degree: int | None = None
    note: str = ""

    def row(self) -> dict:
        """The record as a flat dict (CSV row), fields in declaration order."""
        return dataclasses.asdict(self)


def formulation_system(formulation: Formulation, seed: int = 0, saturate: bool | None = None
                       ) -> tuple[Callable[[int], list[Poly]], Callable[[int], tuple[int, ...]]]:
    """(prime -> polynomials, prime -> known root) of a formulation on the instance of ``seed``.

    The instance is sampled once per prime and its known root checked against every equation. With
    ``saturate`` (default: compaction and gram formulations) the unknowns get t and the system t det H - 1 (det G); the
    root then gets t = 1 / det H.
    """
    config = formulation.config
    if saturate is None:
        saturate = config.parametrization in ("compaction", "gram")
    names = config.unknowns + ((SATURATION_VARIABLE,) if saturate else ())
    cache: dict[int, tuple[list[Poly], tuple[int, ...]]] = {}

    def build(p: int) -> tuple[list[Poly], tuple[int, ...]]:
        if p not in cache:
            instance = sample_gf_instance(config, p, seed)
            check_root(formulation, instance)
            ring = Ring(names, p, "grevlex")
            pad = (0,) if saturate else ()
            polys = [ring.from_terms({e + pad: c for e, c in eq.items()}) for eq in gf_equations(formulation, instance)]
            root = tuple(instance.root)
            if saturate:
                det = ring.one()
                for cond in nonzero_conditions(formulation, [list(r) for r in instance.F], p):
                    det = det * ring.from_terms({e + (0,): c for e, c in cond.items()})
                value = det.evaluate(root + (0,)) % p
                if value == 0:
                    raise ArithmeticError(f"a nonzero condition vanishes at the known root of {formulation.label} mod {p}")
                polys.append(ring.gen(SATURATION_VARIABLE) * det - ring.one())
                root += (pow(value, -1, p),)
            cache[p] = (polys, root)
        return cache[p]

    return (lambda p: build(p)[0]), (lambda p: build(p)[1])


def _exponent_dicts(polys: Sequence[Poly]) -> list[dict]:
    return [dict(f.terms()) for f in polys]


def cell_degree(formulation: Formulation | str, primes: Sequence[int] = DEFAULT_PRIMES, seed: int = 0,
                max_cells: int = 60_000_000, msolve: str | None = None, max_memory: int | None = None,
                threads: int = 1, verbose: bool = False) -> CellDegree:
    """The degree of one formulation (module docstring), agreed by every prime.

    Parameters
    ----------
    formulation : a formulation or its label (``"4r6s-toa3d:all"``).
    primes : at least two for a checked degree.
    seed : the instance's seed (the same seed on every prime).
    max_cells : F4 matrix cap (rows x cols); above it the row has status ``cap``.
    msolve : an msolve executable: its degree on the first prime must agree (EngineDisagreement).
    max_memory, threads, verbose : F4's memory cap (bytes; default :func:`analysis.engine.f4.default_max_memory`, a share of the machine's available memory;
        above it the row has status ``cap`` too), row-reduction threads, one line per F4 round on stderr.

    Raises PrimeDisagreement when primes disagree, NotDivisible when a direct degree is not a multiple of
    the gauge group's order, InconsistentSample when the known root fails an equation.
    """
    formulation = as_formulation(formulation)
    config = formulation.config
    t0 = time.perf_counter()
    system, root = formulation_system(formulation, seed)
    nvars = system(primes[0])[0].ring.nvars
    rank = jacobian_rank(_exponent_dicts(system(primes[0])), root(primes[0]), primes[0])
    base = dict(formulation=formulation.label, config=config.label, model=config.model, dim=config.dim,
                parametrization=config.parametrization, m=config.m, n=config.n, excess=config.excess,
                unknowns=config.n_unknowns, equations=formulation.n_equations, group_order=config.gauge_group_order,
                tangent_dim=nvars - rank, primes=" ".join(map(str, primes)), seed=seed)
    if rank < nvars:
        return CellDegree(**base, status="positive-dimensional", degree=None, up_to_gauge=None, max_matrix="",
                          seconds=time.perf_counter() - t0,
                          note=f"Jacobian rank {rank} < {nvars} unknowns at the known root: no Groebner basis computed")
    try:
        options = F4Options(max_matrix_cells=max_cells, threads=threads, verbose=verbose)
        if max_memory is not None:
            options = dataclasses.replace(options, max_memory=max_memory)
        report = analyse(system, primes, options)
    except MatrixTooLarge as e:
        return CellDegree(**base, status="cap", degree=None, up_to_gauge=None, max_matrix="",
                          seconds=time.perf_counter() - t0, note=str(e))
    for result in report.per_prime:
        point = root(result.prime)
        if any(g.evaluate(point) % result.prime for g in result.gb.basis):
            raise ArithmeticError(f"the known root does not vanish on the Groebner basis of {formulation.label} "
                                  f"mod {result.prime}")
    rows, cols = report.max_matrix
    if not report.zero_dimensional:
        return CellDegree(**base, status="positive-dimensional", degree=None, up_to_gauge=None,
                          max_matrix=f"{rows}x{cols}", seconds=time.perf_counter() - t0,
                          note=f"the known root is isolated, but another component has dimension {report.dimension}")
    degree = report.degree
    up, remainder = divmod(degree, config.gauge_group_order)
    if remainder:
        raise NotDivisible(f"{formulation.label}: degree {degree} is not a multiple of the gauge group's "
                           f"order {config.gauge_group_order}")
    msolve_degree, note = None, ""
    if msolve is not None:
        check = analyse(system, primes[:1], engines=("msolve",), msolve=msolve)
        msolve_degree = check.degree
        if msolve_degree != degree:
            raise EngineDisagreement(f"{formulation.label}: msolve gives degree {msolve_degree} mod {primes[0]}, "
                                     f"the own engine {degree}")
        note = f"msolve agrees on {primes[0]}"  # no timing here: the note is a deterministic column
    return CellDegree(**base, status="ok", degree=degree, up_to_gauge=up, max_matrix=f"{rows}x{cols}",
                      seconds=time.perf_counter() - t0, msolve_degree=msolve_degree, note=note)


def _child(conn, label: str, primes: tuple[int, ...], seed: int, max_cells: int, msolve: str | None,
           options: dict) -> None:
    """Child process body of :func:`cell_degree_capped`: the record, or the exception, through the pipe."""
    try:
        conn.send(("ok", cell_degree(label, primes, seed, max_cells, msolve, **options)))
    except BaseException as e:  # sent to the parent, which re-raises it
        conn.send(("error", e))
    finally:
        conn.close()


def cell_degree_capped(formulation: Formulation | str, seconds: float, primes: Sequence[int] = DEFAULT_PRIMES,
                       seed: int = 0, max_cells: int = 60_000_000, msolve: str | None = None,
                       **options) -> CellDegree:
    """:func:`cell_degree` in one child process stopped after ``seconds`` of wall time (``options``: its
    max_memory, threads and verbose).

    A formulation that runs out of time gets status ``timeout`` (its cap in the note), never dropped;
    exceptions raised in the child (disagreeing primes, inconsistent samples) are raised here.
    """
    formulation = as_formulation(formulation)
    config = formulation.config
    ctx = multiprocessing.get_context("fork")
    parent, child = ctx.Pipe(duplex=False)
    t0 = time.perf_counter()
    proc = ctx.Process(target=_child, args=(child, formulation.label, tuple(primes), seed, max_cells, msolve, options))
    proc.start()
    child.close()
    try:
        if parent.poll(seconds):
            kind, value = parent.recv()
            proc.join()
            if kind == "error":
                raise value
            return value
    finally:
        if proc.is_alive():
            proc.terminate()
            proc.join()
        parent.close()
    return CellDegree(formulation=formulation.label, config=config.label, model=config.model, dim=config.dim,
                      parametrization=config.parametrization, m=config.m, n=config.n, excess=config.excess,
                      unknowns=config.n_unknowns, equations=formulation.n_equations, status="timeout", degree=None,
                      up_to_gauge=None, group_order=config.gauge_group_order, tangent_dim=None,
                      primes=" ".join(map(str, primes)), seed=seed, max_matrix="",
                      seconds=time.perf_counter() - t0, note=f"stopped at the {seconds:g} s wall-time cap")


# --------------------------------------------------------------------------------------------------
# Plain-text tables
# --------------------------------------------------------------------------------------------------

FIELDS: tuple[str, ...] = tuple(f.name for f in dataclasses.fields(CellDegree))
"""CSV columns of a cell-degree table, in :class:`CellDegree` order."""


def _whole_cell(record: CellDegree) -> bool:
    formulation = as_formulation(record.formulation)
    return formulation.equations == equation_names(formulation.config)


def read_records(path: str) -> list[CellDegree]:
    """The records of a cell-degree table's CSV (:func:`write_table`), as written (round trip: the same CSV)."""
    import csv
    import typing

    types = typing.get_type_hints(CellDegree)
    out = []
    with open(path, newline="") as handle:
        for row in csv.DictReader(handle):
            values = {}
            for name in FIELDS:
                text, kind = row[name], types[name]
                if kind is str:
                    values[name] = text
                elif kind is float:
                    values[name] = float(text)
                else:  # int or int | None
                    values[name] = int(text) if text != "" else None
            out.append(CellDegree(**values))
    return out


def cell_summary(records: Sequence[CellDegree], evidence: str = "") -> str:
    """What a grid cell shows: the smallest count up to the gauge over its zero-dimensional formulations (the
    cell's complexity, as in Table 3), written ``<=N`` when the whole cell's formulation has no count and
    N > 1 (N then bounds the number of networks from above); else ``cap``/``timeout`` when a formulation ran out of budget
    (the cell is open); else ``dim>0`` with the smallest tangent dimension at the known root. ``evidence``: what
    a cell without a certified count shows instead of cap/timeout/dim>0 (a count by other means, which says
    so: tables/monodromy3d.* for the 3D minimal cells)."""
    counts = [r.up_to_gauge for r in records if r.status == "ok"]
    if evidence and not counts:
        return evidence
    if counts:
        whole = any(r.status == "ok" and _whole_cell(r) for r in records)
        # a subset with one solution leaves exactly one for the whole cell: the known root satisfies both
        return str(min(counts)) if whole or min(counts) == 1 else f"<={min(counts)}"
    stopped = [r.status for r in records if r.status in ("cap", "timeout")]
    if stopped:
        return "/".join(dict.fromkeys(stopped))
    tangent = min(r.tangent_dim for r in records if r.tangent_dim is not None)
    return f"dim>0 (tangent {tangent})"


def markdown_grid(records: Sequence[CellDegree], parametrization: str = "compaction",
                  evidence: dict[tuple[str, int, int, int], str] | None = None) -> str:
    """One m x n grid per (model, dimension) of the records of one parametrization (module docstring);
    ``evidence``: :func:`cell_summary`'s, per (model, dim, m, n)."""
    evidence = evidence or {}
    out = []
    groups: dict[tuple[str, int], dict[tuple[int, int], list[CellDegree]]] = {}
    for r in records:
        if r.parametrization == parametrization:
            groups.setdefault((r.model, r.dim), {}).setdefault((r.m, r.n), []).append(r)
    for (model, dim), cells in groups.items():
        ms = sorted({m for m, _ in cells})
        ns = sorted({n for _, n in cells})
        out.append(f"**{model.upper()} {dim}D ({parametrization}): smallest number of solutions (up to rotation, "
                   "reflection and translation) over the cell's zero-dimensional formulations (<=N: only a subset of "
                   "the cell's equations has a count, N bounds the cell's), else cap/timeout (open), else dim>0 "
                   "(smallest tangent dimension at the known root); blank: not in the table**\n")
        out.append("| m/n | " + " | ".join(map(str, ns)) + " |")
        out.append("|---|" + "---|" * len(ns))
        for m in ms:
            row = [cell_summary(cells[(m, n)], evidence.get((model, dim, m, n), "")) if (m, n) in cells else ""
                   for n in ns]
            out.append(f"| {m} | " + " | ".join(row) + " |")
        out.append("")
    return "\n".join(out)


def markdown_rows(records: Sequence[CellDegree]) -> str:
    """Every record as one Markdown table row (the CSV's main columns)."""
    cols = ("formulation", "excess", "unknowns", "equations", "status", "degree", "group_order", "up_to_gauge",
            "tangent_dim", "primes", "msolve_degree", "max_matrix", "note")
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for r in records:
        row = r.row()
        lines.append("| " + " | ".join("" if row[c] is None else str(row[c]).replace("|", "/") for c in cols) + " |")
    return "\n".join(lines) + "\n"


def provenance(root: str) -> dict:
    """Commit and dirty flag of the checkout at ``root`` (read before any output is written)."""
    import subprocess

    def git(*args: str) -> str:
        try:
            return subprocess.run(["git", *args], cwd=root, capture_output=True, text=True, timeout=30).stdout.strip()
        except (OSError, subprocess.SubprocessError):
            return ""

    return {"commit": git("rev-parse", "HEAD"), "worktree_dirty": bool(git("status", "--porcelain", "--untracked-files=no"))}


def write_table(records: Sequence[CellDegree], out_dir: str, stem: str, title: str, regenerate: str,
                meta: dict, notes: str = "", evidence: dict[tuple[str, int, int, int], str] | None = None) -> list[str]:
    """Write ``<stem>.csv``, ``<stem>.md`` and ``<stem>.meta.json`` into out_dir; returns the paths.

    Rows keep the given order (the scripts give a fixed one); the Markdown starts with the
    ``# Regenerate:`` line, then the title, the grids, ``notes`` and every row.
    """
    import csv
    import json
    import os
    import platform

    import numpy

    os.makedirs(out_dir, exist_ok=True)
    paths = [os.path.join(out_dir, f"{stem}.{ext}") for ext in ("csv", "md", "meta.json")]
    with open(paths[0], "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(FIELDS), lineterminator="\n")
        writer.writeheader()
        for r in records:
            row = r.row()
            row["seconds"] = f"{r.seconds:.2f}"
            writer.writerow(row)
    grids = "\n".join(markdown_grid(records, p, evidence) for p in ("compaction", "direct"))
    with open(paths[1], "w") as handle:
        handle.write(f"<!-- # Regenerate: {regenerate}; provenance in {stem}.meta.json -->\n\n**{title}**\n\n"
                     f"{grids}\n{notes}\nEvery row:\n\n{markdown_rows(records)}")
    full = dict(meta)
    full.setdefault("versions", {"python": platform.python_version(), "numpy": numpy.__version__})
    full.setdefault("machine", {"platform": platform.platform(), "cpus": os.cpu_count()})
    with open(paths[2], "w") as handle:
        json.dump(full, handle, indent=2)
        handle.write("\n")
    return paths


def run_table_script(argv: Sequence[str] | None, doc: str, root: str, script: str, stem: str, title: str, notes: str,
                     jobs: Callable[[], Sequence[tuple[Formulation, bool]]], meta_extra: dict,
                     seconds: float = 120.0, max_cells: int = 30_000_000,
                     check: Callable[[Sequence[CellDegree]], None] | None = None,
                     evidence: Callable[[], tuple[dict[tuple[str, int, int, int], str], str]] | None = None) -> int:
    """The command line of a cell-degree table script (``scripts/toa_table.py``, ``scripts/table3d.py``).

    Options --seconds (wall-time cap per formulation), --max-cells (F4 matrix cap), --out-dir (default
    root/tables), --reuse (take the records of the committed ``<stem>.csv`` instead of running the sweep:
    they must be the formulations of ``jobs()``, in order; the meta file keeps the sweep's provenance).
    ``jobs()`` gives the formulations in table order, each with whether msolve (when
    installed) must confirm its degree; ``check`` may raise on the finished records (e.g. two
    parametrizations disagreeing); ``evidence()`` gives counts by other means for cells without a certified
    one (:func:`cell_summary`) and a note naming where they come from. Writes ``<stem>.{csv,md,meta.json}``
    with provenance (commit and dirty flag read before anything is written, primes, seed, caps, versions,
    machine, seconds).
    """
    import argparse
    import datetime
    import os
    import sys

    from ..engine.msolve import find_msolve, msolve_version

    parser = argparse.ArgumentParser(description=doc.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=seconds, help=f"wall-time cap per formulation (default {seconds:g})")
    parser.add_argument("--max-cells", type=int, default=max_cells,
                        help=f"F4 matrix cap, rows x cols (default {max_cells})")
    parser.add_argument("--out-dir", default=os.path.join(root, "tables"))
    parser.add_argument("--reuse", action="store_true",
                        help=f"take the records of tables/{stem}.csv (no F4 sweep); merge the evidence only")
    args = parser.parse_args(argv)
    extra, evidence_note = evidence() if evidence is not None else ({}, "")
    if args.reuse:
        return _rewrite_table(root, args.out_dir, stem, title, notes + evidence_note, jobs, extra)
    exe = find_msolve()
    info = provenance(root)
    t_start = time.perf_counter()
    records = []
    for formulation, confirm in jobs():
        r = cell_degree_capped(formulation, args.seconds, DEFAULT_PRIMES, 0, args.max_cells, exe if confirm else None)
        records.append(r)
        print(f"{r.formulation:<45} {r.status:<22} degree {r.degree!s:<5} up to gauge {r.up_to_gauge!s:<5} "
              f"{r.seconds:.1f} s", file=sys.stderr, flush=True)
    if check is not None:
        check(records)
    command = f"python {script}" + "".join(
        f" {flag} {value:g}" for flag, value, default in (("--seconds", args.seconds, seconds),
                                                          ("--max-cells", args.max_cells, max_cells))
        if value != default)
    meta = {
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        **info,
        "command": command,
        "primes": list(DEFAULT_PRIMES), "seed": 0,
        **meta_extra,
        "caps": {"seconds_per_formulation": args.seconds, "max_matrix_cells": args.max_cells},
        "instances": "analysis.formulations.tdoa.sample_gf_instance(config, prime, seed 0): gauge-frame positions over GF(p)",
        "msolve": msolve_version(exe) or "not installed",
        "seconds_total": round(time.perf_counter() - t_start, 1),
    }
    paths = write_table(records, args.out_dir, stem, title, command, meta, notes + evidence_note, extra)
    print("wrote " + ", ".join(paths), file=sys.stderr)
    return 0


def _rewrite_table(root: str, out_dir: str, stem: str, title: str, notes: str,
                   jobs: Callable[[], Sequence[tuple[Formulation, bool]]],
                   evidence: dict[tuple[str, int, int, int], str]) -> int:
    """:func:`run_table_script` with --reuse: the committed records and meta, the evidence merged."""
    import json
    import os
    import sys

    source = os.path.join(root, "tables", stem)
    records = read_records(source + ".csv")
    wanted = [as_formulation(f).label for f, _ in jobs()]
    if [r.formulation for r in records] != wanted:
        raise ValueError(f"{source}.csv holds other formulations than the script's (rerun without --reuse)")
    with open(source + ".meta.json") as handle:
        meta = json.load(handle)
    paths = write_table(records, out_dir, stem, title, meta["command"], meta, notes, evidence)
    print("wrote " + ", ".join(paths) + " (records reused)", file=sys.stderr)
    return 0
