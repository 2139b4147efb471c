"""The C kernels of F4 (:file:`f4_kernels.c`: sparse reduction, hashed monomial lookup), compiled on first
use and loaded by ctypes.

The kernel is the C twin of the numba kernel :func:`analysis.engine.sparse_kernels.sparse_echelon` (same
results; rows reduced a block at a time with vector multiplies, see the source's header). It exists because loading numba and its cached kernel costs a process about
0.45 s and 110 MB, more than the whole F4 run of most systems; the shared library loads in a millisecond.
It is compiled once with the system's C compiler (``$CC`` or ``cc``) into ``analysis/__pycache__`` (or the
user's cache directory when that is read-only), named by a hash of the source and the flags, so an edited
source is rebuilt. Without a working compiler :func:`kernel` returns None and callers use the numba
kernel.
"""
from __future__ import annotations

import contextlib
import ctypes
import os
import threading
import zlib
from pathlib import Path

import numpy as np

SOURCE = Path(__file__).with_name("f4_kernels.c")
FLAGS = ("-O3", "-funroll-loops", "-shared", "-fPIC", "-std=c99")
OPENMP = ("-fopenmp",)
"""Added to FLAGS where the compiler has OpenMP (gcc, clang with libomp): the row reduction, the symbolic
preprocessing, the column lookup and the pair update then run on ``threads`` threads; without it the library
is built single-threaded (same results)."""

_LOCK = threading.Lock()
_LOADED: list = []  # [library or None] once tried
_WHY: list[str] = []  # why the library is not loaded, once known (describe())


def _cache_dirs() -> list[Path]:
    user = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "tdoa-workbench"
    return [SOURCE.parent / "__pycache__", user]


DISABLE_ENV = "TDOA_WORKBENCH_NATIVE"
"""Set to ``off`` to run the numba/numpy kernels instead of the C ones (a comparison, a broken compiler);
the homotopy solvers' compiled tapes (:mod:`solvers.continuation.tape_native`) obey it too."""


def disabled() -> bool:
    """Whether ``TDOA_WORKBENCH_NATIVE`` switches the compiled C code off (``off``, ``0`` or ``no``)."""
    return os.environ.get(DISABLE_ENV, "").lower() in ("off", "0", "no")


def _build() -> Path | None:
    """The shared library for the current source, compiled if not cached; None without a compiler."""
    if disabled():
        _WHY.append(f"{DISABLE_ENV}={os.environ[DISABLE_ENV]}")
        return None
    if not SOURCE.exists():
        _WHY.append(f"{SOURCE} is missing")
        return None
    names = {flags: f"f4_kernels-{zlib.crc32(SOURCE.read_bytes() + ' '.join(flags).encode()):08x}.so"
             for flags in (FLAGS + OPENMP, FLAGS)}
    for folder in _cache_dirs():
        for name in names.values():
            if (folder / name).exists():
                return folder / name
    # only a process that compiles pays for these imports
    import shutil
    import subprocess
    import tempfile

    compiler = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    if compiler is None:
        _WHY.append("no C compiler found (cc, gcc or $CC)")
        return None
    for folder in _cache_dirs():
        try:
            folder.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(suffix=".so", dir=folder)
            os.close(fd)
        except OSError:
            continue
        try:
            for flags, name in names.items():  # with OpenMP first
                done = subprocess.run([compiler, *flags, "-o", tmp, str(SOURCE)], capture_output=True, timeout=120)
                if not done.returncode:
                    break
            if done.returncode:
                lines = done.stderr.decode(errors="replace").strip().splitlines()
                _WHY.append(f"{compiler} failed on {SOURCE.name}: {lines[0] if lines else done.returncode}")
                return None
            os.replace(tmp, folder / name)  # atomic: concurrent processes see a whole file or none
            for stale in folder.glob("f4_kernels-*.so"):  # builds of earlier sources
                if stale.name != name:
                    stale.unlink(missing_ok=True)
            return folder / name
        except (OSError, subprocess.SubprocessError) as exc:
            _WHY.append(f"{compiler} could not build {SOURCE.name}: {exc}")
            return None
        finally:
            if os.path.exists(tmp):
                os.unlink(tmp)
    return None


