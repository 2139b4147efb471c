"""The Jacobian's zero pattern, an elimination order that keeps it, and tapes renamed to follow that order.

The batched tracker factors the N x N Jacobian of H(x, s) several times a step (RK4: three stages and the
corrector's Newton steps), densely, with partial pivoting in the order of the unknowns and equations: on 3D 5r/9s
(45 unknowns) 80 % of a graph's CPU was that factorisation. Most parametrizations are sparse: each TDOA equation
holds one receiver's and one transmitter's coordinates and an offset (261 of 5r/9s's 2,025 entries are not zero).
Partial pivoting keeps a zero pattern that can be known before any number is: a row that can be the pivot of
column k, and every row that can receive a multiple of it, can afterwards hold any column that one of them could
(George & Ng, "Symbolic factorization for sparse Gaussian elimination with partial pivoting", SIAM J. Sci. Stat.
Comput. 8 (1987)), whichever row the numbers pick. :func:`elimination_order` picks the pivot columns greedily by
that bound (Markowitz's product of the candidate rows and the columns they could fill) and a candidate row for each
step's position; :func:`schedule` lists, per step, the positions that can be non-zero in the pivot column and the
columns the pivot row can hold. On 5r/9s the bound is 1,779 entry updates against 32,430 for the dense order.

The order is applied by renaming, not by another LU: :func:`permuted` returns the tapes with their unknowns'
registers and their output rows renamed (unknown ``cols[k]`` is the tracker's unknown k, equation ``rows[i]`` its
equation i), so the dense LU of the renamed Jacobian *is* the ordered factorisation, in the interpreter, numba's
tracker and the compiled one alike. The compiled LU (:func:`solvers.continuation.tape_native.lu_source`) then
skips what the schedule says is zero: the entries it leaves are exact zeros, whose updates (``a - 0 b``) and
interchanges change nothing, so it gives the dense LU's bits (up to the sign of a zero, and a NaN that the dense
order would have spread from a row into rows whose multiplier is zero). :class:`Sparse` carries the renamed tapes and
the maps of the unknowns both ways; :func:`plan` builds it where the order saves at least :data:`WORTH` of the work.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import tape_kernel, tape_native
from .slp import HomotopyTapes, Tape
from .tape_jit import CONST, OUT

__all__ = ["Sparse", "WORTH", "dense_cost", "elimination_order", "pattern", "permuted", "plan", "reached", "schedule"]

#: The ordered factorisation is used where its bound on entry updates is at most this share of the dense one
#: (5r/9s: 0.055; 3D 7r/5s: 0.24); elsewhere the tapes are left as they are (dense systems: the same bits as before).
WORTH = 0.5


def _zero_writes(tape) -> np.ndarray:
    """(instructions,) bool: the OUT instructions that write a register last set by the constant 0."""
    zero = np.zeros(tape.n_registers, dtype=bool)
    writes = np.zeros(len(tape.code), dtype=bool)
    for k, (op, d, a, _, _) in enumerate(tape.code):
        if op == OUT:
            writes[k] = zero[a]
        else:
            zero[d] = op == CONST and tape.imm[k] == 0.0
    return writes


def _jacobian_writes(tape, N: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(instruction indices, rows i, columns j) of the OUT instructions that write the Jacobian entry (i, j)."""
    d = tape.code[:, 1].astype(np.int64)
    k = np.nonzero((tape.code[:, 0] == OUT) & (d >= N) & (d < N + N * N))[0]
    return k, (d[k] - N) // N, (d[k] - N) % N


def pattern(tape, N: int) -> np.ndarray:
    """(N, N) bool: the Jacobian entries the tape can write as non-zero (output rows N + i N + j); an entry is zero
    only where its output is a register last set by the constant 0 (exact, no evaluation)."""
    nz = np.ones((N, N), dtype=bool)
    k, i, j = _jacobian_writes(tape, N)
    nz[i, j] = ~_zero_writes(tape)[k]  # (each entry written once: slp.homotopy_tapes)
    return nz


