"""The quadratic-manifold and reduced-eigenproblem methods (one-shot configurations, no Newton).

``manifold``: the configuration ``q = phi_j eta + 1/2 theta_jj eta^2`` (seed 000 eq. 7 with the 1/2) and a
full eigen solve there; ``reduced``: the same configuration, eigenproblem in the basis of the first modes,
their modal derivatives and the driving mode (Wu and Tiso 2015). Accuracy limits: see
:mod:`model.methods.taylor` and bench/bench_methods.py.
"""

from __future__ import annotations

import numpy as np

from ..assembly import State, System
from ..modal import Modes, modes_at
from .taylor import ModalDerivatives, _eq_at, _Prepared

__all__ = ["eigen_curve"]


def _manifold_state(sys: System, md: ModalDerivatives, st0: State, eta: float) -> State:
    """Configuration on the quadratic manifold ``q = phi_j eta + 1/2 theta_jj eta^2`` (eq. 7 with 1/2)."""
    return sys.update(st0, md.phi_j * eta + 0.5 * md.theta_jj * eta * eta)


def _reduced_basis(sys: System, md: ModalDerivatives, k: int) -> np.ndarray:
    """M-orthonormal basis (free DOFs, drive entry 0) of the first k modes, their theta_ij and theta_jj."""
    import scipy.linalg as sla  # lazily: 0.2-1 s to import, which the hermite path (and auto) never needs

    cols = [md.phi[:, :k], md.theta[:, :k], md.dphi[:, :k], md.theta_jj[:, None]]
    pj = md.phi_j.copy()
    pj[sys.drive] = 0.0
    cols.append(pj[:, None])
    Dv = sys.scale_free  # DOF scales: the basis is built in unit-free coordinates
    B = np.hstack(cols)[sys.free] / Dv[:, None]
    Mf = Dv[:, None] * sys.free_block(md.M) * Dv[None, :]
    Lc = np.linalg.cholesky(0.5 * (Mf + Mf.T))
    C = Lc.T @ B
    C = C / np.maximum(np.linalg.norm(C, axis=0), 1e-300)
    U, sv, _ = np.linalg.svd(C, full_matrices=False)
    U = U[:, sv > 1e-10 * sv[0]]
    Vf = Dv[:, None] * sla.solve_triangular(Lc.T, U, lower=False)
    V = np.zeros((sys.n, Vf.shape[1]))
    V[sys.free] = Vf
    return V


def eigen_curve(prep: _Prepared, eta: np.ndarray, reduced: bool, n_rep: int) -> tuple:
    """Frequencies at ``eta`` on the quadratic manifold: full (``reduced`` False) or reduced eigen solves."""
    import scipy.linalg as sla  # lazily, as in _reduced_basis

    an, md = prep.an, prep.md
    sys = an.system
    k = n_rep + 2
    V = None
    if reduced:
        if prep.basis is None:
            prep.basis = _reduced_basis(sys, md, max(2 * k, 12))
        V = prep.basis
    hz = np.empty((len(eta), n_rep))
    labels = np.empty((len(eta), n_rep), dtype=object)
    par = np.empty(len(eta))
    drive_dev = 0.0
    for p, e in enumerate(eta):
        st = _manifold_state(sys, md, prep.eq0.state, e)
        drive_dev = max(drive_dev, abs(sys.drive_value(st, near=e) - e))
        if V is not None:  # reduced
            ev = sys.evaluate(st)
            Mm = sys.mass(st)
            Kr, Mr = V.T @ ev.H @ V, V.T @ Mm @ V
            w, Y = sla.eigh(0.5 * (Kr + Kr.T), 0.5 * (Mr + Mr.T))
            modes = Modes(w[:k], V @ Y[:, :k], Mm)
        else:
            modes = modes_at(sys, _eq_at(sys, st), k, "locked")
        lab, pz = an.label_modes(modes)
        hz[p], labels[p], par[p] = modes.hz[:n_rep], np.array(lab[:n_rep], dtype=object), pz
    return hz, labels, par, drive_dev
