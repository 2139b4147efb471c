"""Straight-line programs: a system kept in its factored form, differentiated, compiled to a tape.

A :class:`Program` records arithmetic on :class:`Value` objects (operator overloading), so a system is
written once from its formulas (matrices, products, determinants) instead of its expanded monomials.
Every operation is hash-consed (the same operation on the same operands is one node: common
subexpressions are shared) and constants are folded (x * 0, x + 0, x * 1, c1 * c2 ...).
:func:`derivative` differentiates a set of nodes by forward accumulation on the graph, one input at a
time, creating new nodes in the same program (so derivative nodes share subexpressions with each
other and with the values). :meth:`Program.compile` keeps what the outputs need, fuses a product read
by one sum into it, schedules the outputs in a given order (depth first) and allocates registers by
liveness: the :class:`Tape` is an array of instructions ``(opcode, destination, a, b, c)`` with a real
immediate, run for many points at once by :mod:`solvers.continuation.tape_kernel` (its kernels, in
:mod:`solvers.continuation.tape_jit`, own the instruction set).

:func:`homotopy_program` builds, for a parameter homotopy H(x, s) = F(x; q0 + s (q1 - q0)), the
program of H, its Jacobian in x and dH/ds; :func:`homotopy_tapes` compiles its three tapes
(:class:`HomotopyTapes`). :func:`tdoa_equations` writes the TDOA formulation's equations (analysis.
formulations: compaction matrix, A/B/C families, minors) on program values, :func:`squared_equations` a
system squared by random combinations, :func:`positions_equations` the 4r/5s positions formulation;
:func:`system_equations` finds the program of a committed solver's system by its name;
:func:`expanded_equations` any generated solver's system from its coefficient function and monomials.

Reference: the straight-line programs of HomotopyContinuation.jl's ModelKit (Breiding & Timme, 2018)
and Griewank & Walther, "Evaluating derivatives", 2nd ed. (2008), ch. 2-3.
"""
from __future__ import annotations

import numbers
import re
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

__all__ = ["OPCODES", "HomotopyTapes", "Program", "Tape", "Value", "derivative", "expanded_equations",
           "homotopy_program", "homotopy_tapes", "positions_equations", "squared_equations", "system_equations",
           "system_homotopy_tapes", "kd_equations", "tdoa_equations", "tdoa_homotopy_tapes"]

from .tape_jit import ADD, AXPY, CADD, CMUL, CONST, MUL, MULADD, NEG, OPCODES, OUT, SQR, SUB  # noqa: F401

_INPUT = -1


class Value:
    """A node of a :class:`Program`; arithmetic with Values and real numbers records new nodes."""

    __slots__ = ("program", "id")

    def __init__(self, program: "Program", id: int):
        self.program, self.id = program, id

    def _other(self, other) -> "Value":
        if isinstance(other, Value):
            if other.program is not self.program:
                raise ValueError("values of two programs mixed")
            return other
        if isinstance(other, numbers.Real):
            return self.program.constant(float(other))
        return NotImplemented

    def __add__(self, other):
        o = self._other(other)
        return NotImplemented if o is NotImplemented else self.program.add(self, o)

    __radd__ = __add__

    def __sub__(self, other):
        o = self._other(other)
        return NotImplemented if o is NotImplemented else self.program.sub(self, o)

    def __rsub__(self, other):
        o = self._other(other)
        return NotImplemented if o is NotImplemented else self.program.sub(o, self)

    def __mul__(self, other):
        o = self._other(other)
        return NotImplemented if o is NotImplemented else self.program.mul(self, o)

    __rmul__ = __mul__

    def __neg__(self):
        return self.program.neg(self)

    def __pow__(self, k: int):
        if not isinstance(k, int) or k < 0:
            raise ValueError(f"only non-negative integer powers, not {k!r}")
        out, base = self.program.constant(1.0), self
        while k:
            if k & 1:
                out = out * base
            k >>= 1
            if k:
                base = self.program.sqr(base)
        return out

    def __repr__(self) -> str:
        return f"Value({self.id}: {self.program.describe(self.id)})"


