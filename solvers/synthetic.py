"""Synthetic 2D and 3D TDOA (and TOA) networks and their known algebraic roots.

This module owns the ground truth used by validation and tests: a `Network` (receivers,
transmitters, transmitter clock offsets), the TDOA measurements it produces, the paper's random
sampler and `true_root`, the point (H, b, o) of the algebraic formulation that the network
corresponds to in the gauge r_1 = 0.

Measurement model (paper Sec. 1, eq. (2)): f_ij = ||r_i - s_j|| + o_j, receivers synchronised,
one unknown offset o_j per transmitter (TOA: all offsets zero). Positions have K = 2 or 3 coordinates.
Only numpy is used.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "DegenerateNetworkError",
    "Network",
    "corrupt_measurements",
    "array_network",
    "random_network",
    "room_network",
    "tetrahedral_array",
    "true_root",
]


class DegenerateNetworkError(ValueError):
    """The network has no well-defined algebraic root (e.g. s_1, s_2, s_3 collinear)."""


DIMENSIONS = (2, 3)
"""Spatial dimensions a network may have."""


def _frozen_array(values: object, shape: tuple[int | None, ...], name: str) -> np.ndarray:
    """Return a read-only float64 copy of `values`, checking its shape (None = any length)."""
    array = np.array(values, dtype=float)
    if array.ndim != len(shape) or any(
        want is not None and got != want for got, want in zip(array.shape, shape)
    ):
        raise ValueError(f"{name} must have shape {shape} (None = any), got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must be finite")
    array.setflags(write=False)
    return array


@dataclass(frozen=True, eq=False)
class Network:
    """A TDOA sensor network in 2D or 3D: m synchronised receivers, n transmitters with clock offsets.

    Parameters
    ----------
    receivers : (m, K) array, K = 2 or 3
        Receiver positions r_i.
    transmitters : (n, K) array
        Transmitter positions s_j (the same K).
    offsets : (n,) array
        Transmitter clock offsets o_j (in distance units).

    Reference: paper Sec. 1, TDOA measurement equation (f_ij - o_j)^2 = ||r_i - s_j||^2.
    """

    receivers: np.ndarray
    transmitters: np.ndarray
    offsets: np.ndarray

    def __post_init__(self) -> None:
        receivers = _frozen_array(self.receivers, (None, None), "receivers")
        if receivers.shape[1] not in DIMENSIONS:
            raise ValueError(f"positions must have 2 or 3 coordinates, got {receivers.shape[1]}")
        transmitters = _frozen_array(self.transmitters, (None, receivers.shape[1]), "transmitters")
        offsets = _frozen_array(self.offsets, (transmitters.shape[0],), "offsets")
        object.__setattr__(self, "receivers", receivers)
        object.__setattr__(self, "transmitters", transmitters)
        object.__setattr__(self, "offsets", offsets)

    @property
    def dim(self) -> int:
        """Spatial dimension K (2 or 3)."""
        return self.receivers.shape[1]

    @property
    def m(self) -> int:
        """Number of receivers."""
        return self.receivers.shape[0]

    @property
    def n(self) -> int:
        """Number of transmitters."""
        return self.transmitters.shape[0]

    def distances(self) -> np.ndarray:
        """Return the (m, n) receiver-transmitter distances d_ij = ||r_i - s_j||."""
        diff = self.receivers[:, None, :] - self.transmitters[None, :, :]
        return np.sqrt(np.einsum("ijk,ijk->ij", diff, diff))

    def measurements(
        self, noise_sigma: float = 0.0, rng: np.random.Generator | None = None
    ) -> np.ndarray:
        """Return the (m, n) TDOA measurements F[i, j] = ||r_i - s_j|| + o_j (+ noise).

        Parameters
        ----------
        noise_sigma : float
            Standard deviation of i.i.d. zero-mean Gaussian noise added to every f_ij.
        rng : numpy.random.Generator, optional
            Source of the noise; required when `noise_sigma > 0` (seeds stay explicit).

        Returns
        -------
        (m, n) float array.

        Reference: paper Sec. 1 eq. (2) and Sec. 4.2 (noisy data).
        """
        if noise_sigma < 0:
            raise ValueError(f"noise_sigma must be >= 0, got {noise_sigma}")
        F = self.distances() + self.offsets[None, :]
        if noise_sigma > 0:
            if rng is None:
                raise ValueError("noise_sigma > 0 requires an explicit numpy Generator `rng`")
            F = F + noise_sigma * rng.standard_normal(F.shape)
        return F


def random_network(
    m: int,
    n: int,
    rng: np.random.Generator,
    position_sigma: float = 10.0,
    offset_sigma: float = 1.0,
    dim: int = 2,
) -> Network:
    """Sample a network as in the paper's experiments (in 2D; ``dim=3`` for a 3D network).

    Parameters
    ----------
    m, n : int
        Numbers of receivers and transmitters.
    rng : numpy.random.Generator
        Explicitly seeded generator; draws receivers, then transmitters, then offsets.
    position_sigma : float
        Standard deviation of the zero-mean normal node coordinates (paper: 10).
    offset_sigma : float
        Standard deviation of the zero-mean normal offsets (paper: 1; 0 gives a TOA network).
    dim : int
        Spatial dimension K, 2 (default) or 3.

    Returns
    -------
    Network

    Reference: paper Sec. 4 (synthetic data).
    """
    if m < 1 or n < 1:
        raise ValueError(f"need m >= 1 and n >= 1, got m={m}, n={n}")
    if dim not in DIMENSIONS:
        raise ValueError(f"dim must be 2 or 3, got {dim!r}")
    receivers = position_sigma * rng.standard_normal((m, dim))
    transmitters = position_sigma * rng.standard_normal((n, dim))
    offsets = offset_sigma * rng.standard_normal(n)
    return Network(receivers, transmitters, offsets)


#: A room's extent in metres (x, y, z): the box :func:`room_network` places the nodes in.
ROOM = (8.0, 6.0, 3.0)


def room_network(
    m: int,
    n: int,
    rng: np.random.Generator,
    room: tuple[float, float, float] = ROOM,
    offset_sigma: float = 1.0,
) -> Network:
    """Sample a 3D network in a room-sized box: receivers and transmitters uniform in the box, offsets normal.

    Parameters
    ----------
    m, n, rng :
        As for :func:`random_network` (the same order of draws).
    room : (3,) floats, or (2,) for a 2D network
        The box [0, room[0]] x [0, room[1]] x [0, room[2]] in metres (default :data:`ROOM`, 8 x 6 x 3 m);
        two extents give a 2D network in the rectangle (e.g. ``ROOM[:2]``, the room's floor).
    offset_sigma : float
        Standard deviation of the zero-mean normal offsets in metres (0 gives a TOA network).

    Returns
    -------
    Network with dim len(room) (3 by default).
    """
    if m < 1 or n < 1:
        raise ValueError(f"need m >= 1 and n >= 1, got m={m}, n={n}")
    box = np.asarray(room, dtype=float)
    if box.shape not in ((2,), (3,)) or not np.all(box > 0):
        raise ValueError(f"room must be three (or, in 2D, two) positive extents (x, y[, z]), got {room!r}")
    receivers = rng.uniform(0.0, 1.0, (m, len(box))) * box
    transmitters = rng.uniform(0.0, 1.0, (n, len(box))) * box
    offsets = offset_sigma * rng.standard_normal(n)
    return Network(receivers, transmitters, offsets)


def true_root(network: Network) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return the root (H, b, o) of the algebraic formulation that `network` corresponds to.

    After translating so that r_1 = 0, the factorisation D~ = R~^T S~ with R~ = D~[:, :K]^T and
    S~ = I (first K columns of the compaction matrix) is matched by L = -2 S, where
    S = [s_2 - s_1, ..., s_{K+1} - s_1]. Hence H = (L^T L)^{-1} = (4 S^T S)^{-1} and
    b = L^{-1} s_1 = -1/2 S^{-1} s_1. Any L' = Q L with Q orthogonal gives the same H; that is the
    rotation/reflection gauge.

    Parameters
    ----------
    network : Network
        Needs n >= K + 1 with s_1..s_{K+1} affinely independent (not collinear in 2D, not coplanar in 3D).

    Returns
    -------
    H : (K, K) symmetric positive-definite array
    b : (K,) array
    o : (n,) array, the offsets (a copy)

    Raises
    ------
    DegenerateNetworkError
        If n < K + 1 or s_1..s_{K+1} are (numerically) affinely dependent.

    Reference: paper Sec. 2.1 eq. (4)-(5) and Sec. 3.1 eq. (6).
    """
    k = network.dim
    if network.n < k + 1:
        raise DegenerateNetworkError(f"the {k}D parametrisation needs n >= {k + 1} transmitters, got {network.n}")
    r1 = network.receivers[0]
    s1 = network.transmitters[0] - r1
    S = (network.transmitters[1:k + 1] - network.transmitters[0]).T  # columns s_2 - s_1, ..., s_{K+1} - s_1
    singular_values = np.linalg.svd(S, compute_uv=False)
    if not singular_values[k - 1] > 1e-12 * singular_values[0]:
        what = "collinear or coincident" if k == 2 else "coplanar"
        raise DegenerateNetworkError(f"transmitters s_1..s_{k + 1} are {what}")
    S_inv = np.linalg.inv(S)
    H = 0.25 * S_inv @ S_inv.T  # (4 S^T S)^{-1}
    H = 0.5 * (H + H.T)
    b = -0.5 * S_inv @ s1
    return H, b, network.offsets.copy()


def corrupt_measurements(
    F: np.ndarray,
    rng: np.random.Generator,
    missing: float = 0.0,
    outliers: float = 0.0,
    min_per_receiver: int = 3,
    min_per_transmitter: int = 4,
) -> tuple[np.ndarray, np.ndarray]:
    """Return (F with gaps and gross errors, outlier mask) for robustness experiments.

    Missing: round(missing * m * n) entries set to NaN, drawn at random among those whose removal
    leaves every receiver at least `min_per_receiver` and every transmitter at least
    `min_per_transmitter` measurements (fewer if that is impossible). Outliers: round(outliers * N)
    of the N remaining measured entries replaced by a value uniform in [min F, max F] (the data
    range). Draws: the missing entries' order, then the outliers' positions, then their values.

    Reference: Larsson et al. (EUSIPCO 2021) evaluate with uniform outliers and random gaps.
    """
    F = np.array(F, dtype=float)
    m, n = F.shape
    lo, hi = float(np.nanmin(F)), float(np.nanmax(F))
    rows, cols = np.isfinite(F).sum(axis=1), np.isfinite(F).sum(axis=0)
    want = int(round(missing * m * n))
    for k in rng.permutation(m * n):
        if want == 0:
            break
        i, j = divmod(int(k), n)
        if np.isfinite(F[i, j]) and rows[i] > min_per_receiver and cols[j] > min_per_transmitter:
            F[i, j] = np.nan
            rows[i] -= 1
            cols[j] -= 1
            want -= 1
    measured = np.flatnonzero(np.isfinite(F))
    bad = rng.choice(measured, int(round(outliers * measured.size)), replace=False)
    F.flat[bad] = rng.uniform(lo, hi, bad.size)
    mask = np.zeros(m * n, bool)
    mask[bad] = True
    return F, mask.reshape(m, n)


#: Speed of sound (m/s) and sample rate (Hz) of the simulated arrays (:func:`array_network`).
SPEED_OF_SOUND = 343.0
SAMPLE_RATE = 48_000.0


def tetrahedral_array(per_edge: int = 8, radius: float = 0.15) -> np.ndarray:
    """(6 per_edge, 3) microphone positions on the six edges of a regular tetrahedron (circumradius
    `radius`, centred at the origin, one face horizontal below), `per_edge` evenly spaced on each edge
    (vertices excluded): the shape of a 48-microphone array built on a tetrahedral frame."""
    if per_edge < 1 or not radius > 0:
        raise ValueError(f"need per_edge >= 1 and radius > 0, got {per_edge}, {radius}")
    top = np.array([0.0, 0.0, 1.0])
    base = [np.array([np.sqrt(8.0 / 9.0) * np.cos(a), np.sqrt(8.0 / 9.0) * np.sin(a), -1.0 / 3.0])
            for a in (0.0, 2.0 * np.pi / 3.0, 4.0 * np.pi / 3.0)]
    vertices = [radius * v for v in [top] + base]
    t = (np.arange(per_edge) + 0.5) / per_edge
    edges = [(a, b) for a in range(4) for b in range(a + 1, 4)]
    return np.vstack([vertices[a][None, :] * (1.0 - t[:, None]) + vertices[b][None, :] * t[:, None] for a, b in edges])


def array_network(
    rng: np.random.Generator,
    receivers: np.ndarray | None = None,
    *,
    cones: tuple[float, ...] = (-12.0, 2.0, 14.0),
    per_cone: int = 180,
    distance: tuple[float, float] = (3.5, 4.2),
    quantum: float = 0.25,
    outliers: float = 0.015,
    model_error: float = 3e-4,
) -> tuple[Network, np.ndarray, np.ndarray]:
    """A compact microphone array and far loudspeakers, measured as a real recording would be:
    (network, F, gross mask).

    Sources lie on elevation cones (degrees; `per_cone` azimuths each, uniform, with the cone's elevation
    jittered by up to 1 degree) at distances uniform in `distance` (m); emission offsets uniform in [0, 1] m.
    F[i, j] = |r_i - s_j| + o_j + model error, rounded to steps of `quantum` samples at SAMPLE_RATE
    (SPEED_OF_SOUND m/s; a quarter sample: 1.79 mm, rounding std 0.52 mm). The model error is what a
    point microphone does not capture (its body, diffraction by the frame): per microphone a smooth
    function of the direction of arrival u, model_error * u^T A_i u with A_i symmetric, traceless, of unit
    spectral norm (not a shift of the microphone: no position absorbs it). Then round(outliers x entries)
    gross errors: an entry moved by a wrong GCC-PHAT peak, a whole number of samples uniform in +-(10..60).

    Draws, in order: source azimuths, elevation jitters, distances, offsets, the A_i, then the gross entries,
    their shifts and signs. receivers: default :func:`tetrahedral_array` (48 microphones, radius 0.15 m).
    """
    R = tetrahedral_array() if receivers is None else np.asarray(receivers, dtype=float)
    if R.ndim != 2 or R.shape[1] != 3:
        raise ValueError(f"receivers must be (m, 3), got {R.shape}")
    if per_cone < 1 or not cones or quantum <= 0 or not 0.0 <= outliers < 1.0 or model_error < 0:
        raise ValueError("need per_cone >= 1, at least one cone, quantum > 0, 0 <= outliers < 1, model_error >= 0")
    m, n = R.shape[0], per_cone * len(cones)
    azimuth = rng.uniform(0.0, 2.0 * np.pi, n)
    elevation = np.radians(np.repeat(np.asarray(cones, dtype=float), per_cone) + rng.uniform(-1.0, 1.0, n))
    ranges = rng.uniform(*distance, n)
    offsets = rng.uniform(0.0, 1.0, n)
    u = np.column_stack([np.cos(elevation) * np.cos(azimuth), np.cos(elevation) * np.sin(azimuth), np.sin(elevation)])
    net = Network(R, u * ranges[:, None], offsets)
    A = rng.standard_normal((m, 3, 3))
    A = A + A.transpose(0, 2, 1)
    A -= np.trace(A, axis1=1, axis2=2)[:, None, None] * np.eye(3) / 3.0
    A /= np.abs(np.linalg.eigvalsh(A)).max(axis=1)[:, None, None]
    step = quantum * SPEED_OF_SOUND / SAMPLE_RATE
    F = net.measurements() + model_error * np.einsum("ja,iab,jb->ij", u, A, u)
    F = np.round(F / step) * step
    bad = np.zeros((m, n), bool)
    k = rng.choice(m * n, int(round(outliers * m * n)), replace=False)
    F.flat[k] += rng.integers(10, 61, k.size) * rng.choice([-1.0, 1.0], k.size) * (SPEED_OF_SOUND / SAMPLE_RATE)
    bad.flat[k] = True
    return net, F, bad
