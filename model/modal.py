"""Linearised natural frequencies at an equilibrium, mode tracking and parasitic labels.

At a converged equilibrium the tangent stiffness ``K`` is the Hessian of the Lagrangian in the
exponential chart (material plus geometric stiffness from the internal generalised stresses, and the
multipliers' curvature for rigid deformations), and ``M`` the mass matrix at the deflected configuration.
With the drive locked, the drive DOF is removed: for a rotation drive that removes only the incremental
spin about the drive axis (delta_omega . axis = 0), with no curvature of the lock (the other incremental
rotations follow straight lines of the exponential chart). Rigid deformations are imposed on the
eigenproblem through an orthonormal null-space basis ``Z`` of their Jacobian: ``(Z^T K Z - w^2 Z^T M Z) y = 0``.

Modes are tracked between stroke points by the mass-weighted modal assurance criterion (MAC) and a
linear assignment, so curves follow modes through crossings.
"""

from __future__ import annotations

import sys
import warnings
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from . import linalg as _linalg
from .assembly import System
from .errors import FlexoptError
from .linalg import TRSM_MAX as _TRSM_MAX
from .statics import Equilibrium

_ABSTOL = 2.0 * float(np.finfo(float).tiny)

__all__ = ["Modes", "modes_at", "track", "participation", "general_pairs"]


@dataclass
class Modes:
    """Eigenpairs at one equilibrium."""

    omega2: np.ndarray  # (k,) eigenvalues [rad^2/s^2], ascending
    phi: np.ndarray  # (n, k) mass-normalised mode shapes over all DOFs (drive basis)
    M: np.ndarray  # (n, n) mass matrix used
    #: the Lanczos solve's (steps, run), when it took that route: the hint for a neighbouring solve
    #: (:func:`model.linalg.lanczos_first_check`)
    lanczos: tuple[int, int] | None = None
    #: under non-conservative loads (unsymmetric stiffness, :func:`general_pairs`): the complex eigenvalues
    #: ``omega^2`` (one of each conjugate pair, positive imaginary part, by real part): flutter. Not in
    #: ``omega2``, which holds the real eigenvalues only
    complex_omega2: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=complex))

    @property
    def hz(self) -> np.ndarray:
        """Natural frequencies [Hz] (negative eigenvalues give negative numbers: unstable)."""
        return np.sign(self.omega2) * np.sqrt(np.abs(self.omega2)) / (2 * np.pi)