class Program:
    """A hash-consed expression graph with constant folding (see the module docstring).

    Nodes are ``(op, a, b, imm)``: op an opcode or ``_INPUT``; a, b node ids (-1 unused); imm a float
    (the constant of CONST, CMUL, CADD; the input's index for inputs). Creation order is a topological
    order.
    """

    def __init__(self):
        self.nodes: list[tuple[int, int, int, float]] = []
        self.names: list[str] = []
        self._index: dict[tuple, int] = {}

    # -- node creation --------------------------------------------------------------------------
    def _node(self, op: int, a: int = -1, b: int = -1, imm: float = 0.0) -> Value:
        key = (op, a, b, imm)
        i = self._index.get(key)
        if i is None:
            i = len(self.nodes)
            self.nodes.append(key)
            self._index[key] = i
        return Value(self, i)

    def input(self, name: str) -> Value:
        self.names.append(name)
        return self._node(_INPUT, imm=float(len(self.names) - 1))

    def inputs(self, names: Sequence[str]) -> list[Value]:
        return [self.input(n) for n in names]

    def constant(self, c: float) -> Value:
        return self._node(CONST, imm=float(c) + 0.0)  # +0.0: -0.0 and 0.0 are one constant

    def _const_of(self, v: Value) -> float | None:
        op, _, _, imm = self.nodes[v.id]
        return imm if op == CONST else None

    def add(self, a: Value, b: Value) -> Value:
        ca, cb = self._const_of(a), self._const_of(b)
        if ca is not None and cb is not None:
            return self.constant(ca + cb)
        if ca is not None:
            a, b, ca, cb = b, a, cb, ca
        if cb is not None:
            return a if cb == 0.0 else self._cadd(a, cb)
        if self.nodes[b.id][0] == NEG:
            return self.sub(a, Value(self, self.nodes[b.id][1]))
        if self.nodes[a.id][0] == NEG:
            return self.sub(b, Value(self, self.nodes[a.id][1]))
        x, y = sorted((a.id, b.id))
        return self._node(ADD, x, y)

    def _cadd(self, a: Value, c: float) -> Value:
        op, x, _, imm = self.nodes[a.id]
        if op == CADD:  # (x + c1) + c2
            return self.add(Value(self, x), self.constant(imm + c))
        return self._node(CADD, a.id, imm=c)

    def sub(self, a: Value, b: Value) -> Value:
        ca, cb = self._const_of(a), self._const_of(b)
        if ca is not None and cb is not None:
            return self.constant(ca - cb)
        if cb is not None:
            return self.add(a, self.constant(-cb))
        if ca is not None:
            return self.neg(b) if ca == 0.0 else self._cadd(self.neg(b), ca)
        if a.id == b.id:
            return self.constant(0.0)
        if self.nodes[b.id][0] == NEG:
            return self.add(a, Value(self, self.nodes[b.id][1]))
        return self._node(SUB, a.id, b.id)

    def neg(self, a: Value) -> Value:
        op, x, y, imm = self.nodes[a.id]
        if op == CONST:
            return self.constant(-imm)
        if op == NEG:
            return Value(self, x)
        if op == SUB:
            return self._node(SUB, y, x)
        if op == CMUL:
            return self.scale(Value(self, x), -imm)
        return self._node(NEG, a.id)

    def scale(self, a: Value, c: float) -> Value:
        op, x, _, imm = self.nodes[a.id]
        if c == 0.0:
            return self.constant(0.0)
        if c == 1.0:
            return a
        if op == CONST:
            return self.constant(c * imm)
        if c == -1.0:
            return self.neg(a)
        if op == CMUL:
            return self.scale(Value(self, x), c * imm)
        if op == NEG:
            return self.scale(Value(self, x), -c)
        return self._node(CMUL, a.id, imm=c)

    def mul(self, a: Value, b: Value) -> Value:
        ca, cb = self._const_of(a), self._const_of(b)
        if ca is not None and cb is not None:
            return self.constant(ca * cb)
        if ca is not None:
            return self.scale(b, ca)
        if cb is not None:
            return self.scale(a, cb)
        if a.id == b.id:
            return self.sqr(a)
        # constant factors move out of products: (c x) y = c (x y), so x y is shared
        for u, v in ((a, b), (b, a)):
            op, x, _, imm = self.nodes[u.id]
            if op == CMUL:
                return self.scale(self.mul(Value(self, x), v), imm)
            if op == NEG:
                return self.neg(self.mul(Value(self, x), v))
        x, y = sorted((a.id, b.id))
        return self._node(MUL, x, y)

    def sqr(self, a: Value) -> Value:
        op, x, _, imm = self.nodes[a.id]
        if op == CONST:
            return self.constant(imm * imm)
        if op == NEG:
            return self.sqr(Value(self, x))
        if op == CMUL:
            return self.scale(self.sqr(Value(self, x)), imm * imm)
        return self._node(SQR, a.id)

    def describe(self, i: int) -> str:
        op, a, b, imm = self.nodes[i]
        if op == _INPUT:
            return self.names[int(imm)]
        return f"{OPCODES[op]}({a}, {b}, {imm:g})"

    def is_zero(self, v: Value) -> bool:
        return self._const_of(v) == 0.0

    # -- compilation ------------------------------------------------------------------------------
    def compile(self, outputs: Sequence[Value], fuse: bool = True, schedule: Sequence[int] | None = None) -> "Tape":
        """The tape computing ``outputs`` (output row k = outputs[k]) from the inputs.

        Input k is register k (the caller writes it); other nodes get registers by liveness (a register
        is reused after the last instruction that reads it), so the workspace stays small. With
        ``fuse``, a product (or constant multiple) read only by one sum or difference is computed
        inside it (MULADD, AXPY): fewer instructions and register round trips. ``schedule`` (output
        indices): the outputs are computed one after the other in this order, each with what it needs
        that is not computed yet (depth first), and written as soon as computed; grouping outputs that
        share intermediates (an equation, its Jacobian row and dH/ds) keeps fewer values alive at once
        than creation order. The arithmetic is the same either way.
        """
        n_in = len(self.names)
        need = np.zeros(len(self.nodes), dtype=bool)
        stack = [v.id for v in outputs]
        while stack:
            i = stack.pop()
            if need[i]:
                continue
            need[i] = True
            op, a, b, _ = self.nodes[i]
            for j in (a, b):
                if j >= 0 and op not in (CONST, _INPUT):
                    stack.append(j)
        order = [i for i in range(len(self.nodes)) if need[i] and self.nodes[i][0] != _INPUT]
        out_ids = {v.id for v in outputs}
        uses: dict[int, int] = {}
        for i in order:
            op, a, b, _ = self.nodes[i]
            for j in (a, b):
                if j >= 0:
                    uses[j] = uses.get(j, 0) + 1
        instr: dict[int, tuple[int, tuple[int, ...], float]] = {}
        fused: set[int] = set()
        for i in order:
            op, a, b, c = self.nodes[i]
            ins = (op, tuple(j for j in (a, b) if j >= 0), c)
            if fuse and op in (ADD, SUB):
                ins = self._fused(op, a, b, uses, out_ids, fused) or ins
            instr[i] = ins
        # items: (node, None) computes a node, (node, k) writes it to output row k
        writes: dict[int, list[int]] = {}
        for k, v in enumerate(outputs):
            writes.setdefault(v.id, []).append(k)
        items: list[tuple[int, int | None]] = []
        if schedule is None:
            items = [(i, None) for i in order if i not in fused]
            items += [(v.id, k) for k, v in enumerate(outputs)]
        else:
            if sorted(schedule) != list(range(len(outputs))):
                raise ValueError("schedule must be a permutation of the output indices")
            done = {i for i in range(len(self.nodes)) if self.nodes[i][0] == _INPUT}
            items = [(i, k) for i in sorted(done & set(writes)) for k in writes[i]]
            for k in schedule:
                stack = [(outputs[k].id, False)]
                while stack:
                    i, expanded = stack.pop()
                    if i in done:
                        continue
                    if expanded:
                        done.add(i)
                        items.append((i, None))
                        items += [(i, w) for w in writes.get(i, ())]
                        continue
                    stack.append((i, True))
                    stack += [(j, False) for j in reversed(instr[i][1]) if j not in done]
        last = {}
        for pos, (i, k) in enumerate(items):
            for j in (instr[i][1] if k is None else (i,)):
                last[j] = pos
        reg = {i: int(self.nodes[i][3]) for i in range(len(self.nodes)) if self.nodes[i][0] == _INPUT}
        free: list[int] = []
        n_reg = n_in
        code, imm = [], []
        for pos, (i, k) in enumerate(items):
            if k is not None:
                code.append((OUT, k, reg[i], 0, 0))
                imm.append(0.0)
                if last.get(i) == pos and self.nodes[i][0] != _INPUT and (schedule is not None or i not in out_ids):
                    free.append(reg[i])
                continue
            op, operands, c = instr[i]
            regs = [reg[j] for j in operands] + [0] * (3 - len(operands))
            # the destination is chosen before the operands whose last use is here free their registers:
            # an instruction never writes a register it reads (the kernel's loop over points vectorises
            # only when its stores cannot overlap its loads)
            if free:
                d = free.pop()
            else:
                d = n_reg
                n_reg += 1
            reg[i] = d
            for j in set(operands):
                if last.get(j) == pos and self.nodes[j][0] != _INPUT:
                    free.append(reg[j])
            code.append((op, d, *regs))
            imm.append(c)
        return Tape(np.array(code, dtype=np.int32).reshape(-1, 5), np.array(imm, dtype=np.float64),
                    n_in, n_reg, len(outputs), tuple(self.names))

    def _fused(self, op: int, a: int, b: int, uses: dict, out_ids: set, fused: set):
        """The fused instruction (op, operands, imm) for the sum or difference a +- b, or None."""

        def single(j: int, kinds: tuple[int, ...]) -> bool:
            return uses.get(j) == 1 and j not in out_ids and self.nodes[j][0] in kinds

        def factors(j: int) -> tuple[int, int]:
            o, x, y, _ = self.nodes[j]
            return (x, x) if o == SQR else (x, y)

        products = (MUL, SQR)
        if single(b, products):  # a + x y, a - x y
            fused.add(b)
            return (MULADD, (*factors(b), a), 1.0 if op == ADD else -1.0)
        if op == ADD and single(a, products):  # x y + b
            fused.add(a)
            return (MULADD, (*factors(a), b), 1.0)
        if single(b, (CMUL,)):  # a +- k x
            fused.add(b)
            k = self.nodes[b][3]
            return (AXPY, (a, self.nodes[b][1]), k if op == ADD else -k)
        if op == ADD and single(a, (CMUL,)):  # k x + b
            fused.add(a)
            return (AXPY, (b, self.nodes[a][1]), self.nodes[a][3])
        return None