def kernel():
    """The loaded library (functions ``f4_sparse_echelon``, ``f4_free``, ``f4_index_of``, ``f4_update``,
    ``f4_reducers``, ``f4_new_terms``, ``f4_columns``, ``f4_preprocess``), or None when it cannot be built
    here."""
    if _LOADED:
        return _LOADED[0]
    with _LOCK:
        if not _LOADED:
            lib = None
            path = _build()
            if path is not None:
                # threads that wait for work sleep instead of spinning: on a machine shared with other
                # processes a spinning thread takes the core its partner needs (katsura-9 on 2 threads at
                # load 8 on 2 cores: 2x slower than one thread when spinning, as fast when sleeping).
                # Read once, when OpenMP starts; a value the user set is kept.
                os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
                try:
                    lib = ctypes.CDLL(str(path))
                except OSError as exc:
                    _WHY.append(f"{path} did not load: {exc}")
                    lib = None
            if lib is not None:
                lib.f4_sparse_echelon.restype = ctypes.c_int
                lib.f4_sparse_echelon.argtypes = [ctypes.c_void_p] * 4 + [ctypes.c_int64] + [ctypes.c_void_p] * 4 + [
                    ctypes.c_int64, ctypes.c_int64, ctypes.c_int64, ctypes.c_int, ctypes.c_int, ctypes.c_void_p]
                lib.f4_free.restype = None
                lib.f4_free.argtypes = [ctypes.c_void_p]
                lib.f4_update.restype = ctypes.c_int
                lib.f4_update.argtypes = [ctypes.c_int64] + [ctypes.c_void_p] * 3 + [ctypes.c_int64] * 3 + [
                    ctypes.c_void_p] * 4 + [ctypes.c_int]
                lib.f4_openmp.restype = ctypes.c_int
                lib.f4_openmp.argtypes = []
                lib.f4_reducers.restype = ctypes.c_int
                lib.f4_reducers.argtypes = [ctypes.c_int64, ctypes.c_void_p, ctypes.c_int64, ctypes.c_void_p,
                                            ctypes.c_int64, ctypes.c_void_p]
                lib.f4_new_terms.restype = ctypes.c_int
                lib.f4_new_terms.argtypes = [ctypes.c_void_p] * 4 + [ctypes.c_int64, ctypes.c_void_p, ctypes.c_int64,
                                                                     ctypes.c_void_p]
                lib.f4_columns.restype = ctypes.c_int
                lib.f4_columns.argtypes = [ctypes.c_void_p] * 4 + [ctypes.c_int64, ctypes.c_void_p, ctypes.c_int64,
                                                                   ctypes.c_void_p, ctypes.c_int]
                lib.f4_preprocess.restype = ctypes.c_int
                lib.f4_preprocess.argtypes = [ctypes.c_void_p] * 5 + [ctypes.c_int64, ctypes.c_void_p, ctypes.c_int64,
                                              ctypes.c_int64, ctypes.c_void_p, ctypes.c_uint64] + [
                    ctypes.c_void_p] * 3 + [ctypes.c_int64, ctypes.c_int, ctypes.c_int, ctypes.c_void_p]
                lib.f4_index_of.restype = ctypes.c_int
                lib.f4_index_of.argtypes = [ctypes.c_void_p, ctypes.c_int64, ctypes.c_void_p, ctypes.c_int64,
                                            ctypes.c_void_p]
            _LOADED.append(lib)
    return _LOADED[0]


@contextlib.contextmanager
def share_small_work():
    """Within the block, every C step that can share its work among threads does so however small its
    input (the library's ``f4_share_small``): the tests run the threaded code paths on small systems.
    Not thread-safe; for tests."""
    lib = kernel()
    flag = ctypes.c_int.in_dll(lib, "f4_share_small")
    before, flag.value = flag.value, 1
    try:
        yield
    finally:
        flag.value = before


def describe() -> str:
    """One line for a report: which F4 kernels this process runs, and why not the C ones when it cannot."""
    lib = kernel()
    if lib is not None:
        return f"C kernels ({lib._name}{', OpenMP threads' if lib.f4_openmp() else ', one thread: no OpenMP'})"
    return f"numba/numpy kernels ({_WHY[-1] if _WHY else 'the C kernels are unavailable'})"


def _take(address: int, count: int, dtype) -> np.ndarray:
    """A copy of count values of dtype at a C address."""
    if not count:
        return np.zeros(0, dtype=dtype)
    return np.frombuffer((ctypes.c_char * (count * np.dtype(dtype).itemsize)).from_address(address), dtype=dtype).copy()


