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


@pytest.mark.parametrize("name", ["leaf-spring", "cross-spring-pivot", "three-fold-cross-hinge", "double-cross-hinge"])
def test_compiled_assembly_equals_numpy_route_bit_for_bit(name: str) -> None:
    """model/assembly.py's one-call evaluate, mass, Hessian derivative (gather, kernel, scatter in C) and update
    against the numpy route
    (gather by fancy indexing, the same kernel through its batch entry, numpy.bincount): the same sums in
    the same order, so equal to the last bit, at a deflected equilibrium with rotated offset nodes (the
    hinges' bodies). Reference: the numpy route of the same class, which the C route replaces."""
    from flexopt.model import Analysis, template
    from flexopt.model.statics import NewtonOptions, solve_point

    sys_ = Analysis(template(name)).system
    assert sys_._fast is not None  # beams only, no rigid deformations: the compiled route applies
    eq = solve_point(sys_, sys_.reference_state(), 0.0, NewtonOptions(), 0.0)
    st = sys_.update(eq.state, 0.05 * eq.tangent / max(abs(eq.tangent).max(), 1e-300) * sys_.scale)
    step = np.random.default_rng(0).standard_normal(sys_.n) * 0.1 * sys_.scale  # an update rotating every master
    fast = sys_.evaluate(st), sys_.mass(st), sys_.update(st, step), sys_.hessian_derivative(st, step)
    saved = sys_._fast, sys_._fast_update
    sys_._fast = sys_._fast_update = None
    try:
        slow = sys_.evaluate(st), sys_.mass(st), sys_.update(st, step), sys_.hessian_derivative(st, step)
    finally:
        sys_._fast, sys_._fast_update = saved
    assert np.array_equal(fast[2].X, slow[2].X) and np.array_equal(fast[2].R, slow[2].R)
    assert np.array_equal(fast[3], slow[3]) and np.abs(fast[3]).max() > 0
    for field in ("g", "H", "c", "G", "e_beam", "e_truss", "chart"):
        assert np.array_equal(getattr(fast[0], field), getattr(slow[0], field)), field
    assert np.array_equal(fast[1], slow[1])
    assert np.abs(fast[0].g).max() > 0 and np.abs(fast[1]).max() > 0  # a state that loads every term


@pytest.mark.parametrize("name", ["leaf-spring", "cross-spring-pivot", "parallel-leaf-spring", "double-cross-hinge"])
def test_compiled_newton_system_equals_numpy_route_bit_for_bit(name: str) -> None:
    """model.linalg.newton (the drive, the Newton system, its LU solve, the scaled increment and residual in
    C) against model.statics' numpy route on the same state: rotation drives with the reduced free block
    (leaf) and the bordered system (pivot, double cross: the driven body swings), a translation drive
    (guide). The state is off the path (a predictor), so the residual and the increment are not small.
    Reference: the numpy route, which the C route replaces."""
    from flexopt.model import Analysis, template
    from flexopt.model.statics import (NewtonOptions, _compiled_step, _compiled_system, _newton_step,
                                       _scaled_residual, predict, walk)

    sys_ = Analysis(template(name)).system
    ns = _compiled_system(sys_)
    assert ns is not None
    h = 0.2 if sys_.s.drive_kind == "rotation" else 0.2 * sys_.s.length_scale / 10
    seen: list = []
    assert walk(sys_, np.array([h]), NewtonOptions(), lambda e: seen.append(e)) is None
    eq = seen[-1]
    s_target = 2 * h
    st = predict(sys_, eq, h, None)  # a tangent step from a deflected equilibrium
    ev = sys_.evaluate(st)
    dxi, tan, sc = _compiled_step(sys_, ns, ev, st, s_target, h)
    dval = sys_.drive_value(st, near=h)
    dxi0, _, tan0, _ = _newton_step(sys_, ev, sys_.drive_gradient(st), dval - s_target)
    assert np.array_equal(dxi, dxi0) and np.array_equal(tan, tan0)
    assert sc[0] == dval
    assert sc[1] == float(np.max(np.abs(dxi0 / sys_.scale)))
    assert sc[2] == _scaled_residual(sys_, ev, dval, s_target)
    assert sc[1] > 1e-6 and sc[2] > 1e-6  # off the path: the test compares real work
    # the path taken: the free block where the drive gradient is the drive DOF alone, else the bordered system
    assert sc[5] == (0.0 if name in ("cross-spring-pivot", "double-cross-hinge") else 1.0)


def test_compiled_newton_system_reports_a_singular_tangent() -> None:
    """A singular tangent (here: the stiffness of a leaf scaled to zero) raises StepFailure naming LAPACK's
    info, as the numpy route's LinAlgError does."""
    from flexopt.model import Analysis, template
    from flexopt.model.statics import StepFailure, _compiled_step, _compiled_system

    sys_ = Analysis(template("leaf-spring")).system
    ns = _compiled_system(sys_)
    st = sys_.reference_state()
    ev = sys_.evaluate(st)
    ev.H[:] = 0.0
    ev.chart[:] = 0.0
    with pytest.raises(StepFailure, match="singular tangent .*LAPACK dgesv info"):
        _compiled_step(sys_, ns, ev, st, 0.1, 0.0)


def test_without_a_c_compiler_the_numpy_routes_give_the_same_curve() -> None:
    """No C compiler (kernels._compiler returns None, in a fresh process): the kernels run in CasADi's virtual
    machine with a KernelPerformanceWarning, the compiled per-point routes are off, and the curve agrees with
    the compiled one. Tolerance 1e-8: the fallback's eigen solve goes through scipy's LAPACK wrappers without
    the extended-precision Rayleigh quotient (about 1e-10 apart on this pivot)."""
    code = """
import json, warnings, numpy as np
import flexopt.model.kernels as K
K._compiler = lambda: None
from flexopt.model import Analysis, template
with warnings.catch_warnings(record=True) as w:
    warnings.simplefilter("always")
    an = Analysis(template("cross-spring-pivot"))
    c = an.frequency_curve(np.linspace(-45, 45, 7))
s = an.system
print(json.dumps({"off": [s._fast is None, s._fast_update is None, s._newton_system is None],
                  "warned": any(type(x.message).__name__ == "KernelPerformanceWarning" for x in w),
                  "hz": c.parasitic_hz.tolist()}))
"""
    import json

    from flexopt.model import Analysis, template

    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    res = json.loads(out.stdout.strip().splitlines()[-1])
    assert res["off"] == [True, True, True] and res["warned"]
    ref = Analysis(template("cross-spring-pivot")).frequency_curve(np.linspace(-45, 45, 7)).parasitic_hz
    np.testing.assert_allclose(res["hz"], ref, rtol=1e-8)