@dataclass(frozen=True)
class Tape:
    """Instructions (n, 5) int32 ``(opcode, destination, a, b, c)`` and immediates (n,); registers
    0..n_inputs-1 are the inputs, n_registers in all; OUT instructions write output rows."""

    code: np.ndarray
    imm: np.ndarray
    n_inputs: int
    n_registers: int
    n_outputs: int
    input_names: tuple[str, ...]

    @property
    def n_instructions(self) -> int:
        """Arithmetic instructions (OUT copies not counted)."""
        return int(np.sum(self.code[:, 0] != OUT))

    def counts(self) -> dict[str, int]:
        ops, k = np.unique(self.code[:, 0], return_counts=True)
        return {OPCODES[o]: int(c) for o, c in zip(ops, k)}


def derivative(values: Sequence[Value], wrt: Value) -> list[Value]:
    """d values / d wrt by forward accumulation on the graph (new nodes in the same program)."""
    prog = values[0].program if values else wrt.program
    top = max(v.id for v in values) if values else -1
    zero = prog.constant(0.0)
    d: dict[int, Value] = {}
    nodes = prog.nodes
    for i in range(min(wrt.id, top + 1), top + 1):
        op, a, b, c = nodes[i]
        if op == _INPUT:
            d[i] = prog.constant(1.0) if i == wrt.id else zero
            continue
        if op == CONST:
            continue
        da = d.get(a, zero) if a >= 0 else zero
        db = d.get(b, zero) if b >= 0 else zero
        if prog.is_zero(da) and prog.is_zero(db):
            continue
        va, vb = Value(prog, a), (Value(prog, b) if b >= 0 else None)
        if op == ADD:
            r = da + db
        elif op == SUB:
            r = da - db
        elif op == NEG:
            r = -da
        elif op == CMUL:
            r = prog.scale(da, c)
        elif op == CADD:
            r = da
        elif op == SQR:
            r = prog.scale(va * da, 2.0)
        elif op == MUL:
            r = da * vb + va * db
        else:  # pragma: no cover - OUT never appears in a program's nodes
            raise AssertionError(op)
        d[i] = r
    return [d.get(v.id, zero) for v in values]