def sparse_echelon(piv_indptr, piv_cols, piv_vals, piv_offsets, row_indptr, row_cols, row_vals, row_offsets,
                   ncols: int, p: int, echelon: bool, threads: int = 1):
    """As :func:`analysis.engine.sparse_kernels.sparse_echelon` (indptr int64, columns and values int32, all
    C-contiguous), by the C kernel, except that the values of row i of a block start at vals[offsets[i]]
    (int64; indptr[:-1] for the plain layout), on up to ``threads`` threads (the same result: blocks of
    rows are reduced concurrently, a new pivot published by compare-and-swap at its leading column; one
    thread where the library was built without OpenMP); returns (indptr int64, cols int32, vals int32)."""
    lib = kernel()
    result = np.zeros(4, dtype=np.int64)
    status = lib.f4_sparse_echelon(
        piv_indptr.ctypes.data, piv_cols.ctypes.data, piv_vals.ctypes.data, piv_offsets.ctypes.data,
        len(piv_indptr) - 1, row_indptr.ctypes.data, row_cols.ctypes.data, row_vals.ctypes.data,
        row_offsets.ctypes.data, len(row_indptr) - 1, ncols, p, int(echelon), int(threads), result.ctypes.data,
    )
    if status:
        raise MemoryError("the C sparse kernel ran out of memory")
    addresses = [int(a) for a in result[:3]]
    try:
        indptr = _take(addresses[0], int(result[3]) + 1, np.int64)
        size = int(indptr[-1])
        return indptr, _take(addresses[1], size, np.int32), _take(addresses[2], size, np.int32)
    finally:
        for address in addresses:
            lib.f4_free(address)


def index_of(keys: np.ndarray, queries: np.ndarray) -> np.ndarray:
    """Position of every query in keys (distinct values), -1 where absent: ``np.searchsorted`` on sorted
    keys with a check, by a hash table in C for uint64 codes (several times faster on large matrices:
    one probe instead of log2(len(keys)) cache misses), by numpy otherwise."""
    lib = kernel()
    if lib is None or keys.dtype != np.uint64 or queries.dtype != np.uint64 or not len(keys):
        at = np.searchsorted(keys, queries)
        at[at == len(keys)] = 0
        if len(keys):
            at[keys[at] != queries] = -1
        else:
            at[:] = -1
        return at
    keys, queries = np.ascontiguousarray(keys), np.ascontiguousarray(queries)
    out = np.empty(len(queries), dtype=np.int64)
    if lib.f4_index_of(keys.ctypes.data, len(keys), queries.ctypes.data, len(queries), out.ctypes.data):
        raise MemoryError("the C lookup ran out of memory")
    return out