def _lowest_pairs(
    K: np.ndarray, M: np.ndarray, k: int, band: tuple[np.ndarray, int] | None = None
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The ``k`` lowest eigenpairs of ``K phi = lambda M phi`` solved *through K*; ``(None, None)`` if ``K``
    is not positive definite.

    With ``band`` (the pencil's band order, :meth:`System.eigen_band`) the banded Lanczos route first
    (:func:`model.linalg.lowest_pairs_banded`, checked by a Sturm count); then the compiled dense driver
    (:func:`model.linalg.lowest_pairs`: the same algorithm in one C call, MRRR for the wanted pairs and
    extended-precision Rayleigh quotients) when it is available; otherwise, or when its LAPACK reports a
    failure, the scipy route below.

    Both matrices are first scaled symmetrically by ``D = diag(K)^(-1/2)`` (Jacobi equilibration: the
    eigenvalues are unchanged, the DOF units -- metres against radians -- drop out). With the Cholesky
    factor ``K_s = L L^T`` the pencil becomes the standard problem ``C y = mu y``, ``C = L^-1 M_s L^-T``,
    ``mu = 1 / lambda``, and the lowest ``lambda`` are the *largest* ``mu``: a symmetric eigen solver
    gives each ``mu`` to an absolute error of about ``eps mu_max`` (Parlett, The Symmetric Eigenvalue
    Problem, ch. 4), i.e. the lowest frequency to ``eps`` relative, whatever the conditioning of ``M``.
    The route through ``M`` (LAPACK dsygvx: Cholesky of ``M``) bounds the error by ``eps lambda_max``
    instead, up to 4e-4 relative for the lowest modes of finely meshed thin leaves (issue 12). Vectors:
    ``phi = D L^-T y / sqrt(mu)`` (mass-normalised).
    """
    if band is not None:  # a banded pencil: Lanczos, checked by a Sturm count (model.linalg.lanczos_pairs)
        got = _linalg.lowest_pairs_banded(K, M, k, *band)
        if got is not None:
            return got if got is not False else (None, None)
    fast = _linalg.lowest_pairs(K, M, k)
    if fast is not None:
        return fast if fast is not False else (None, None)
    from scipy.linalg import blas, lapack  # lazily: the compiled driver needs no scipy.linalg

    d = K.diagonal()
    if not (np.all(d > 0) and np.all(M.diagonal() > 0)):  # the route through M reports a singular M
        return None, None
    D = 1.0 / np.sqrt(d)
    Ks = K * D[:, None] * D[None, :]
    Ms = M * D[:, None] * D[None, :]
    L, info = lapack.dpotrf(Ks, lower=1, clean=0, overwrite_a=1)
    if info != 0:
        return None, None
    n = K.shape[0]
    if n <= _TRSM_MAX:  # two BLAS-3 triangular solves: faster than LAPACK's unblocked dsygs2 on small n
        C = blas.dtrsm(
            1.0, L, blas.dtrsm(1.0, L, Ms, side=0, lower=1, overwrite_b=1), side=1, lower=1, trans_a=1, overwrite_b=1
        )
    else:
        C, info = lapack.dsygst(Ms, L, itype=1, lower=1, overwrite_a=1)
    mu, Y, _, _, info = lapack.dsyevx(
        C, compute_v=1, range="I", il=n - k + 1, iu=n, lower=1, abstol=_ABSTOL, overwrite_a=1
    )
    if info != 0 or not np.all(mu[:k] > 0):
        return None, None
    mu, Y = mu[:k][::-1], Y[:, :k][:, ::-1]
    X, info = lapack.dtrtrs(L, Y, lower=1, trans=1)
    if info != 0:
        return None, None
    return 1.0 / mu, X * D[:, None] / np.sqrt(mu)[None, :]


def _lowest_pairs_through_m(K: np.ndarray, M: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray, int]:
    """The ``k`` lowest eigenpairs by LAPACK's dsygvx (Cholesky of ``M``): also for an indefinite ``K``.

    Called directly (scipy.linalg.eigh's checks cost a third of a small solve). Only the lower triangles
    are read, so ``K``'s round-off asymmetry is irrelevant. ``ABSTOL = 2 * underflow`` is LAPACK's
    setting for the most accurate eigenvalues.
    """
    from scipy.linalg import lapack

    w, V, _, _, info = lapack.dsygvx(K.T, M.T, itype=1, jobz="V", range="I", il=1, iu=k, uplo="L", abstol=_ABSTOL)
    return w[:k], V[:, :k], info


def _in_place(H: np.ndarray, M: np.ndarray, N: int) -> bool:
    """Whether ``H`` and ``M`` are C-ordered float64 views with row stride ``N`` (the extended numbering's
    matrices, as :meth:`System.evaluate` and :meth:`System.mass` give them): a banded pencil reads them in place."""
    return all(A.dtype == np.float64 and A.strides == (8 * N, 8) for A in (H, M))


def modes_at(sys: System, eq: Equilibrium, k: int, drive: str = "locked", near: Modes | None = None) -> Modes:
    """The ``k`` lowest eigenpairs at ``eq`` with the drive ``locked`` or ``free``. ``near``: the modes of a
    neighbouring equilibrium (the previous point of a curve), whose Lanczos step count the banded solve starts
    from (:func:`model.linalg.lanczos_first_check`; the same eigenpairs to rounding, reproducible from the
    arguments)."""
    s = sys.s
    M = sys.mass(eq.state)
    locked = drive == "locked"
    dofs = sys.free if locked else np.arange(sys.n)
    k = min(k, len(dofs))
    if k == 0:
        return Modes(np.zeros(0), np.zeros((sys.n, 0)), M)
    if sys.loads is not None and sys.loads.nonconservative:  # unsymmetric stiffness: the general eigenproblem
        K, Mr = sys.free_block(eq.ev.H, locked), sys.free_block(M, locked)
        Z = None
        if sys.n_con:
            from scipy.linalg import null_space

            Z = null_space(eq.ev.G[:, dofs])
            K, Mr = Z.T @ K @ Z, Z.T @ Mr @ Z
        wg, Vg, cw = general_pairs(K, Mr, min(k, K.shape[0]))
        phi = np.zeros((sys.n, len(wg)))
        phi[dofs] = Vg if Z is None else Z @ Vg
        return Modes(wg, phi, M, complex_omega2=cw)
    pencil = sys.banded_pencil(locked) if not sys.n_con and 2 * k < len(dofs) else None
    band: tuple[np.ndarray, int] | Literal[False] | None = None  # False: K not positive definite (route through M)
    if pencil is not None:
        if _in_place(eq.ev.H, M, sys.N):
            # the free blocks of H and M read in place, the vectors written into phi's free rows: one C call
            phi = np.zeros((sys.n, k))
            w, hint = pencil.solve(eq.ev.H, M, k, phi, pencil.at[4], hint=None if near is None else near.lanczos)
            if w is not None and w is not False:
                return Modes(w, phi, M, hint)
            band = False if w is False else None  # K not positive definite: the route through M; else dense
        else:
            band = (pencil.perm, pencil.kd)
    K = sys.free_block(eq.ev.H, locked)
    Mr = Mf = sys.free_block(M, locked)
    Z = None
    if sys.n_con:
        from scipy.linalg import null_space

        Z = null_space(eq.ev.G[:, dofs])
        K, Mr = Z.T @ K @ Z, Z.T @ Mr @ Z
        k = min(k, K.shape[0])
        if k == 0:
            return Modes(np.zeros(0), np.zeros((sys.n, 0)), M)
    w, V = (None, None) if band is False else _lowest_pairs(K, Mr, k, band)
    if w is None or V is None:  # K not positive definite (unstable) or singular: the pencil route through M
        w, V, info = _lowest_pairs_through_m(K, Mr, k)
        if info > K.shape[0]:  # LAPACK: the leading minor of order info - n of M is not positive definite
            bad = [s.dof_label(int(sys.act_full[d])) for d in dofs[np.diag(Mf) <= 0][:5]]
            raise FlexoptError(
                "the mass matrix is singular"
                + (f" (no mass on {', '.join(bad)})" if bad else "")
                + "; give every moving body mass and inertia or attach it to beams"
            )
        if info != 0:
            raise FlexoptError(
                f"the eigen solver did not converge (LAPACK dsygvx info {info}); the stiffness "
                "matrix may contain non-finite values: check the scene's dimensions"
            )
    w, V = w[:k], V[:, :k]
    phi = np.zeros((sys.n, k))
    phi[dofs] = V if Z is None else Z @ V
    return Modes(w, phi, M)


#: An eigenvalue of the general problem counts as complex when its imaginary part exceeds this fraction of its
#: modulus. A real double eigenvalue about to split into a complex pair is perturbed by rounding to about
#: ``sqrt(eps)`` (1.5e-8) relative, either way; 1e-6 is above that, and moves the located onset of flutter
#: (where the imaginary part grows as the square root of the distance to it) by about (1e-6)^2 relative.
COMPLEX_RTOL = 1e-6


def general_pairs(K: np.ndarray, M: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The ``k`` lowest real eigenpairs of ``K phi = lambda M phi`` with an unsymmetric ``K`` (non-conservative
    loads), mass-normalised (``phi^T M phi = 1``; right eigenvectors), and every complex eigenvalue (one per
    conjugate pair, ascending real part).

    Solved through ``K`` like :func:`_lowest_pairs`: ``C = K^-1 M`` (LU) has the eigenvalues ``mu = 1 /
    lambda`` (LAPACK's dgeev by scipy.linalg.eig), so the lowest ``lambda`` are the largest ``mu``, each
    accurate to about ``eps`` relative however stiff the rest; a singular ``K`` (exactly at divergence) takes
    the pencil ``(K, M)`` by QZ (scipy.linalg.eig with two matrices) instead. Real and complex are told apart
    by :data:`COMPLEX_RTOL`; negative real eigenvalues (divergence) stay in the real list, first.
    """
    import scipy.linalg as sla

    n = K.shape[0]
    if n == 0:
        return np.zeros(0), np.zeros((0, 0)), np.zeros(0, dtype=complex)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # scipy warns of an ill-conditioned K; its smallest pivot decides below
        lu, piv = sla.lu_factor(K, check_finite=False)
    pivots = np.abs(np.diag(lu))
    if np.all(np.isfinite(lu)) and pivots.min() > 1e-13 * pivots.max():
        mu, V = sla.eig(sla.lu_solve((lu, piv), M, check_finite=False), check_finite=False)
        keep = np.abs(mu) > 1e-300
        lam, V = 1.0 / mu[keep], V[:, keep]
    else:
        lam, V = sla.eig(K, M, check_finite=False)
        keep = np.isfinite(lam)
        lam, V = lam[keep], V[:, keep]
    real = np.abs(lam.imag) <= COMPLEX_RTOL * np.abs(lam)
    order = np.flatnonzero(real)[np.argsort(lam.real[real])][:k]
    w = lam.real[order]
    X = V[:, order].real
    X = X / np.sqrt(np.einsum("ik,ik->k", X, M @ X))[None, :]
    cw = lam[~real & (lam.imag > 0)]
    return w, X, cw[np.argsort(cw.real)]


def participation(sys: System, modes: Modes) -> np.ndarray | None:
    """Fraction of each mode's kinetic energy in the declared support directions (None if undeclared)."""
    P = sys.s.support_projector
    if P is None:
        return None
    phi = modes.phi
    pg = sys.support_projector() @ phi
    num = np.einsum("ik,ik->k", pg, modes.M @ pg)
    den = np.einsum("ik,ik->k", phi, modes.M @ phi)
    return np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)


def mac_matrix(prev: Modes, cur: Modes) -> np.ndarray:
    """Mass-weighted MAC of every ``prev`` mode (rows) with every ``cur`` mode (columns), with ``cur``'s mass."""
    A = prev.phi
    B = cur.phi
    MB = cur.M @ B
    num = (A.T @ MB) ** 2
    den = np.outer(np.einsum("ij,ij->j", A, cur.M @ A), np.einsum("ij,ij->j", B, MB))
    return num / np.where(den > 0, den, 1.0)


def track(prev: Modes, cur: Modes) -> np.ndarray:
    """Permutation ``p`` such that ``cur`` mode ``p[i]`` continues ``prev`` mode ``i`` (mass-weighted MAC)."""
    return assign(mac_matrix(prev, cur))


#: The margin by which a certified assignment beats every other one (in total MAC, which lies in [0, n]). Far
#: above the rounding of any exact solver on these sizes (potentials summed from n^2 steps: ~1e-13), so every
#: exact solver, scipy's included, returns the certified permutation; a closer call (a tie, or modes matched
#: equally well two ways) goes to scipy's solver, whose choice is then the one returned.
_MARGIN = 1e-9
_TIGHT = 1e-12  # rounding allowed in a certificate's reduced costs (which are 0 on the permutation, >= 0 off it)


def assign(mac: np.ndarray) -> np.ndarray:
    """The permutation of largest total MAC: ``p[i]`` is the column matched to row ``i`` (see :func:`track`).

    When each row's best column is a different column, that permutation (optimal: every term is at its
    row's maximum). Otherwise the same permutation as ``scipy.optimize.linear_sum_assignment(-mac)``,
    without importing ``scipy.optimize`` (0.15-0.8 s, a cold command-line curve's largest single cost; issue
    26 item 2) when a certificate proves it the unique optimum by :data:`_MARGIN`: potentials ``u``, ``v``
    from the shortest-augmenting-path (Hungarian) method (:func:`_hungarian`) whose reduced costs
    ``r = u_i + v_j - mac_ij`` are >= 0, 0 on the permutation, and admit no cycle of swaps among the edges
    off it with ``r < _MARGIN`` (:func:`_certified`). Every other permutation then has a total MAC lower by
    at least the margin, far above any exact solver's rounding, so scipy's solver returns the same one.
    Only when no certificate holds (a tie: modes matched equally well two ways), or when scipy.optimize
    is loaded already (its solver is faster than the Python loop), does scipy decide."""
    if mac.size == 0:
        return np.arange(mac.shape[0])
    perm = _assign_certified(mac, hungarian="scipy.optimize" not in sys.modules)
    if perm is not None:
        return perm
    from scipy.optimize import linear_sum_assignment  # lazily: scipy.optimize costs 0.15-0.8 s to import

    rows, cols = linear_sum_assignment(-mac)
    perm = np.empty(len(rows), dtype=int)
    perm[rows] = cols
    return perm


def _assign_certified(mac: np.ndarray, hungarian: bool = True) -> np.ndarray | None:
    """The largest-MAC permutation of a square ``mac`` when a certificate proves it unique by :data:`_MARGIN`
    (:func:`_certified`), else None: each row's best column when those differ, then (``hungarian``) the
    potentials of :func:`_hungarian`. The name says the second case; the first is :func:`assign`'s own rule."""
    n = mac.shape[0]
    if n != mac.shape[1]:
        return None
    best = np.argmax(mac, axis=1)
    if n == 1:
        return best
    if np.bincount(best, minlength=n).max() == 1:
        # every mode's best match is a different mode: that permutation is an assignment of largest total
        # MAC (each term is at its row's maximum); the one returned here since before the certificates (a
        # row whose maximum is tied picks its first column, as np.argmax does), so curves are unchanged
        return best
    return _certified(mac, *_hungarian(-mac)) if hungarian else None


def _certified(mac: np.ndarray, perm: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray | None:
    """``perm`` if the potentials ``u`` (rows), ``v`` (columns) prove it the unique largest-MAC permutation by
    :data:`_MARGIN` (see :func:`assign`), else None.

    The reduced costs ``r = u_i + v_j - mac_ij`` must be >= 0 everywhere and 0 on ``perm`` (then ``perm`` is
    optimal). Another permutation ``q`` loses ``sum_i r[i, q(i)]``; it loses less than the margin only if every
    edge it moves to is nearly tight (``r < _MARGIN``). Its moves form cycles of columns (row ``i`` leaves
    ``perm[i]`` for ``q[i]``, whose row leaves it for the next, ...), so such a ``q`` exists exactly when the
    graph with an arc ``perm[i] -> j`` for every nearly tight ``(i, j)`` off ``perm`` has a cycle: the
    certificate is that this graph has none (peeled to nothing by removing columns without incoming arcs)."""
    n = len(perm)
    if np.bincount(perm, minlength=n).max() != 1:
        return None
    rows = np.arange(n)
    r = u[:, None] + v[None, :] - mac
    if not (np.all(np.abs(r[rows, perm]) <= _TIGHT) and r.min() >= -_TIGHT):
        return None
    near = r < _MARGIN
    near[rows, perm] = False
    arcs = np.zeros((n, n), dtype=bool)  # arcs[a, b]: column a -> column b
    arcs[perm] = near
    alive = np.ones(n, dtype=bool)
    while alive.any():
        sources = alive & ~arcs[alive].any(axis=0)
        if not sources.any():
            return None  # a cycle of nearly tight swaps: a second assignment within the margin
        alive &= ~sources
    return perm


def _hungarian(cost: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Minimum-cost permutation of a square ``cost`` matrix with its dual potentials, by shortest augmenting
    paths (Kuhn-Munkres with potentials: rows added one at a time, a Dijkstra search over reduced costs
    per row; Burkard, Dell'Amico and Martello, Assignment Problems, 2009, sec. 4.4). Returns ``perm`` (row
    to column) and potentials of the *maximisation* of ``-cost`` (``u = -u_min``, ``v = -v_min``), the form
    :func:`_certified` checks. Every result is checked there, so this only has to be good, not trusted."""
    n = cost.shape[0]
    u = np.zeros(n + 1)
    v = np.zeros(n + 1)
    row_of = np.zeros(n + 1, dtype=int)  # row_of[j]: row (1-based) matched to column j (1-based); 0: free
    way = np.zeros(n + 1, dtype=int)
    for i in range(1, n + 1):
        row_of[0] = i
        j0 = 0
        minv = np.full(n + 1, np.inf)
        used = np.zeros(n + 1, dtype=bool)
        while True:
            used[j0] = True
            i0 = row_of[j0]
            cur = cost[i0 - 1] - u[i0] - v[1:]
            free = ~used[1:]
            better = free & (cur < minv[1:])
            minv[1:][better] = cur[better]
            way[1:][better] = j0
            cand = np.where(free, minv[1:], np.inf)
            j1 = int(np.argmin(cand)) + 1
            delta = cand[j1 - 1]
            if not np.isfinite(delta):  # non-finite costs: no certificate (scipy reports them)
                return np.zeros(n, dtype=int), np.zeros(n), np.zeros(n)
            u[row_of[used]] += delta
            v[used] -= delta
            minv[1:][free] -= delta
            j0 = j1
            if row_of[j0] == 0:
                break
        while j0:
            j1 = way[j0]
            row_of[j0] = row_of[j1]
            j0 = j1
    perm = np.empty(n, dtype=int)
    perm[row_of[1:] - 1] = np.arange(n)
    return perm, -u[1:], -v[1:]