def homotopy_program(equations: Callable[[list[Value], list[Value]], list[Value]], unknowns: Sequence[str],
                     parameters: Sequence[str]) -> tuple[Program, list[Value], list[Value], list[Value]]:
    """Program of H(x, s) = F(x; q0 + s dq), its Jacobian dH/dx and dH/ds.

    ``equations(x, q)`` writes F on program values. Inputs, in register order: the unknowns, s, the
    start parameters q0_k and the directions dq_k (``q0:<name>``, ``dq:<name>``). Returns the program
    and the lists H (N), J (N * N, row-major: J[e * N + k] = dH_e / dx_k), Hs (N).
    """
    prog = Program()
    x = prog.inputs(list(unknowns))
    s = prog.input("s")
    q0 = prog.inputs([f"q0:{p}" for p in parameters])
    dq = prog.inputs([f"dq:{p}" for p in parameters])
    q = [a + s * b for a, b in zip(q0, dq)]
    H = list(equations(x, q))
    if len(H) != len(x):
        raise ValueError(f"{len(H)} equations in {len(x)} unknowns: a homotopy needs a square system")
    J = [None] * (len(H) * len(x))
    for k, xk in enumerate(x):
        col = derivative(H, xk)
        for e in range(len(H)):
            J[e * len(x) + k] = col[e]
    Hs = derivative(H, s)
    return prog, H, J, Hs


