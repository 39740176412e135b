"""The compiled dense linear algebra of the hot path (model/linalg.py, model/lapack.py).

References: the eigenvalues of a fixed-free chain of unit springs and masses in closed form,
``lambda_j = 4 sin^2((2j - 1) pi / (2 (2n + 1)))`` (e.g. Strang, Linear Algebra and its Applications,
the second-difference matrix with one free end); linear solves against numpy.linalg.solve (LAPACK dgesv
through numpy's own wrapper: another code path to the same factorisation).
"""

from __future__ import annotations

import subprocess
import sys
import threading

import numpy as np
import pytest

from flexopt.model import lapack, linalg

pytestmark = pytest.mark.skipif(not linalg.available(), reason="the compiled drivers need a C compiler")


def _chain(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fixed-free spring-mass chain: K (second difference, last diagonal 1), M = I, exact eigenvalues."""
    K = 2 * np.eye(n) - np.eye(n, k=1) - np.eye(n, k=-1)
    K[-1, -1] = 1.0
    j = np.arange(1, n + 1)
    return K, np.eye(n), 4 * np.sin((2 * j - 1) * np.pi / (2 * (2 * n + 1))) ** 2


@pytest.mark.parametrize("n", [1, 7, 60, 120])  # 120: above the dtrsm/dsygst switch at 80
def test_chain_eigenvalues_closed_form(n: int) -> None:
    K, M, exact = _chain(n)
    k = min(6, n)
    # a non-uniform, SPD mass and a scaled stiffness: the pencil (D K D, D M D) has the same eigenvalues
    d = np.linspace(0.5, 3.0, n)
    lam, phi = linalg.lowest_pairs(d[:, None] * K * d, d[:, None] * M * d, k)
    # 1e-12: the condition of the lowest eigenvalue is lambda_max / lambda_1 ~ 4e4 at n = 120, times eps
    assert np.allclose(lam, exact[:k], rtol=1e-12, atol=0)
    Md = d[:, None] * M * d
    assert np.allclose(phi.T @ Md @ phi, np.eye(k), atol=1e-10)  # mass-normalised and M-orthogonal
    Kd = d[:, None] * K * d
    assert np.allclose(Kd @ phi, Md @ phi * lam, rtol=0, atol=1e-10 * np.abs(Kd).max())


def test_not_positive_definite_is_reported() -> None:
    K, M, _ = _chain(10)
    assert linalg.lowest_pairs(K - 0.5 * np.eye(10), M, 3) is False  # indefinite: the route through M applies
    M2 = M.copy()
    M2[3, 3] = 0.0
    assert linalg.lowest_pairs(K, M2, 3) is False  # a massless DOF


def test_solve_matches_numpy_and_reports_singular() -> None:
    rng = np.random.default_rng(1)
    A = rng.standard_normal((50, 50)) + 10 * np.eye(50)  # non-symmetric, well conditioned (cond ~ 10)
    B = np.asfortranarray(rng.standard_normal((50, 2)))
    X = np.linalg.solve(A, B)
    Xc = B.copy(order="F")
    assert linalg.solve(A.copy(), Xc) == 0
    assert np.allclose(Xc, X, rtol=0, atol=1e-13)
    S = np.ones((4, 4))
    assert linalg.solve(S, np.ones((4, 1), order="F")) > 0
    with pytest.raises(ValueError, match="Fortran-ordered"):
        linalg.solve(A.copy(), np.ones((50, 2)))  # C-ordered right-hand sides would be misread


def test_both_lapack_sources_agree() -> None:
    """numpy's ILP64 OpenBLAS and scipy's LP64 one, each through its own compiled driver."""
    tables = [t for t in (lapack._from_numpy(), lapack._from_scipy()) if t is not None]
    assert any(t.int_type == "int" for t in tables)  # scipy is a dependency: its source is always there
    K, M, exact = _chain(40)
    for t in tables:
        lam, _ = linalg.lowest_pairs(K, M, 4, driver=linalg.build(t))
        assert np.allclose(lam, exact[:4], rtol=1e-12, atol=0), t.source


def test_threads_keep_their_own_workspace() -> None:
    K, M, exact = _chain(200)
    errors: list = []

    def run() -> None:
        for _ in range(20):
            lam, _ = linalg.lowest_pairs(K, M, 3)
            if not np.allclose(lam, exact[:3], rtol=1e-12, atol=0):
                errors.append(lam)

    threads = [threading.Thread(target=run) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors


def test_curve_path_does_not_import_scipy_linalg() -> None:
    """Issue 12 item 5: importing scipy.linalg costs 0.17-0.3 s of a command-line call's start-up."""
    code = ("import sys; from flexopt.model import Analysis, template; "
            "Analysis(template('leaf-spring')).frequency_curve(); print('scipy.linalg' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
