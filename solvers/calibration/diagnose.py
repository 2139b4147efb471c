"""Stage 1, diagnose the data: what the TDOA matrix says before any fit of the model.

From the data alone: the redundancy (entries against the unknowns after the gauge), the singular values
of the robust low-rank factorization (plane waves: rank K after the offsets; near field: more), and for
plane waves the spread of the source directions and which way round the matrix is. `initialise` reads
the diagnosis to choose its route; `judge` reads it to say what the data cannot determine.
"""
from __future__ import annotations

import numpy as np

from .adjustment import n_unknowns
from .factorization import elevation_span, metric_upgrade, robust_low_rank
from .scoring import _prune
from .state import Diagnosis

#: The (K+1)-th singular value of the data (after the robust rank-K fit), relative to the first, below which
#: the wavefronts count as plane: the plane-wave factorization then places the receivers within a few per
#: mille of the array's size. Measured: 48 microphones in 0.3 m with sources at 3.5-4.2 m, 0.0088-0.0092
#: (receivers within 0.75 mm from the factorization alone); room networks (8 x 6 x 3 m, nodes mixed)
#: 24r/16s 0.068, 40r/30s 0.088. The bound sits between the two, at about the geometric mean.
FAR_FIELD_CURVATURE = 0.025
#: The factorization is computed when the entries are at least this many times its unknowns.
FACTORIZATION_REDUNDANCY = 2.0
#: Source directions spanning fewer degrees than this out of their main plane leave the receivers'
#: coordinate along its normal weakly determined (a height from sources near the horizon).
WEAK_SPAN_DEGREES = 10.0
#: A rank-K fit with row offsets this many times worse than with column offsets decides the orientation.
ORIENTATION_DECIDED = 2.0


def diagnose(F: np.ndarray, dim: int) -> Diagnosis:
    """The diagnosis of F (m receivers x n transmitters, NaN = missing) for a calibration in `dim` dimensions.

    Returns a Diagnosis (see there); never fits the nonlinear model.
    """
    mask = np.isfinite(F)
    m, n = F.shape
    rows_ok, cols_ok = _prune(mask, dim)
    work = mask & rows_ok[:, None] & cols_ok[None, :]
    entries = int(work.sum())
    unknowns = max(n_unknowns(int(rows_ok.sum()), int(cols_ok.sum()), dim), 0)
    dof = entries - unknowns
    base = dict(dim=dim, entries=entries, unknowns=unknowns, dof=dof)
    params = (dim + 1) * (m + n) + n
    if min(m, n) < dim + 3 or entries < FACTORIZATION_REDUNDANCY * params:
        return Diagnosis(**base)
    # the plane-wave fit (rank K after the column offsets), robust; what it leaves on its inliers is the
    # wavefronts' curvature and the noise: its largest singular value is the (K+1)-th of the data without
    # the gross errors (a robust rank-(K+1) fit would spend its extra rank on a row of gross errors)
    low_k = robust_low_rank(F, work, dim)
    E = np.where(low_k.inliers, F - low_k.o[None, :] - low_k.A @ low_k.B.T, 0.0)
    top = low_k.singular_values[0]
    sv = np.append(low_k.singular_values, np.linalg.svd(E, compute_uv=False)[0]) / (top if top > 0 else 1.0)
    curvature = float(sv[dim])
    if not curvature < FAR_FIELD_CURVATURE:
        return Diagnosis(**base, singular_values=sv, curvature=curvature, wavefront="spherical")
    upgrade = metric_upgrade(low_k)
    span, axis = elevation_span(upgrade.directions) if dim == 3 else (180.0, None)
    transposed = robust_low_rank(F, work, dim, transposed=True)
    ratio = transposed.scale / low_k.scale if low_k.scale > 0 else float("inf")
    notes = [f"the data are plane waves: the wavefronts' curvature is {curvature:.2g} of the linear term "
             f"(singular values of the factorization {', '.join(f'{v:.2g}' for v in sv)}); the sources are far "
             "from the receivers, whose positions the factorization gives, while the sources' ranges may be "
             "weakly determined"]
    if dim == 3 and span < WEAK_SPAN_DEGREES:
        notes.append(f"the sources span {span:.0f} deg of elevation: the receivers' height (their coordinate "
                     "across the plane of the source directions) is weakly determined")
    return Diagnosis(**base, singular_values=sv, curvature=curvature, wavefront="plane", low_rank=low_k,
                     upgrade=upgrade, elevation_span=span, span_axis=axis, orientation_ratio=ratio, notes=tuple(notes))