def expanded_equations(coefficients: Callable, exponents, term_equation) -> Callable[[list[Value], list[Value]], list[Value]]:
    """``equations(x, q)`` of any homotopy solver's system from its generated parts: the coefficient
    function (numpy code in the parameters, its shared subexpressions kept: it is run on an object
    array of program values) and the terms' exponents and equations. The monomials are shared between
    terms and equations (each is one more factor on a shorter one), but the system is expanded in the
    unknowns: a program written from the formulas (:func:`tdoa_equations`) is shorter.
    """
    exponents = np.asarray(exponents, dtype=np.int64)
    term_equation = np.asarray(term_equation, dtype=np.int64)
    n_eq = int(term_equation.max()) + 1 if len(term_equation) else 0

    def equations(x: list[Value], q: list[Value]) -> list[Value]:
        prog = x[0].program
        Q = np.empty((1, len(q)), dtype=object)
        Q[0, :] = q
        c = np.asarray(coefficients(Q), dtype=object).reshape(-1)
        if len(c) != len(exponents):
            raise ValueError(f"the coefficient function gives {len(c)} coefficients for {len(exponents)} terms")
        monomials: dict[tuple, Value] = {(0,) * len(x): prog.constant(1.0)}

        def monomial(a: tuple) -> Value:
            if a not in monomials:
                v = next(k for k, e in enumerate(a) if e)
                monomials[a] = monomial(a[:v] + (a[v] - 1,) + a[v + 1:]) * x[v]
            return monomials[a]

        out = [prog.constant(0.0) for _ in range(n_eq)]
        for ct, a, e in zip(c, exponents, term_equation):
            ct = ct if isinstance(ct, Value) else prog.constant(float(ct))
            out[e] = out[e] + ct * monomial(tuple(int(k) for k in a))
        return out

    return equations


