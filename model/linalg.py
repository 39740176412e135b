"""Compiled linear algebra of the hot path: the lowest eigenpairs, the Newton solve and system, one C call each.

**Eigen solve** (:func:`lowest_pairs`). The algorithm is the one :func:`model.modal._lowest_pairs`
documents (Jacobi scaling ``D = diag(K)^(-1/2)``, Cholesky ``K_s = L L^T``, the standard problem ``C y = mu y``
with ``C = L^-1 M_s L^-T`` and ``mu = 1/lambda``, vectors ``phi = D L^-T y / sqrt(mu)``); only the symmetric
eigen solver differs. LAPACK's expert driver dsyevx (and dsyevr, for a subset of the spectrum) finds the
wanted pairs by bisection and inverse iteration, which costs several times the Householder
tridiagonalisation at a flexure model's sizes (241 us against 47 us at n = 59). Here the tridiagonal
problem is solved by the MRRR algorithm for the ``k`` wanted pairs only (dstemr: Dhillon, Parlett and
Voemel, ACM TOMS 32(4), 2006) and the vectors are transformed back by dormtr. Each eigenvalue is then
replaced by the Rayleigh quotient of its vector accumulated in extended precision (``long double``), which
takes the relative error of thin, finely meshed leaves from a few 1e-8 (cancellation in ``K x``) to about
1e-11 (issue 12 item 2; tests/test_eigen_accuracy.py).

**Banded eigen solve** (:func:`lowest_pairs_banded`). A flexure's pencil is sparse: its nonzeros are the
elements' 12 x 12 blocks, within half bandwidth 11-23 of the diagonal on the templates after a reverse
Cuthill-McKee order (:func:`band_order`), so the dense reduction (O(n^3): 5-6 ms of a 6 ms solve at n = 239)
does work on zeros. This route keeps the same scaled standard problem but factorises ``K_s`` in band form
(dpbtrf) and runs Lanczos on ``U^-T M_s U^-1`` with full reorthogonalisation from a fixed pseudo-random start
(each step two banded triangular solves and a banded product); the largest ``mu`` of a flexure converge in
20-40 steps to residuals of 1e-14 ``mu_max``. A Lanczos vector can miss an eigenvalue (an exact multiple, or
a start orthogonal to a mode), so each result is checked by a Sturm count, the inertia of
``K_s - sigma M_s`` just above the k-th eigenvalue (banded LDL^T), which must be exactly k; otherwise, or
without convergence, the dense route answers. The eigenvalues are the same extended-precision Rayleigh
quotients; against an extended-precision reference both routes err by about 1e-10 at most
(tests/test_eigen_accuracy.py, tests/test_linalg.py).

**Newton solve** (:func:`solve`): LU with partial pivoting (dgetrf, dgetrs) of a row-major matrix, read as
its transpose by LAPACK and solved with ``trans = 'T'``, so nothing is copied.

**Newton system** (:func:`newton`): one iteration's whole linear-algebra step of model.statics -- the twist
drive and its gradient, the reduced free block or the bordered system, its LU solve, the scaled increment
and residual -- in one call, with the same floating-point operations in the same order as the numpy code
(``_newton_step``, ``_scaled_residual``, model.rotations), so the same numbers to the bit
(tests/test_linalg.py); the numpy code remains the route without a compiler and for drive bases that are
not made of global axes or structures with rigid deformations. Where the system's band after
:func:`band_order` is narrow (:data:`BAND_FRACTION`), it is solved by a banded LU (dgbtrf/dgbtrs) instead:
the same system, other rounding (backward error checked in the tests).

The routines come from :func:`model.lapack.routines` (numpy's OpenBLAS, else scipy's), so this path never
imports ``scipy.linalg``. The C code (model/native/linalg.c) is compiled once and cached like the element kernels
(:func:`model.kernels.native_library`); without a C compiler or a usable LAPACK :func:`available` is False
and the callers use scipy's Python wrappers.
"""

from __future__ import annotations

import ctypes
import threading
from typing import Literal

import numpy as np

from .errors import KernelBuildError
from .kernels import c_enum, native_library
from .lapack import NAMES, routines

__all__ = [
    "lowest_pairs",
    "lowest_pairs_banded",
    "BandedPencil",
    "solve",
    "newton",
    "NewtonSystem",
    "available",
    "build",
    "band_order",
]