def pair_update(E: np.ndarray, degrees: np.ndarray, active: np.ndarray, k: int, m: int, pairs: np.ndarray,
                lcms: np.ndarray, threads: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The Gebauer-Möller update of :meth:`analysis.engine.f4._State.insert` for the new elements k, ..., k + m - 1
    (E: int32 exponents of all k + m elements, degrees int64, active: bool flags of the k old ones; pairs
    (i, j, lcm degree) int64 with int32 lcm exponents lcms), on up to ``threads`` threads (the same pairs on
    any count). Returns (keep mask of the existing pairs, new pairs, their lcm exponents, active flags of all
    k + m elements)."""
    lib = kernel()
    n = E.shape[1]
    E, degrees = np.ascontiguousarray(E, dtype=np.int32), np.ascontiguousarray(degrees, dtype=np.int64)
    pairs, lcms = np.ascontiguousarray(pairs, dtype=np.int64), np.ascontiguousarray(lcms, dtype=np.int32)
    flags = np.zeros(k + m, dtype=np.uint8)
    flags[:k] = active
    keep = np.empty(len(pairs), dtype=np.uint8)
    result = np.zeros(3, dtype=np.int64)
    if lib.f4_update(n, E.ctypes.data, degrees.ctypes.data, flags.ctypes.data, k, m, len(pairs), pairs.ctypes.data,
                     lcms.ctypes.data, keep.ctypes.data, result.ctypes.data, int(threads)):
        raise MemoryError("the C pair update ran out of memory")
    count = int(result[2])
    try:
        new = _take(int(result[0]), 4 * count, np.int64).reshape(count, 4)
        new_lcms = _take(int(result[1]), n * count, np.int32).reshape(count, n)
    finally:
        lib.f4_free(int(result[0]))
        lib.f4_free(int(result[1]))
    alive = new[:, 3] >= 0
    return keep.view(bool), new[alive, :3], new_lcms[alive], flags.view(bool)


def first_divisors(leads: np.ndarray, monomials: np.ndarray) -> np.ndarray:
    """For each exponent row of monomials, the position of the first row of leads (exponents) that divides
    it, or -1 (by the C kernel; both int32-convertible, same number of columns)."""
    lib = kernel()
    leads = np.ascontiguousarray(leads, dtype=np.int32)
    monomials = np.ascontiguousarray(monomials, dtype=np.int32)
    best = np.empty(len(monomials), dtype=np.int64)
    if lib.f4_reducers(leads.shape[1], leads.ctypes.data, len(leads), monomials.ctypes.data, len(monomials),
                       best.ctypes.data):
        raise MemoryError("the C reducer search ran out of memory")
    return best


def _rows_args(pool: np.ndarray, starts: np.ndarray, lengths: np.ndarray, mult: np.ndarray) -> tuple:
    """Rows mult[r] * (the terms pool[starts[r] : starts[r] + lengths[r]]) as C arguments (and the arrays
    that must stay alive while they are used)."""
    arrays = (np.ascontiguousarray(pool), np.ascontiguousarray(starts, dtype=np.int64),
              np.ascontiguousarray(lengths, dtype=np.int64), np.ascontiguousarray(mult))
    return tuple(a.ctypes.data for a in arrays) + (len(starts),), arrays


def new_terms(pool: np.ndarray, starts: np.ndarray, lengths: np.ndarray, mult: np.ndarray,
              known: np.ndarray) -> np.ndarray:
    """The distinct codes (uint64) of the terms of the rows mult[r] * pool[starts[r] : starts[r] + lengths[r]]
    that are not in known (distinct codes), in order of first occurrence, by the C kernel."""
    lib = kernel()
    args, keep = _rows_args(pool, starts, lengths, mult)
    known = np.ascontiguousarray(known)
    result = np.zeros(2, dtype=np.int64)
    if lib.f4_new_terms(*args, known.ctypes.data, len(known), result.ctypes.data):
        raise MemoryError("the C term search ran out of memory")
    try:
        return _take(int(result[0]), int(result[1]), np.uint64)
    finally:
        lib.f4_free(int(result[0]))


def column_indices(pool: np.ndarray, starts: np.ndarray, lengths: np.ndarray, mult: np.ndarray,
                   columns: np.ndarray, threads: int = 1) -> np.ndarray:
    """The column (int32; len(columns) - 1 - position in the ascending codes columns) of every term of the
    rows mult[r] * pool[starts[r] : starts[r] + lengths[r]], row after row, by the C kernel on up to
    ``threads`` threads."""
    lib = kernel()
    args, keep = _rows_args(pool, starts, lengths, mult)
    columns = np.ascontiguousarray(columns)
    out = np.empty(int(np.sum(lengths)), dtype=np.int32)
    if lib.f4_columns(*args, columns.ctypes.data, len(columns), out.ctypes.data, threads):
        raise MemoryError("the C column lookup ran out of memory")
    return out


def preprocess(pool: np.ndarray, starts: np.ndarray, lengths: np.ndarray, lm_codes: np.ndarray, act: np.ndarray,
               act_exps: np.ndarray, shifts: np.ndarray, field_mask: int, winv_t: np.ndarray, mult: np.ndarray,
               index: np.ndarray, leads_done: bool, threads: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Symbolic preprocessing of :func:`analysis.engine.f4._preprocess` in C, for narrow codes of a graded order
    (per element: term pool offsets and lengths, leading codes; the active elements in order of preference
    with their lead exponents; the codes' field shifts, mask and inverse weights), on up to ``threads``
    threads (the set of codes seen split by a hash among them; the same result on any count). Returns the
    reducers' multipliers (uint64) and elements (int64), wave by wave, and the matrix columns (codes,
    ascending)."""
    lib = kernel()
    arrays = [np.ascontiguousarray(pool), np.ascontiguousarray(starts, dtype=np.int64),
              np.ascontiguousarray(lengths, dtype=np.int64), np.ascontiguousarray(lm_codes),
              np.ascontiguousarray(act, dtype=np.int64), np.ascontiguousarray(act_exps, dtype=np.int32),
              np.ascontiguousarray(shifts, dtype=np.uint64), np.ascontiguousarray(winv_t, dtype=np.int64),
              np.ascontiguousarray(mult), np.ascontiguousarray(index, dtype=np.int64)]
    pool, starts, lengths, lm_codes, act, act_exps, shifts, winv_t, mult, index = arrays
    result = np.zeros(5, dtype=np.int64)
    if lib.f4_preprocess(pool.ctypes.data, starts.ctypes.data, lengths.ctypes.data, lm_codes.ctypes.data,
                         act.ctypes.data, len(act), act_exps.ctypes.data, act_exps.shape[1], len(shifts),
                         shifts.ctypes.data, field_mask, winv_t.ctypes.data, mult.ctypes.data, index.ctypes.data,
                         len(index), int(leads_done), int(threads), result.ctypes.data):
        raise MemoryError("the C symbolic preprocessing ran out of memory")
    addresses = [int(result[0]), int(result[1]), int(result[3])]
    try:
        return (_take(addresses[0], int(result[2]), np.uint64), _take(addresses[1], int(result[2]), np.int64),
                _take(addresses[2], int(result[4]), np.uint64))
    finally:
        for address in addresses:
            lib.f4_free(address)
