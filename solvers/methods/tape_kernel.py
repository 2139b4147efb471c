"""The compiled interpreter of :class:`solvers.methods.slp.Tape`: one kernel for every system.

Registers hold complex numbers as two real arrays (real and imaginary parts) of shape
(registers, points); every instruction runs over all points (live paths) in its inner loop, so the
cost of dispatching an instruction (a few ns) is spread over the points and the loop over points is
plain vectorisable arithmetic. The kernel is compiled once by numba and cached on disk: no system
needs its own compile.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .slp import ADD, CADD, CMUL, CONST, MUL, NEG, OUT, SQR, SUB, Tape

__all__ = ["run", "run_tape", "evaluate"]


@njit(cache=True, nogil=True, boundscheck=False)
def run_tape(code, imm, Rr, Ri, Or, Oi, P):
    """Run the tape on points 0..P-1: registers Rr, Ri (n_registers, capacity) with the inputs in
    their first rows; output rows of Or, Oi (n_outputs, capacity) written."""
    for k in range(code.shape[0]):
        op = code[k, 0]
        d = code[k, 1]
        a = code[k, 2]
        b = code[k, 3]
        if op == MUL:
            for p in range(P):
                ar = Rr[a, p]
                ai = Ri[a, p]
                br = Rr[b, p]
                bi = Ri[b, p]
                Rr[d, p] = ar * br - ai * bi
                Ri[d, p] = ar * bi + ai * br
        elif op == ADD:
            for p in range(P):
                xr = Rr[a, p] + Rr[b, p]
                xi = Ri[a, p] + Ri[b, p]
                Rr[d, p] = xr
                Ri[d, p] = xi
        elif op == SUB:
            for p in range(P):
                xr = Rr[a, p] - Rr[b, p]
                xi = Ri[a, p] - Ri[b, p]
                Rr[d, p] = xr
                Ri[d, p] = xi
        elif op == CMUL:
            c = imm[k]
            for p in range(P):
                xr = c * Rr[a, p]
                xi = c * Ri[a, p]
                Rr[d, p] = xr
                Ri[d, p] = xi
        elif op == SQR:
            for p in range(P):
                ar = Rr[a, p]
                ai = Ri[a, p]
                Rr[d, p] = ar * ar - ai * ai
                Ri[d, p] = 2.0 * ar * ai
        elif op == CADD:
            c = imm[k]
            for p in range(P):
                xr = Rr[a, p] + c
                xi = Ri[a, p]
                Rr[d, p] = xr
                Ri[d, p] = xi
        elif op == NEG:
            for p in range(P):
                xr = -Rr[a, p]
                xi = -Ri[a, p]
                Rr[d, p] = xr
                Ri[d, p] = xi
        elif op == CONST:
            c = imm[k]
            for p in range(P):
                Rr[d, p] = c
                Ri[d, p] = 0.0
        elif op == OUT:
            for p in range(P):
                Or[d, p] = Rr[a, p]
                Oi[d, p] = Ri[a, p]


def workspace(tape: Tape, capacity: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Register and output arrays (real, imaginary) for up to ``capacity`` points."""
    return (np.zeros((tape.n_registers, capacity)), np.zeros((tape.n_registers, capacity)),
            np.zeros((tape.n_outputs, capacity)), np.zeros((tape.n_outputs, capacity)))


def run(tape: Tape, inputs: np.ndarray) -> np.ndarray:
    """Outputs (n_outputs, P) complex of the tape at inputs (n_inputs, P) complex (a reference entry
    point for tests; trackers keep their workspace and call :func:`run_tape`)."""
    inputs = np.asarray(inputs, dtype=complex)
    if inputs.shape[0] != tape.n_inputs:
        raise ValueError(f"{inputs.shape[0]} input rows given; the tape has {tape.n_inputs}")
    P = inputs.shape[1]
    Rr, Ri, Or, Oi = workspace(tape, P)
    Rr[: tape.n_inputs] = inputs.real
    Ri[: tape.n_inputs] = inputs.imag
    run_tape(tape.code, tape.imm, Rr, Ri, Or, Oi, P)
    return Or + 1j * Oi


def evaluate(tape: Tape, x: np.ndarray, s: np.ndarray, q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
    """Outputs (P, n_outputs) of a homotopy tape (:func:`slp.homotopy_program`) at points x (P, N),
    path parameters s (P,) on the segments q0 -> q1 (P, Q) or (Q,)."""
    x = np.atleast_2d(np.asarray(x, dtype=complex))
    P = len(x)
    s = np.broadcast_to(np.asarray(s, dtype=float), (P,))
    q0 = np.broadcast_to(np.asarray(q0, dtype=complex), (P, np.shape(q0)[-1]))
    q1 = np.broadcast_to(np.asarray(q1, dtype=complex), (P, np.shape(q1)[-1]))
    inputs = np.concatenate([x.T, s[None, :], q0.T, (q1 - q0).T], axis=0)
    return run(tape, inputs).T