# --------------------------------------------------------------------------------------------------
# the TDOA formulation, unexpanded
# --------------------------------------------------------------------------------------------------


def tdoa_equations(formulation) -> Callable[[list[Value], list[Value]], list[Value]]:
    """``equations(x, q)`` of a TDOA formulation (families A, B, C, minors) written from its formulas.

    Same equations as :func:`analysis.formulations.tdoa.factored_equations` (and the generated solvers'
    coefficients): unknowns h11, h12, h22, b1, b2, o1..on; parameters f_ij row by row. e_ij = f_ij -
    f_1j, p_ij = f_ij + f_1j; compaction matrix D~_ij = c_ij + 2 e_{i+1,1} o1 - 2 e_{i+1,j+1} o_{j+1}
    with c_ij = e p - e p; d_ij^2 - d_1j^2 = e_ij (p_ij - 2 o_j); d_11^2 = (f_11 - o1)^2; a minor is the
    determinant of its 3 x 3 submatrix of D~ by cofactors of the first row (the 2 x 2 minors of its last
    two rows are shared between minors with the same rows and columns).
    """
    from analysis.formulations.tdoa import _family, _parse_minor, as_formulation

    formulation = as_formulation(formulation)
    config = formulation.config
    m, n = config.m, config.n
    if not config.is_planar_tdoa:
        return kd_equations(formulation)
    for name in formulation.equations:
        if _family(name) not in ("A", "B", "C", "minors"):
            raise ValueError(f"{formulation.label}: equation {name} has no unexpanded program (families A, B, C, minors)")

    def equations(x: list[Value], q: list[Value]) -> list[Value]:
        h11, h12, h22, b1, b2, *o = x
        f = [q[i * n:(i + 1) * n] for i in range(m)]
        e = {(i, j): f[i][j] - f[0][j] for i in range(1, m) for j in range(n)}
        p = {(i, j): f[i][j] + f[0][j] for i in range(1, m) for j in range(n)}

        def comp(i: int, j: int) -> Value:  # D~_ij, 1-based
            c = e[i, j] * p[i, j] - e[i, 0] * p[i, 0]
            return c + 2.0 * (e[i, 0] * o[0]) - 2.0 * (e[i, j] * o[j])

        det = h11 * h22 - h12 * h12
        d2_11 = (f[0][0] - o[0]) ** 2
        out = []
        for name in formulation.equations:
            if name == "A":
                b_adj_b = h22 * b1 * b1 - 2.0 * (h12 * b1 * b2) + h11 * b2 * b2
                out.append(d2_11 * det - b_adj_b)
            elif name.startswith("B"):
                j = int(name[1:])
                e_adj_e, b_adj_e = (h22, b1 * h22 - b2 * h12) if j == 2 else (h11, b2 * h11 - b1 * h12)
                lhs = (f[0][j - 1] - o[j - 1]) ** 2 - d2_11
                out.append(lhs * det - 0.25 * e_adj_e + b_adj_e)
            elif name.startswith("M"):
                rows, cols = _parse_minor(config, name)
                a = [[comp(r, c) for c in cols] for r in rows]
                out.append(a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
                           - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
                           + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]))
            else:
                i = int(name[1:])
                r1, r2 = comp(i - 1, 1), comp(i - 1, 2)
                quad = h11 * (r1 * r1) + 2.0 * (h12 * (r1 * r2)) + h22 * (r2 * r2)
                lin = b1 * r1 + b2 * r2
                d2_diff = e[i - 1, 0] * (p[i - 1, 0] - 2.0 * o[0])
                out.append(d2_diff - quad + 2.0 * lin)
        return out

    return equations


