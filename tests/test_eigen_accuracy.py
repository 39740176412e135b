"""Accuracy of the eigen solve (issue 12 item 2) against an independent, higher-precision reference.

Reference: shifted inverse iteration on the *same* float64 matrices with every residual and Rayleigh
quotient evaluated in extended precision (``numpy.longdouble``) and the shifted solves refined iteratively
(Wilkinson's iterative refinement). It converges to the eigenvalue of the float64 matrices themselves, so
it measures only the error the eigen solver adds. The solver under test factorises through ``K`` and
takes each eigenvalue as the extended-precision Rayleigh quotient of its vector (model/linalg.py: on these
banded meshes the Lanczos route, checked against the dense one in tests/test_linalg.py); the
former route through ``M`` (LAPACK dsygvx) erred by up to 3e-4, the float64 route through ``K`` without the
Rayleigh quotient (the scipy route of model/modal.py ``_lowest_pairs``, taken without a C compiler) by up
to 4.4e-8.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla
from flexopt.model import Analysis, linalg, template

LD = np.longdouble


def _refined(K: np.ndarray, M: np.ndarray, lam: float, x: np.ndarray, its: int = 3) -> float:
    """Shifted inverse iteration with extended-precision residuals and Rayleigh quotients from (lam, x)."""
    Kl, Ml = K.astype(LD), M.astype(LD)
    lam_l = LD(lam)
    for _ in range(its):
        sigma = LD(float(lam_l) * (1.0 + 1e-9))  # a shift off the eigenvalue: the LU stays regular
        lu = sla.lu_factor(K - float(sigma) * M)
        b = Ml @ x.astype(LD)
        y = sla.lu_solve(lu, b.astype(float)).astype(LD)
        for _ in range(3):
            y = y + sla.lu_solve(lu, (b - (Kl - sigma * Ml) @ y).astype(float)).astype(LD)
        x = y / np.sqrt(y @ (Ml @ y))
        lam_l = (x @ (Kl @ x)) / (x @ (Ml @ x))
    return lam_l


def _errors(name: str, segments: int, n_modes: int = 2) -> tuple[dict, dict]:
    """Relative errors of the lowest modes at +-45 deg and the eigenvalues there."""
    an = Analysis(template(name, segments=segments))
    s = an.system
    seen: dict = {}
    an.frequency_curve(np.array([-45.0, 45.0]), visit=lambda eq, m, lab: seen.setdefault(eq.stroke, (eq, m)))
    err, lam = {}, {}
    for stroke, (eq, m) in seen.items():
        K = np.tril(eq.ev.H[s.ix_free]) + np.tril(eq.ev.H[s.ix_free], -1).T  # the triangle the solver reads
        M = np.tril(m.M[s.ix_free]) + np.tril(m.M[s.ix_free], -1).T
        for i in np.argsort(m.omega2)[:n_modes]:
            ref = _refined(K, M, float(m.omega2[i]), m.phi[s.free][:, i])
            err[(stroke, int(i))] = float(abs(m.omega2[i] / ref - 1))
            lam[(stroke, int(i))] = float(m.omega2[i])
    return err, lam


needs_driver = pytest.mark.skipif(not linalg.available(), reason="the compiled eigen driver needs a C compiler")


@needs_driver
def test_leaf_eigenvalues_match_extended_precision_reference() -> None:
    err, _ = _errors("leaf-spring", 40, n_modes=8)
    # every tracked mode, 1e-9: measured 1.1e-10 by the banded Lanczos route the curve takes (7.9e-11 by the
    # dense route on this machine; both through _errors, stop 14; an earlier session's figure for the dense
    # route was 2.0e-11, mode 2 at 45 deg); the float64 route through K
    # erred by 2.4e-8 on that mode and the dsygvx route by 2.7e-8 on mode 1. (On the 10-element leaf at
    # 45 deg an mpmath solve at 40 digits gave 8.6e-12 through K and 9.8e-10 through M for mode 1.)
    assert max(err.values()) < 1e-9, err


@pytest.mark.slow
@needs_driver
def test_fine_mesh_pivot_eigenvalues_accurate_and_mirror_symmetric() -> None:
    err, lam = _errors("cross-spring-pivot", 64, n_modes=3)
    # issue 12 item 2: 1e-8 at every mesh. dsygvx (Cholesky of the badly scaled M) erred by 2.4e-4 and
    # 3.2e-4 here; the float64 route through K by 4.4e-8 (cancellation in K x: the float64 Rayleigh
    # quotient of the converged vector itself errs by 4e-8); with the extended-precision Rayleigh quotient
    # measured 3.0e-10 (dense route); 1.6e-10 by the banded Lanczos route the curve now takes.
    assert max(err.values()) < 1e-8, err
    a = min(v for (s, _), v in lam.items() if s < 0)  # the lowest mode at -45 and at +45 deg
    b = min(v for (s, _), v in lam.items() if s > 0)
    # mirror-symmetric pivot: +45 and -45 deg agree up to the equilibria's Newton tolerance (the references
    # at +-45 differ by 2.2e-8); dsygvx's values differed by 2.1e-4
    assert abs(a / b - 1) < 1e-7