#: Up to this order ``C = L^-1 M_s L^-T`` is formed by two triangular solves (BLAS dtrsm), above it by
#: LAPACK dsygst (half the flops): whole eigen solve measured 324 vs 384 us at n = 59, even at n = 89-119
#: (scipy route, model.modal); the compiled driver takes the same switch.
TRSM_MAX = 80

_LOCAL = threading.local()  # workspace per thread (ctypes releases the GIL during the call) and per order
_DRIVER: list = []  # [(library, routines)] once loaded, [None] when unavailable


def source_definitions(int_type: str) -> tuple[tuple[tuple[str, str]], str]:
    """What model/native/linalg.c needs defined before it: ``FINT`` (the LAPACK integer ``int_type``) and the
    slots of the LAPACK pointer table, an enum of :data:`model.lapack.NAMES` (``fp[DGETRF]``)."""
    return (("FINT", int_type),), c_enum(NAMES, "lapack_routine")


def build(table) -> tuple | None:
    """Compile (or load from the cache) the driver for one LAPACK pointer table (model.lapack.Routines);
    ``(library, table, integer dtype)``, or None without a working C compiler."""
    try:
        lib = native_library("flexopt_linalg", "linalg.c", *source_definitions(table.int_type))
    except KernelBuildError:
        return None
    L, P = ctypes.c_longlong, ctypes.c_void_p
    lib.lowest_pairs.restype = L
    lib.lowest_pairs.argtypes = [L, L, L, P, P, P, P, P, P, P, L]
    lib.solve.restype = L
    lib.solve.argtypes = [L, L, P, P, P, P]
    lib.newton.restype = L
    lib.newton.argtypes = [P] * 13
    lib.lanczos_pairs.restype = L
    lib.lanczos_pairs.argtypes = [P] * 13
    lib.lanczos_doubles.restype = L
    lib.lanczos_doubles.argtypes = [L, L, L]
    for name in ("work_doubles", "work_ints"):
        getattr(lib, name).restype = L
        getattr(lib, name).argtypes = [L]
    return lib, table, (np.int64 if table.int_type == "long long" else np.intc)


def _driver():
    if not _DRIVER:
        table = routines()
        _DRIVER.append(build(table) if table is not None else None)
    return _DRIVER[0]


def available() -> bool:
    """Whether the compiled drivers could be built (a C compiler and a LAPACK, see model.lapack)."""
    return _driver() is not None


def _thread_cache() -> dict:
    """This thread's workspaces (ctypes releases the GIL during a call), by key."""
    cache = getattr(_LOCAL, "work", None)
    if cache is None:
        cache = _LOCAL.work = {}
    return cache