def kd_equations(formulation) -> Callable[[list[Value], list[Value]], list[Value]]:
    """``equations(x, q)`` of any other configuration (TOA, 3D, direct parametrization): the formulas of
    :func:`analysis.formulations.kd.formulas`, the same ones its parametric system is written from,
    on program values (products and determinants unexpanded); parameters f_ij row by row."""
    from analysis.formulations.tdoa import as_formulation
    from analysis.formulations.kd import formulas

    formulation = as_formulation(formulation)
    config = formulation.config
    m, n = config.m, config.n

    def equations(x: list[Value], q: list[Value]) -> list[Value]:
        prog = x[0].program
        f = [q[i * n:(i + 1) * n] for i in range(m)]
        return formulas(formulation, dict(zip(config.unknowns, x)), f, prog.constant(0.0), 0.25)[0]

    return equations


def squared_equations(equations: Callable[[list[Value], list[Value]], list[Value]], keep: int,
                      combinations: np.ndarray) -> Callable[[list[Value], list[Value]], list[Value]]:
    """``equations(x, q)`` of a system squared by :func:`analysis.formulations.parametric.square`: the first ``keep``
    equations, then the combinations (rows of integer coefficients) of the others."""
    combinations = np.asarray(combinations, dtype=np.int64)

    def squared(x: list[Value], q: list[Value]) -> list[Value]:
        F = list(equations(x, q))
        rest = F[keep:]
        if combinations.shape[1] != len(rest):
            raise ValueError(f"{combinations.shape[1]} coefficients per combination for {len(rest)} equations")
        out = F[:keep]
        for row in combinations:
            acc = x[0].program.constant(0.0)
            for c, v in zip(row, rest):
                acc = acc + float(c) * v
            out.append(acc)
        return out

    return squared


def positions_equations(m: int, n: int, variant: str) -> Callable[[list[Value], list[Value]], list[Value]]:
    """``equations(x, q)`` of a positions formulation (:mod:`analysis.formulations.positions`) written from its formulas
    (determinants and adjugates of the 3 x 3 matrices A~_j unexpanded): the ``receivers-orbits`` variant
    (the committed 4r/5s solver's); parameters f_ij row by row."""
    from analysis.formulations.positions import receivers_orbits_equations

    if variant != "receivers-orbits":
        raise ValueError(f"positions variant {variant!r} has no unexpanded program (receivers-orbits)")

    def equations(x: list[Value], q: list[Value]) -> list[Value]:
        prog = x[0].program
        return receivers_orbits_equations(m, n, x, lambda i, j: q[(i - 1) * n + (j - 1)], prog.constant(0.0),
                                          prog.constant(1.0))[1]

    return equations


_POSITIONS_LABEL = re.compile(r"^(\d+)r(\d+)s:positions-([a-z-]+)$")