def dense_cost(N: int) -> int:
    """Entry updates (with the multipliers) of the dense LU in the same count as :func:`schedule`'s."""
    return sum((N - k) * (N - k + 1) for k in range(N))


def elimination_order(nz: np.ndarray) -> tuple[list[int], list[int]]:
    """(rows, cols): the equations and unknowns in elimination order, greedily: at each step the column whose
    candidate rows times the columns they could fill is least (ties: the lowest column), and as its position's row
    the candidate with the fewest possible non-zeros (ties: the lowest row)."""
    N = len(nz)
    pat = [set(np.nonzero(nz[i])[0].tolist()) for i in range(N)]
    rows_left, cols_left = set(range(N)), set(range(N))
    rows, cols = [], []
    for _ in range(N):
        best = None
        for c in sorted(cols_left):
            S = [i for i in sorted(rows_left) if c in pat[i]]
            U = set().union(*(pat[i] for i in S)) - {c} if S else set()
            key = (len(S) - 1) * len(U) if S else N * N * N
            if best is None or key < best[0]:
                best = (key, c, S, U)
        _, c, S, U = best
        r0 = min(S, key=lambda i: (len(pat[i]), i)) if S else min(rows_left)
        for i in S:
            pat[i] = set(U)
        rows_left.discard(r0)
        cols_left.discard(c)
        rows.append(r0)
        cols.append(c)
    return rows, cols


def schedule(nz: np.ndarray) -> tuple[tuple[tuple[int, ...], tuple[int, ...]], ...]:
    """Per step k of the natural-order LU with partial pivoting of a matrix with zero pattern ``nz``: (the
    positions i > k that can be non-zero in column k, the columns j > k the pivot row can hold), by the union bound
    (every candidate position, and position k, can afterwards hold any column one of them could)."""
    N = len(nz)
    pat = [set(np.nonzero(nz[i])[0].tolist()) for i in range(N)]
    steps = []
    for k in range(N):
        T = sorted({i for i in range(k, N) if k in pat[i]} | {k})
        U = sorted(set().union(*(pat[i] for i in T)) - set(range(k + 1)))
        for i in T:
            pat[i] = set(U)
        steps.append((tuple(i for i in T if i > k), tuple(U)))
    return tuple(steps)


def cost(steps) -> int:
    """Entry updates (with the multipliers) of a :func:`schedule`."""
    return sum((len(T) + 1) * (len(U) + 1) for T, U in steps)