def _workspace(n: int, drv: tuple) -> tuple[int, int, int, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """The work arrays of order ``n`` (doubles, integers, pivots) of this thread: their addresses and them."""
    cache = _thread_cache()
    key = (n, drv[2])
    ws = cache.get(key)
    if ws is None:  # kept per order: no allocation (nor page faults) per call
        lib, _, int_dtype = drv
        arrays = (
            np.empty(lib.work_doubles(n)),
            np.empty(lib.work_ints(n), dtype=int_dtype),
            np.empty(max(n, 1), dtype=int_dtype),
        )
        # their addresses, taken once (``.ctypes.data`` costs about 1.5 us a call); the arrays stay referenced
        ws = cache[key] = (*(a.ctypes.data for a in arrays), arrays)
    return ws


def lowest_pairs(
    K: np.ndarray, M: np.ndarray, k: int, refine: bool = True, driver: tuple | None = None
) -> tuple[np.ndarray, np.ndarray] | None | Literal[False]:
    """The ``k`` lowest eigenpairs ``(lambda, phi)`` of ``K phi = lambda M phi`` through ``K``.

    Returns ``None`` when the driver is not available (no C compiler), ``False`` when ``K`` is not positive
    definite or a diagonal entry of ``M`` is not positive (the caller's route through ``M`` applies), the
    eigenvalues ascending and the mass-normalised vectors otherwise. ``refine``: eigenvalues as Rayleigh
    quotients in extended precision (see the module docstring). ``driver``: one from :func:`build` instead
    of the process's own (tests compare the LAPACK sources).
    """
    drv = driver or _driver()
    if drv is None:
        return None
    lib, table, _ = drv
    K, M, lam, X = _pencil(K, M, k)
    n = K.shape[0]
    work, iwork, _, _ = _workspace(n, drv)
    status = lib.lowest_pairs(
        n,
        k,
        TRSM_MAX,
        K.ctypes.data,
        M.ctypes.data,
        lam.ctypes.data,
        X.ctypes.data,
        table.table,
        work,
        iwork,
        int(refine),
    )
    return _pairs(status, lam, X)  # None on a LAPACK failure: the scipy route decides what is wrong


def _pencil(K: np.ndarray, M: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Both eigen drivers' inputs as contiguous float64 and their outputs ``lam`` (k) and ``X`` (n x k)."""
    K = np.ascontiguousarray(K, dtype=np.float64)
    M = np.ascontiguousarray(M, dtype=np.float64)
    return K, M, np.empty(k), np.empty((K.shape[0], k))


def _pairs(status: int, lam: np.ndarray, X: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None | Literal[False]:
    """An eigen driver's status read as ``(lam, X)`` (0), ``False`` (1: the route through M) or ``None``."""
    if status == 0:
        return lam, X
    if status == 1:
        return False
    return None


#: Lanczos: at most this many vectors (the templates converge in 20-38), the residual bound of each wanted Ritz
#: pair relative to the largest (1e-14: about the dense solver's own accuracy, see lanczos_pairs), and the
#: relative distance above the k-th eigenvalue at which the Sturm count is taken.
LANCZOS_STEPS, LANCZOS_TOL, STURM_GAP = 80, 1e-14, 1e-7


#: A Lanczos solve given the step count of a solve of a neighbouring problem (the previous point of a curve)
#: computes its first Ritz pairs there, and every :data:`PROBE_EVERY`-th solve in a row that converged at its
#: first check tries two steps fewer (see :func:`lanczos_first_check`).
PROBE_EVERY = 8


def lanczos_first_check(k: int, hint: tuple[int, int] | None) -> int:
    """The Lanczos step at which a solve with ``k`` pairs first computes its Ritz pairs, from ``hint`` = (steps,
    run) of the solve of a neighbouring problem: its step count, and how many solves in a row converged at
    their first check. One MRRR solve of the Lanczos matrix costs as much as four to six Lanczos steps at the
    templates' sizes, and consecutive points of a curve need about the same number of steps, so checking first
    where the last solve stopped saves the checks before it; a run of :data:`PROBE_EVERY` first-check
    convergences tries two steps fewer, so the count follows a problem that gets easier. Without a hint,
    ``3 k``. The result depends only on the arguments: a solve is reproducible from its inputs."""
    if hint is None:
        return 3 * k
    steps, run = hint
    return max(k, steps - 2 if run >= PROBE_EVERY else steps)


class BandedPencil:
    """A structure's banded eigen problem for :func:`lowest_pairs_banded`: the free block (indices ``idx``) of
    the whole n x n stiffness and mass, read in place (row stride ``ld``), its band order ``perm`` with half
    bandwidth ``kd`` (:func:`band_order`), and the index maps with their addresses taken once."""

    def __init__(self, idx: np.ndarray, ld: int, perm: np.ndarray, kd: int) -> None:
        idx = np.ascontiguousarray(idx, dtype=np.int64)
        self.n, self.kd = len(idx), int(kd)
        self.perm = np.ascontiguousarray(perm, dtype=np.int64)
        self.ro, self.co = idx * int(ld), idx
        self.ip = np.zeros(7, dtype=np.int64)
        self.dp = np.array([LANCZOS_TOL, STURM_GAP])
        self.at = [a.ctypes.data for a in (self.ip, self.dp, self.perm, self.ro, self.co)]

    def solve(
        self,
        K: np.ndarray,
        M: np.ndarray,
        k: int,
        X: np.ndarray,
        xo_at: int,
        refine: bool = True,
        hint: tuple[int, int] | None = None,
    ) -> tuple[np.ndarray | None | Literal[False], tuple[int, int] | None]:
        """The ``k`` lowest eigenvalues and vectors (written to the rows ``xo`` of ``X``, n_rows x k, C-contiguous)
        of the free block of ``K``, ``M`` (C-contiguous float64, row stride ``ld``): ``(lam, (steps, run))``,
        the second the ``hint`` for the next solve (:func:`lanczos_first_check`); ``lam`` None or False as
        :func:`lowest_pairs_banded` returns them."""
        drv = _driver()
        if drv is None:
            return None, None
        lib, table, _ = drv
        n, kd = self.n, self.kd
        cache = _thread_cache()
        buf = cache.get(("lanczos", n, kd))
        if buf is None:  # kept per order and band, like _workspace
            arr = np.empty(lib.lanczos_doubles(n, kd, LANCZOS_STEPS))
            buf = cache[("lanczos", n, kd)] = (arr.ctypes.data, arr)
        _, iwork, _, _ = _workspace(n, drv)
        ip = self.ip
        first = lanczos_first_check(k, hint)
        ip[0], ip[1], ip[2], ip[3], ip[4], ip[5] = n, k, kd, LANCZOS_STEPS, int(refine), first
        lam = np.empty(k)
        a = self.at
        status = lib.lanczos_pairs(
            a[0],
            a[1],
            a[2],
            a[3],
            a[4],
            xo_at,
            K.ctypes.data,
            M.ctypes.data,
            lam.ctypes.data,
            X.ctypes.data,
            table.table,
            buf[0],
            iwork,
        )
        if status != 0:
            return (False if status == 1 else None), None
        steps = int(ip[6])
        if steps != first:
            run = 0
        else:
            run = 1 if hint is None or hint[1] >= PROBE_EVERY else hint[1] + 1
        return lam, (steps, run)


def lowest_pairs_banded(
    K: np.ndarray, M: np.ndarray, k: int, perm: np.ndarray, kd: int, refine: bool = True
) -> tuple[np.ndarray, np.ndarray] | None | Literal[False]:
    """:func:`lowest_pairs` for a pencil whose nonzeros lie within ``kd`` of the diagonal in the order
    ``perm`` (:func:`band_order`), by Lanczos on the banded Cholesky factor (C ``lanczos_pairs``: its
    docstring says how it is checked). The same returns, and ``None`` also when Lanczos did not converge or
    its Sturm count disagrees: the caller then takes the dense route, which is always right. (The eigen
    solves of a curve go through a :class:`BandedPencil` of the structure, which reads the free block in
    place and remembers the step count.)"""
    K, M, _, X = _pencil(K, M, k)
    n = K.shape[0]
    pencil = BandedPencil(np.arange(n), n, perm, kd)
    lam, _ = pencil.solve(K, M, k, X, pencil.co.ctypes.data, refine)
    if lam is None or lam is False:
        return lam
    return lam, X


def solve(A: np.ndarray, B: np.ndarray) -> int | None:
    """Solve ``A X = B`` in place: ``A`` square, C-contiguous float64 (destroyed), ``B`` Fortran-ordered
    float64 (overwritten by ``X``). Returns LAPACK's info (0: solved; > 0: ``A`` is singular), ``None``
    without the compiled driver (the caller solves another way; nothing was touched)."""
    drv = _driver()
    if drv is None:
        return None
    lib, table, _ = drv
    n = A.shape[0]
    if not (
        A.flags.c_contiguous
        and A.dtype == np.float64
        and B.dtype == np.float64
        and (B.flags.f_contiguous or B.ndim == 1)
        and B.shape[0] == n
    ):
        raise ValueError("solve needs a C-contiguous float64 A and a Fortran-ordered float64 B of matching rows")
    if n == 0:
        return 0
    _, _, ipiv, _ = _workspace(n, drv)
    nrhs = B.shape[1] if B.ndim == 2 else 1
    return int(lib.solve(n, nrhs, A.ctypes.data, B.ctypes.data, ipiv, table.table))


def band_order(pattern: np.ndarray) -> tuple[np.ndarray, int, int]:
    """An ordering that gives the square nonzero ``pattern`` a narrow band: ``(perm, kl, ku)``, position ``p``
    holding row and column ``perm[p]``, with ``kl`` sub- and ``ku`` superdiagonals after it.

    Reverse Cuthill-McKee (Cuthill and McKee 1969; George and Liu, Computer Solution of Large Sparse Positive
    Definite Systems, 1981, ch. 4) on the symmetrised pattern, each connected part started from a
    pseudo-peripheral node (George and Liu's algorithm: the lowest-degree node of the last breadth-first
    level until the number of levels stops growing), neighbours taken in increasing degree; the given order
    is kept when it is already narrower. Written here because ``scipy.sparse.csgraph`` costs 0.4 s to import
    and a structure's ordering is found once (tests/test_linalg.py compares it with scipy's)."""
    P = np.asarray(pattern, dtype=bool)
    key = (P.shape, np.packbits(P).tobytes())
    hit = _BAND_ORDERS.get(key)
    if hit is None:
        hit = _band_order(P)
        if len(_BAND_ORDERS) >= 64:  # bounded (the optimiser builds a system per design, a family's alike)
            _BAND_ORDERS.clear()
        _BAND_ORDERS[key] = hit
    return hit[0].copy(), hit[1], hit[2]


#: band_order's results by pattern: a family's designs differ in dimensions, not in their pattern, and the
#: Python RCM cost 3-4 ms a system (an eighth of a topology search before this memo)
_BAND_ORDERS: dict = {}


def _band_order(P: np.ndarray) -> tuple[np.ndarray, int, int]:
    """:func:`band_order` of the boolean ``P``, computed."""
    m = P.shape[0]
    S = P | P.T
    np.fill_diagonal(S, False)
    nbrs = [np.flatnonzero(row) for row in S]
    deg = np.array([len(a) for a in nbrs])
    # each node's neighbours in increasing (degree, index), sorted once: a breadth-first sweep filters them
    # (keeping the order) instead of sorting them again at every visit of every sweep
    ranked = [a[np.lexsort((a, deg[a]))].tolist() for a in nbrs]

    def levels(root: int, allowed: np.ndarray) -> list[list[int]]:
        ok = allowed.tolist()
        seen = [False] * m
        seen[root] = True
        out, front = [], [root]
        while front:
            out.append(front)
            nxt = []
            for v in front:
                for w in ranked[v]:
                    if ok[w] and not seen[w]:
                        seen[w] = True
                        nxt.append(w)
            front = nxt
        return out

    order: list[int] = []
    left = np.ones(m, dtype=bool)
    while left.any():
        cand = np.flatnonzero(left)
        root = int(cand[np.argmin(deg[cand])])
        lv = levels(root, left)
        while True:  # pseudo-peripheral root
            last = lv[-1]
            far = min(last, key=lambda u: (deg[u], u))
            lv2 = levels(far, left)
            if len(lv2) <= len(lv):
                break
            root, lv = far, lv2
        part = [v for level in lv for v in level]
        order.extend(part)
        left[part] = False
    perm = np.array(order[::-1], dtype=np.int64)

    def widths(p: np.ndarray) -> tuple[int, int]:
        r, c = np.nonzero(P[np.ix_(p, p)])
        return (int(max(0, (r - c).max(initial=0))), int(max(0, (c - r).max(initial=0))))

    kl, ku = widths(perm)
    kl0, ku0 = widths(np.arange(m))
    if kl0 + ku0 <= kl + ku:
        return np.arange(m, dtype=np.int64), kl0, ku0
    return perm, kl, ku


#: A Newton matrix of order m is solved by a banded LU (dgbtrf) when its band, kl + ku + 1 diagonals after
#: band_order, is at most this fraction of m; measured (throwaway timing of LAPACK's dgetrf against dgbtrf on the
#: templates' tangent stiffness): 32 -> 5 us at m = 58 (band 9), 93 -> 39 at 88 (27), 694 -> 24 at 238 (9).
BAND_FRACTION = 0.5


class NewtonSystem:
    """The fixed data of one structure's compiled Newton system (C ``newton`` of model/native/linalg.c): index and
    scale arrays, with their addresses taken once, the work arrays, and the band orders of its two forms. Made by
    :func:`newton_system`; the row stride of H and C is set by each :func:`newton` call from the arrays it gets.

    ``pattern`` (n x n, bool): every entry of ``H + C`` that can be nonzero (the elements' DOF blocks and the
    chart's rotation blocks). With it, each form of the system (the reduced free block; the bordered matrix, in
    DOF order with the drive's row replaced by the drive gradient's pattern) whose band after
    :func:`band_order` is narrow enough (:data:`BAND_FRACTION`) is solved by a banded LU: at 40 elements a
    leaf's dense LU cost 0.7 ms of a 1.1 ms Newton iteration. None, or ``banded=False``: dense LU only (the
    same numbers as the numpy route, bit for bit)."""

    def __init__(
        self,
        n: int,
        drive: int,
        kind: int,
        free: np.ndarray,
        block_pos: np.ndarray,
        block_comp: np.ndarray,
        axis: np.ndarray,
        scale: np.ndarray,
        scale_free: np.ndarray,
        drv: tuple,
        pattern: np.ndarray | None = None,
        banded: bool = True,
    ) -> None:
        self.n, self.drv = n, drv
        int_dtype = drv[2]
        self.bands: dict[str, tuple[int, int] | None] = {"reduced": None, "bordered": None}
        orders = []
        for form in ("reduced", "bordered"):
            band = [-1, -1] + [0] * (n - 1 if form == "reduced" else n)
            if pattern is not None and banded and n > 1:
                P = np.array(pattern, dtype=bool)
                if form == "reduced":
                    P = P[np.ix_(free, free)]
                else:
                    P[drive] = False
                    P[drive, [*block_pos, drive] if kind == 0 else [drive]] = True
                perm, kl, ku = band_order(P)
                m = P.shape[0]
                if kl + ku + 1 <= BAND_FRACTION * m and (2 * kl + ku + 1) * m <= n * n:
                    band = [kl, ku, *perm]
                    self.bands[form] = (kl, ku)
            orders.append(band)
        self.ip = np.concatenate([[n, 0, drive, kind, len(block_pos)], free, block_pos, block_comp, *orders]).astype(
            np.int64
        )
        self.dp = np.concatenate([axis, [0.0, 0.0, 0.0], scale, scale_free]).astype(np.float64)
        self.J = np.empty(max(n * n, 1))
        self.b = np.empty(5 * max(n, 1))
        self.ipiv = np.empty(max(n, 1), dtype=int_dtype)
        self.sc = np.empty(6)
        self.eye = np.eye(3).ravel()  # the rotation argument of a translation drive (not read)
        self.ptr = [a.ctypes.data for a in (self.ip, self.dp, self.J, self.b, self.ipiv, self.sc, self.eye)]


def newton(
    ns: NewtonSystem,
    H: np.ndarray,
    C: np.ndarray | None,
    g: np.ndarray,
    Rd: np.ndarray | None,
    near: float,
    s_target: float,
    dval: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One Newton system in C: ``(dxi, tan, [dval, inc, res, finite, info, reduced])``. ``H`` and ``C``: n x n
    views with a common row stride (``C`` may be None), ``g`` contiguous, ``Rd`` the driven master's rotation
    (None for a translation drive, whose ``dval`` is given)."""
    lib, table, _ = ns.drv
    n = ns.n
    stride = H.strides[0] // 8
    if H.strides[1] != 8 or (C is not None and C.strides != H.strides) or not g.flags.c_contiguous:
        raise ValueError("newton needs H and C with unit column stride and one row stride, and a contiguous g")
    ns.dp[3], ns.dp[4], ns.dp[5] = near, s_target, dval
    ns.ip[1] = stride
    dxi, tan = np.empty(n), np.empty(n)
    ip, dp, J, b, ipiv, sc, eye = ns.ptr
    R = eye if Rd is None else np.ascontiguousarray(Rd, dtype=np.float64).ctypes.data
    lib.newton(
        ip,
        dp,
        H.ctypes.data,
        None if C is None else C.ctypes.data,
        g.ctypes.data,
        R,
        J,
        b,
        ipiv,
        table.table,
        dxi.ctypes.data,
        tan.ctypes.data,
        sc,
    )
    return dxi, tan, ns.sc.copy()


def newton_system(
    n: int,
    drive: int,
    kind: int,
    free: np.ndarray,
    block_pos: np.ndarray,
    block_comp: np.ndarray,
    axis: np.ndarray,
    scale: np.ndarray,
    scale_free: np.ndarray,
    pattern: np.ndarray | None = None,
    banded: bool = True,
) -> NewtonSystem | None:
    """A :class:`NewtonSystem` (arguments as its) for the process's driver, or None without it."""
    drv = _driver()
    if drv is None:
        return None
    return NewtonSystem(
        n, drive, kind, free, block_pos, block_comp, axis, scale, scale_free, drv, pattern=pattern, banded=banded
    )