def system_equations(name: str) -> tuple[Callable[[list[Value], list[Value]], list[Value]], list[str], list[str]]:
    """``(equations(x, q), unknowns, parameters)`` of a committed solver's system, written from its formulas,
    by the system's name (a generated spec's ``system``): a TDOA formulation (``9r3s:C2-C9``), one with
    its minors squared (``5r4s:A,B2,B3,C2-C5,minors(4) (minors squared, seed 0)``: the equations that
    are not minors are kept, as solvers.generate squares them) or a positions formulation
    (``4r5s:positions-receivers-orbits``). ValueError for a name of none of these forms or without a
    program. A caller checks the program against the system it stands for (tracking._agrees).
    """
    if ":" not in name:  # every one of these names has one ("<config>:<equations>"); a user's system ("circle.sys")
        # is told apart before the formulations and sympy are imported (a generated module's first solve: 0.25 s)
        raise ValueError(f"{name!r} is not a formulation label ('<config>:<equations>'): no program from formulas")
    from analysis.formulations.tdoa import _family, as_formulation, data_symbols
    from analysis.formulations.parametric import parse_squared_name, square_combinations
    from analysis.formulations.positions import positions_system

    match = _POSITIONS_LABEL.match(name)
    if match:
        m, n, variant = int(match.group(1)), int(match.group(2)), match.group(3)
        equations = positions_equations(m, n, variant)
        system = positions_system(m, n, variant)
        return equations, list(system.unknowns), list(system.parameters)
    squared = parse_squared_name(name)
    formulation = as_formulation(squared[0] if squared else name)
    config = formulation.config
    equations = tdoa_equations(formulation)
    if squared:
        keep = sum(_family(e) != "minors" for e in formulation.equations)
        N = len(config.unknowns)
        combos = square_combinations(len(formulation.equations) - keep, N - keep, squared[1])
        equations = squared_equations(equations, keep, combos)
    return equations, list(config.unknowns), [s.name for row in data_symbols(config) for s in row]


def system_homotopy_tapes(name: str) -> "HomotopyTapes":
    """The homotopy tapes of a committed solver's system by its name (:func:`system_equations`)."""
    return homotopy_tapes(*system_equations(name))


@dataclass(frozen=True)
class HomotopyTapes:
    """The tapes of one homotopy, on the same inputs (:func:`homotopy_program`); outputs in rows:
    ``full`` H (N), J (N * N, row-major), dH/ds (N), for the predictor and the step that gives the next
    tangent; ``newton`` H and J, for the other Newton steps (dH/ds is a third of ``full``);
    ``residual`` H; ``lu``: the elimination schedule the compiled LU follows (:func:`.sparse_lu.schedule`, for
    tapes renamed to a sparse order by :func:`.sparse_lu.permuted`), or None (the dense LU)."""

    full: Tape
    newton: Tape
    residual: Tape
    lu: tuple | None = None

    @property
    def n_registers(self) -> int:
        return max(self.full.n_registers, self.newton.n_registers, self.residual.n_registers)


def homotopy_tapes(equations: Callable[[list[Value], list[Value]], list[Value]], unknowns: Sequence[str],
                   parameters: Sequence[str]) -> HomotopyTapes:
    """The :class:`HomotopyTapes` of the system ``equations(x, q)`` (see :func:`homotopy_program`)."""
    prog, H, J, Hs = homotopy_program(equations, unknowns, parameters)
    N = len(H)
    rows = [[e] + [N + e * N + k for k in range(N)] for e in range(N)]  # an equation and its Jacobian row
    full = [k for e, row in enumerate(rows) for k in row + [N + N * N + e]]
    newton = [k for row in rows for k in row]
    return HomotopyTapes(prog.compile(H + J + Hs, schedule=full), prog.compile(H + J, schedule=newton),
                         prog.compile(H, schedule=list(range(N))))


def tdoa_homotopy_tapes(formulation) -> HomotopyTapes:
    """The homotopy tapes of a TDOA formulation (ValueError for a non-square one)."""
    from analysis.formulations.tdoa import as_formulation, data_symbols

    formulation = as_formulation(formulation)
    config = formulation.config
    return homotopy_tapes(tdoa_equations(formulation), config.unknowns,
                          [s.name for row in data_symbols(config) for s in row])