def _renamed(tape, N: int, rows: np.ndarray, cols: np.ndarray):
    """The tape with unknown register cols[k] renamed k, and its output rows (H, J, dH/ds) renamed so that
    equation rows[i] is row i and J's column cols[k] is column k."""
    reg = np.arange(tape.n_registers)
    reg[cols] = np.arange(N)  # unknown cols[k] now lives in register k (a bijection of registers 0..N-1)
    eq = np.empty(N, dtype=np.int64)
    eq[rows] = np.arange(N)
    var = np.empty(N, dtype=np.int64)
    var[cols] = np.arange(N)
    code = tape.code.copy()
    out = code[:, 0] == OUT
    for f in (2, 3, 4):  # operands (unused ones are renamed too: harmless)
        use = code[:, f] >= 0
        code[use, f] = reg[code[use, f]]
    code[~out, 1] = reg[code[~out, 1]]
    d = code[out, 1].astype(np.int64)
    new = d.copy()
    h = d < N
    new[h] = eq[d[h]]
    j = (d >= N) & (d < N + N * N)
    new[j] = N + eq[(d[j] - N) // N] * N + var[(d[j] - N) % N]
    s = (d >= N + N * N) & (d < 2 * N + N * N)
    new[s] = N + N * N + eq[d[s] - N - N * N]
    code[out, 1] = new
    names = list(tape.input_names)
    names[:N] = [tape.input_names[c] for c in cols]
    return Tape(code, tape.imm, tape.n_inputs, tape.n_registers, tape.n_outputs, tuple(names))


def reached(steps, nz: np.ndarray) -> np.ndarray:
    """(N, N) bool: the entries a factorisation by ``steps`` can read or write (the pattern ``nz`` and what its
    schedule can fill); every other entry stays the zero it was."""
    out = nz.copy()
    for k, (T, U) in enumerate(steps):
        for i in (k, *T):
            out[i, k] = True
            out[i, list(U)] = True
    return out


def _unwritten(tape, N: int, keep: np.ndarray):
    """The tape without its OUT instructions that write the constant zero to a Jacobian entry outside ``keep``: the
    trackers' output arrays start zeroed and no factorisation touches those entries, so the zero is there already
    (5r/9s: 1,764 of the full tape's 2,115 outputs are zeros, two vector stores each at every evaluation)."""
    k, i, j = _jacobian_writes(tape, N)
    drop = np.zeros(len(tape.code), dtype=bool)
    drop[k] = _zero_writes(tape)[k] & ~keep[i, j]
    return Tape(tape.code[~drop], tape.imm[~drop], tape.n_inputs, tape.n_registers, tape.n_outputs, tape.input_names)


def permuted(tapes, rows, cols, unwritten: bool = True, steps=None):
    """:class:`~solvers.continuation.slp.HomotopyTapes` renamed to the order (rows, cols), with its LU's
    :func:`schedule` attached (``lu``; ``steps``: that schedule where the caller has it), which the compiled LU
    follows, and without the writes of the zeros no factorisation reaches (:func:`_unwritten`: the tapes are for the
    trackers, whose output arrays start zeroed; ``unwritten`` False keeps them)."""
    N = len(cols)
    rows, cols = np.asarray(rows, dtype=np.int64), np.asarray(cols, dtype=np.int64)
    nz = pattern(tapes.full, N)[np.ix_(rows, cols)]
    steps = schedule(nz) if steps is None else steps
    full, newton = (_renamed(t, N, rows, cols) for t in (tapes.full, tapes.newton))
    if unwritten:
        keep = reached(steps, nz)
        full, newton = _unwritten(full, N, keep), _unwritten(newton, N, keep)
    return HomotopyTapes(full, newton, _renamed(tapes.residual, N, rows, cols), lu=steps)


@dataclass(frozen=True)
class Sparse:
    """Renamed tapes (:func:`permuted`) and the maps of the unknowns: the tracker's x' = x[:, cols], x = x'[:, inv];
    ``work``: the schedule's entry updates against the dense LU's."""

    tapes: HomotopyTapes
    cols: np.ndarray
    inv: np.ndarray
    work: tuple[int, int]

    def track(self, q0, q1, x0, inst, options, near_end: float = 0.0):
        """:func:`.tape_kernel.track` of x0 (P, N) in the unknowns' own order, on the renamed tapes."""
        x, stats = tape_kernel.track(self.tapes, q0, q1, np.atleast_2d(x0)[:, self.cols], inst, options,
                                     near_end=near_end, native=tape_native.addresses(self.tapes))
        return x[:, self.inv], stats

    def newton(self, q, x, inst, steps: int):
        """:func:`.tape_kernel.newton` of x (P, N) in the unknowns' own order, on the renamed tapes."""
        out = tape_kernel.newton(self.tapes, q, np.atleast_2d(x)[:, self.cols], inst, steps,
                                 native=tape_native.addresses(self.tapes))
        return out[:, self.inv]


def plan(tapes) -> Sparse | None:
    """The ordered tapes of a homotopy whose Jacobian is sparse enough (:data:`WORTH`), else None."""
    n_out = tapes.full.n_outputs
    N = int(round(np.sqrt(1 + n_out))) - 1
    if N < 4:
        return None
    nz = pattern(tapes.full, N)
    rows, cols = elimination_order(nz)
    steps = schedule(nz[np.ix_(rows, cols)])
    if cost(steps) > WORTH * dense_cost(N):
        return None
    cols = np.asarray(cols, dtype=np.int64)
    inv = np.empty(N, dtype=np.int64)
    inv[cols] = np.arange(N)
    return Sparse(permuted(tapes, rows, cols, steps=steps), cols, inv, (cost(steps), dense_cost(N)))
