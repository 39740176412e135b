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
from flexopt.model.assembly import newton_system_of

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
    code = (
        "import sys; from flexopt.model import Analysis, template; "
        "Analysis(template('leaf-spring')).frequency_curve(); print('scipy.linalg' in sys.modules)"
    )
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
    assert sys_.native.assemble_call is not None  # beams only, no rigid deformations: the compiled route applies
    eq = solve_point(sys_, sys_.reference_state(), 0.0, NewtonOptions(), 0.0)
    st = sys_.update(eq.state, 0.05 * eq.tangent / max(abs(eq.tangent).max(), 1e-300) * sys_.scale)
    step = np.random.default_rng(0).standard_normal(sys_.n) * 0.1 * sys_.scale  # an update rotating every master
    fast = sys_.evaluate(st), sys_.mass(st), sys_.update(st, step), sys_.hessian_derivative(st, step)
    with sys_.native.off():
        slow = sys_.evaluate(st), sys_.mass(st), sys_.update(st, step), sys_.hessian_derivative(st, step)
    assert np.array_equal(fast[2].X, slow[2].X) and np.array_equal(fast[2].R, slow[2].R)
    assert np.array_equal(fast[3], slow[3]) and np.abs(fast[3]).max() > 0
    for field in ("g", "H", "c", "G", "e_beam", "e_truss", "chart"):
        assert np.array_equal(getattr(fast[0], field), getattr(slow[0], field)), field
    assert np.array_equal(fast[1], slow[1])
    assert np.abs(fast[0].g).max() > 0 and np.abs(fast[1]).max() > 0  # a state that loads every term


def _off_path(name: str):
    """A leaf, pivot, guide or double cross with an off-path state: a tangent step of 0.2 rad (guide: a fiftieth
    of its length) from the equilibrium at the same distance, so the residual and the increment are not small."""
    from flexopt.model import Analysis, template
    from flexopt.model.statics import NewtonOptions, predict, walk

    sys_ = Analysis(template(name)).system
    h = 0.2 if sys_.s.drive_kind == "rotation" else 0.2 * sys_.s.length_scale / 10
    seen: list = []
    assert walk(sys_, np.array([h]), NewtonOptions(), lambda e: seen.append(e)) is None
    st = predict(sys_, seen[-1], h, None)
    return sys_, st, sys_.evaluate(st), 2 * h, h


def _newton_system(sys_, banded: bool = False, pattern=None):
    """The structure's compiled Newton system as model.statics builds it, dense unless ``banded`` with a
    ``pattern``."""
    return newton_system_of(sys_, pattern, banded)


NEWTON_CASES = ["leaf-spring", "cross-spring-pivot", "parallel-leaf-spring", "double-cross-hinge"]


@pytest.mark.parametrize("name", NEWTON_CASES)
def test_compiled_newton_system_equals_numpy_route_bit_for_bit(name: str) -> None:
    """model.linalg.newton with the dense LU (the drive, the Newton system, its LU solve, the scaled increment
    and residual in C) against model.statics' numpy route on the same state: rotation drives with the reduced
    free block (leaf) and the bordered system (pivot, double cross: the driven body swings), a translation
    drive (guide). Reference: the numpy route, which the C route replaces."""
    from flexopt.model.statics import _compiled_step, _newton_step, _scaled_residual

    sys_, st, ev, s_target, h = _off_path(name)
    ns = _newton_system(sys_)
    assert ns.bands == {"reduced": None, "bordered": None}
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


def _newton_matrix(sys_, ev, st, reduced: bool) -> np.ndarray:
    """The dense matrix the compiled system solves (model.statics._newton_step's): the free block of H + chart
    (reduced), or its free rows over all DOFs with the drive gradient as the last row (bordered)."""
    A = ev.H + ev.chart
    f = sys_.free
    if reduced:
        return A[np.ix_(f, f)]
    return np.vstack([A[f], sys_.drive_gradient(st)[None, :]])


@pytest.mark.parametrize("name", NEWTON_CASES)
def test_banded_newton_solve_is_backward_stable(name: str) -> None:
    """The banded LU (model.linalg.band_order, dgbtrf) solves the same system as the dense one: its solution's
    normwise backward error against the dense matrix (Rigal and Gaches: |A x - b| / (|A| |x| + |b|)) is at the
    rounding level. Bound 1e-13: LU with partial pivoting gives about m eps times a small growth factor
    (Higham, Accuracy and Stability of Numerical Algorithms, 2002, thm. 9.5; m <= 180 here); the two routes'
    increments agree to 1e-9 of their size (the tangent's condition times eps). A band that drops entries
    fails the bound by orders of magnitude (checked below), so the bound can fail."""
    from flexopt.model.statics import _compiled_step, _newton_step

    sys_, st, ev, s_target, h = _off_path(name)
    pattern = sys_.pattern()
    ns = _newton_system(sys_, banded=True, pattern=pattern)
    dval = sys_.drive_value(st, near=h)
    dxi, tan, sc = _compiled_step(sys_, ns, ev, st, s_target, h)
    reduced = bool(sc[5])
    assert ns.bands["reduced" if reduced else "bordered"] is not None, "the templates' systems are banded"
    dxi0, _, tan0, _ = _newton_step(sys_, ev, sys_.drive_gradient(st), dval - s_target)
    A = _newton_matrix(sys_, ev, st, reduced)
    f, d = sys_.free, sys_.drive
    dd = sys_.drive_gradient(st)

    def backward(x: np.ndarray, rhs: np.ndarray) -> float:
        r = A @ x - rhs
        return float(np.abs(r).max() / (np.abs(A).sum(axis=1).max() * np.abs(x).max() + np.abs(rhs).max()))

    if reduced:  # dxi[d] is fixed by the drive row; the free part solves A x = -g_f - A_fd dxi_d
        Afd = (ev.H + ev.chart)[f, d]
        checks = [(dxi[f], -ev.g[f] - Afd * dxi[d]), (tan[f], -Afd / dd[d])]
    else:
        checks = [
            (dxi, np.concatenate([-ev.g[f], [s_target - dval]])),
            (tan, np.concatenate([np.zeros(len(f)), [1.0]])),
        ]
    for x, rhs in checks:
        assert backward(x, rhs) < 1e-13
    assert np.abs(dxi - dxi0).max() <= 1e-9 * np.abs(dxi0).max()
    assert np.abs(tan - tan0).max() <= 1e-9 * np.abs(tan0).max()

    # the check can fail: the same band without its subdiagonals (the leaf is planar, so the pattern's outer
    # diagonals hold zeros here and narrowing by one would drop nothing)
    from flexopt.model import linalg

    form = "reduced" if reduced else "bordered"
    kl, ku = ns.bands[form]
    lo = 5 + (sys_.n - 1) + 2 * len(sys_.block_pos) + (0 if reduced else 2 + sys_.n - 1)
    assert tuple(ns.ip[lo : lo + 2]) == (kl, ku)
    ns.ip[lo] = 0
    narrow, _, _ = linalg.newton(
        ns,
        ev.H,
        ev.chart,
        ev.g,
        st.R[sys_.s.drive_master] if sys_.s.drive_kind == "rotation" else None,
        h,
        s_target,
        dval,
    )
    x = narrow[f] if reduced else narrow
    assert backward(x, checks[0][1]) > 1e-8


def test_band_order_recovers_a_known_band() -> None:
    """band_order against closed forms and scipy: a chain of 6-DOF nodes (12 x 12 element blocks: half
    bandwidth 11) shuffled at random is brought back to half bandwidth 11 (no ordering of a node's 12-DOF
    cliques can do better: each element block is full); a path graph to 1; its result is a permutation whose
    stated bandwidths are those of the reordered pattern; and on the templates' tangent patterns it is no
    wider than scipy.sparse.csgraph.reverse_cuthill_mckee (the library it stands in for, see its docstring)."""
    from flexopt.model import Analysis, linalg, template
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import reverse_cuthill_mckee

    def width(P: np.ndarray, perm: np.ndarray) -> tuple[int, int]:
        r, c = np.nonzero(P[np.ix_(perm, perm)])
        return int((r - c).max()), int((c - r).max())

    rng = np.random.default_rng(0)
    nodes = 15
    P = np.zeros((6 * nodes, 6 * nodes), dtype=bool)
    for e in range(nodes - 1):
        P[6 * e : 6 * e + 12, 6 * e : 6 * e + 12] = True
    shuffle = rng.permutation(len(P))
    Q = P[np.ix_(shuffle, shuffle)]
    perm, kl, ku = linalg.band_order(Q)
    assert sorted(perm) == list(range(len(P))) and (kl, ku) == width(Q, perm) == (11, 11)
    path = np.eye(40, dtype=bool) | np.eye(40, k=1, dtype=bool) | np.eye(40, k=-1, dtype=bool)
    s = rng.permutation(40)
    assert linalg.band_order(path[np.ix_(s, s)])[1:] == (1, 1)
    for name in [
        "leaf-spring",
        "cross-spring-pivot",
        "parallel-leaf-spring",
        "three-fold-cross-hinge",
        "double-cross-hinge",
        "cartwheel-hinge",
    ]:
        sys_ = Analysis(template(name)).system
        P = sys_.pattern()[np.ix_(sys_.free, sys_.free)]
        perm, kl, ku = linalg.band_order(P)
        assert (kl, ku) == width(P, perm)
        ref = reverse_cuthill_mckee(csr_matrix(P.astype(float)), symmetric_mode=True)
        assert kl + ku <= sum(width(P, ref)), name


def test_pattern_covers_every_nonzero() -> None:
    """The bands are cut from System.pattern: every nonzero of H + chart and of the mass matrix at deflected
    states of the templates lies inside it (an entry outside would be dropped by the banded routes)."""
    for name in NEWTON_CASES + ["three-fold-cross-hinge", "cartwheel-hinge"]:
        sys_, st, ev, _, _ = _off_path(name)
        P = sys_.pattern()
        A = ev.H + ev.chart
        assert not np.any(A[~P]), name
        assert not np.any(sys_.mass(st)[~P]), name
        assert P.sum() < 0.5 * P.size  # sparse: the pattern is not everything


def test_compiled_newton_system_reports_a_singular_tangent() -> None:
    """A singular tangent (here: the stiffness of a leaf scaled to zero) raises StepFailure naming LAPACK's
    info, as the numpy route's LinAlgError does."""
    from flexopt.model import Analysis, template
    from flexopt.model.statics import StepFailure, _compiled_step

    sys_ = Analysis(template("leaf-spring")).system
    ns = sys_.native.newton_system()
    st = sys_.reference_state()
    ev = sys_.evaluate(st)
    ev.H[:] = 0.0
    ev.chart[:] = 0.0
    with pytest.raises(StepFailure, match="singular tangent .*LAPACK dgbtrf info"):
        _compiled_step(sys_, ns, ev, st, 0.1, 0.0)


@pytest.mark.parametrize("name", NEWTON_CASES)
def test_compiled_newton_loop_equals_the_python_loop_bit_for_bit(name: str) -> None:
    """model.statics' compiled Newton loop (model/native/newton_point.c: the predictor, evaluations, Newton systems, convergence
    tests and updates of a whole point in one C call) against the Python loop over the same compiled steps
    (statics.predict, System.evaluate, model.linalg.newton, System.update) along a walk of three steps from the
    reference (tangent predictor, then the cubic one): the same states, tangents, assembled numbers and iteration
    counts, to the last bit. Reference: the Python loop, which the C loop replaces."""
    from flexopt.model import Analysis, template
    from flexopt.model.statics import _point_loop, walk

    an = Analysis(template(name))
    sys_ = an.system
    assert _point_loop(sys_, an.options) is not None
    h = 0.15 if sys_.s.drive_kind == "rotation" else 0.15 * sys_.s.length_scale / 10

    def points() -> list:
        got: list = []
        assert walk(sys_, h * np.arange(1, 4), an.options, got.append) is None
        return got

    fast = points()
    saved, sys_.native.point_loop = sys_.native.point_loop, None
    try:
        slow = points()
    finally:
        sys_.native.point_loop = saved
    assert "at" in fast[-1].extra and "at" not in slow[-1].extra  # each route ran
    for a, b in zip(fast, slow):
        assert a.iterations == b.iterations and a.residual == b.residual and a.increment == b.increment
        for x, y in (
            (a.state.X, b.state.X),
            (a.state.R, b.state.R),
            (a.tangent, b.tangent),
            (a.ev.g, b.ev.g),
            (a.ev.H, b.ev.H),
            (a.ev.e_beam, b.ev.e_beam),
            (a.ev.chart, b.ev.chart),
        ):
            assert np.array_equal(x, y)
    assert np.abs(fast[-1].ev.chart).max() > 0  # a loaded state: the chart is not trivially zero


@pytest.mark.parametrize("name", NEWTON_CASES)
def test_compiled_newton_loop_fails_like_the_python_loop(name: str) -> None:
    """Newton from the reference straight to strokes it cannot reach in one solve (and with 3 iterations at most):
    the compiled loop stops with the same StepFailure message, numbers included, as the Python loop (no
    convergence within max_iter, an increment not halved in two iterations, divergence), and a state with a
    non-finite coordinate gives 'non-finite residual' in both."""
    from flexopt.model import Analysis, template
    from flexopt.model.statics import NewtonOptions, StepFailure, _point_loop, solve_point

    an = Analysis(template(name))
    sys_ = an.system
    assert _point_loop(sys_, an.options) is not None
    assert _point_loop(sys_, NewtonOptions(max_iter=100)) is None  # more iterations than the C loop keeps
    rot = sys_.s.drive_kind == "rotation"
    bad = sys_.reference_state()
    bad.X[0, 0] = np.nan
    cases = [
        (sys_.reference_state(), t, NewtonOptions(max_iter=m))
        for t in ((0.8, 1.5) if rot else (0.02, 0.2))
        for m in (3, 12)
    ] + [(bad, 0.1 if rot else 0.001, NewtonOptions())]
    messages = set()
    for start, target, opts in cases:
        out = []
        for loop in (True, False):
            saved = sys_.native.point_loop
            if not loop:
                sys_.native.point_loop = None
            try:
                eq = solve_point(sys_, start, target, opts, 0.0)
                out.append(("converged", eq.iterations, eq.state.X.tobytes()))
            except StepFailure as exc:
                out.append(("failed", str(exc)))
            finally:
                sys_.native.point_loop = saved
        assert out[0] == out[1], (target, opts.max_iter)
        messages.add(out[0][1].split(" (")[0] if out[0][0] == "failed" else "converged")
    # a non-finite state and at least one of Newton's exits (over the four templates: no convergence, not
    # converging, diverging, and convergence)
    assert "non-finite residual" in messages and len(messages) >= 2


def test_banded_pencil_in_place_equals_the_copied_free_blocks() -> None:
    """The eigen solve of a curve (a BandedPencil reading the free block of the whole H and M in place and writing
    phi's free rows) against model.linalg.lowest_pairs_banded on copies of the free blocks: the same arithmetic
    through index maps, so the same eigenvalues and vectors to the bit; the drive's row of phi stays zero."""
    from flexopt.model import Analysis, template
    from flexopt.model.statics import walk

    an = Analysis(template("cross-spring-pivot"))
    sys_ = an.system
    got: list = []
    assert walk(sys_, np.array([0.5]), an.options, got.append) is None
    eq = got[-1]
    M = sys_.mass(eq.state)
    perm, kd = sys_.eigen_band(True)
    pencil = linalg.BandedPencil(sys_.free, sys_.N, perm, kd)
    phi = np.zeros((sys_.n, 8))
    lam, _ = pencil.solve(eq.ev.H, M, 8, phi, pencil.at[4])
    lam0, X0 = linalg.lowest_pairs_banded(sys_.free_block(eq.ev.H), sys_.free_block(M), 8, perm, kd)
    assert np.array_equal(lam, lam0) and np.array_equal(phi[sys_.free], X0) and not phi[sys_.drive].any()


def test_a_curve_is_reproducible_to_the_bit() -> None:
    """The eigen solves of a curve start from the previous point's Lanczos step count (model.linalg
    lanczos_first_check), which moves where a solve stops and so its last bits: that count is carried by the
    modes passed in, not kept by the structure, so the same curve computed again on the same Analysis, after
    other solves, is the same to the bit."""
    from flexopt.model import Analysis, template

    an = Analysis(template("cross-spring-pivot"))
    first = an.frequency_curve()
    an.frequency_curve(np.linspace(0.0, 20.0, 5))  # other solves in between
    again = an.frequency_curve()
    assert np.array_equal(first.modes_hz, again.modes_hz) and np.array_equal(first.parasitic_hz, again.parasitic_hz)


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
print(json.dumps({"off": [s.native.assemble_call is None, s.native.update_call is None,
                          s.native.newton_system() is None],
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


LANCZOS_CASES = [
    ("leaf-spring", {}),
    ("leaf-spring", {"segments": 40}),
    ("cross-spring-pivot", {}),
    ("parallel-leaf-spring", {}),
    ("three-fold-cross-hinge", {}),
    ("double-cross-hinge", {}),
    ("cartwheel-hinge", {"segments": 8}),
]  # the cartwheel's former default mesh


@pytest.mark.parametrize("name,params", LANCZOS_CASES)
def test_lanczos_pairs_equal_the_dense_solve(name: str, params: dict) -> None:
    """The banded Lanczos route (model.linalg.lowest_pairs_banded) against the dense one (reduction to
    tridiagonal form, MRRR: an independent algorithm on the same pencil) at stroke 0 and at the stroke's end,
    where the three-fold cross has degenerate pairs and the leaves are stiffened most. Eigenvalues to 3e-10:
    both are Rayleigh quotients in extended precision of their vectors, and against the extended-precision
    inverse iteration of tests/test_eigen_accuracy.py each route errs by up to about 1e-10 on the 40-element
    leaf at 45 deg (measured: Lanczos 1.1e-10, dense 7.9e-11; they differ by 5.7e-11 there) and by up to
    3.9e-10 on the 64-segment pivot (Lanczos 1.6e-10, dense 3.9e-10). Vectors: each dense mode lies in the
    span of the Lanczos modes of the same eigenvalue cluster (relative gap < 1e-6) to 1e-8, mass-normalised."""
    from flexopt.model import Analysis, linalg, template

    an = Analysis(template(name, **params))
    sys_ = an.system
    band = sys_.eigen_band(True)
    assert band is not None, "the templates' pencils are banded"
    k = an.structure.scene.modes + 2
    pts: dict = {}
    end = an.scene.stroke.values()[-1]
    an.frequency_curve(np.array([0.0, end]), visit=lambda eq, m, lab: pts.setdefault(eq.stroke, eq), mesh_error=False)
    assert len(pts) == 2
    for eq in pts.values():
        K = sys_.free_block(eq.ev.H)
        M = sys_.free_block(sys_.mass(eq.state))
        got = linalg.lowest_pairs_banded(K, M, k, *band)
        assert got is not None and got is not False, "Lanczos converged and its Sturm count agreed"
        lam, X = got
        lam0, X0 = linalg.lowest_pairs(K, M, k)
        np.testing.assert_allclose(lam, lam0, rtol=3e-10, atol=0)
        np.testing.assert_allclose(np.einsum("ik,ij,jk->k", X, M, X), 1.0, rtol=1e-10)
        for j in range(k):
            cluster = np.flatnonzero(np.abs(lam0 / lam0[j] - 1) < 1e-6)
            B = X[:, cluster]
            coef = np.linalg.solve(B.T @ M @ B, B.T @ M @ X0[:, j])
            r = X0[:, j] - B @ coef
            assert np.sqrt(abs(r @ M @ r)) < 1e-8, (j, cluster)


def test_lanczos_finds_an_exactly_double_eigenvalue() -> None:
    """Two uncoupled copies of a leaf's pencil (block diagonal: every eigenvalue exactly double): a single-vector
    Krylov space holds only one copy of each in exact arithmetic, so Lanczos either finds the second copies
    from rounding or its Sturm count sends the solve to the dense route; either way the result is the dense
    one (here the k lowest are 4 distinct double eigenvalues)."""
    from flexopt.model import Analysis, linalg, template

    an = Analysis(template("leaf-spring"))
    sys_ = an.system
    from flexopt.model.statics import solve_point

    eq = solve_point(sys_, sys_.reference_state(), 0.0, an.options, 0.0)
    K1 = sys_.free_block(eq.ev.H)
    M1 = sys_.free_block(sys_.mass(eq.state))
    n = len(K1)
    Z = np.zeros((n, n))
    K = np.block([[K1, Z], [Z, K1]])
    M = np.block([[M1, Z], [Z, M1]])
    perm1, kd = sys_.eigen_band(True)
    perm = np.concatenate([perm1, perm1 + n]).astype(np.int64)
    k = 8
    lam0, _ = linalg.lowest_pairs(K, M, k)
    assert np.allclose(lam0[0::2], lam0[1::2], rtol=1e-12)  # the pairs are double
    got = linalg.lowest_pairs_banded(K, M, k, perm, kd)
    if got is None:  # the Sturm count caught a missing copy: the dense route answers (modal._lowest_pairs)
        from flexopt.model.modal import _lowest_pairs

        got = _lowest_pairs(K, M, k, (perm, kd))
    np.testing.assert_allclose(got[0], lam0, rtol=1e-11)


def test_sturm_count_equals_the_number_of_eigenvalues_below_the_shift() -> None:
    """The Sturm count of the Lanczos route (C band_inertia: LDL^T of A - sigma B without pivoting, Bathe 1996
    sec. 11.4.3) against the eigenvalues of the pencil counted directly (numpy eigvalsh of the symmetrically
    reduced problem), for shifts between and just above the lowest eigenvalues of a pivot's pencil."""
    import ctypes

    from flexopt.model import Analysis, linalg, template
    from flexopt.model.statics import solve_point

    an = Analysis(template("cross-spring-pivot"))
    sys_ = an.system
    eq = solve_point(sys_, sys_.reference_state(), 0.0, an.options, 0.0)
    K = sys_.free_block(eq.ev.H)
    M = sys_.free_block(sys_.mass(eq.state))
    perm, kd = sys_.eigen_band(True)
    n = len(K)
    Kp, Mp = K[np.ix_(perm, perm)], M[np.ix_(perm, perm)]
    ld = kd + 1

    def band(A: np.ndarray) -> np.ndarray:
        B = np.zeros((n, ld))  # column j's ld entries contiguous: B[j, kd + i - j] = A[i, j]
        for j in range(n):
            for i in range(max(0, j - kd), j + 1):
                B[j, kd + i - j] = A[i, j]
        return B

    Kb, Mb, W = band(Kp), band(Mp), np.empty((n, ld))
    L = np.linalg.cholesky(M)
    lam = np.sort(np.linalg.eigvalsh(np.linalg.solve(L, np.linalg.solve(L, K).T)))
    lib = linalg._driver()[0]
    lib.sturm_count.restype = ctypes.c_longlong
    lib.sturm_count.argtypes = [
        ctypes.c_longlong,
        ctypes.c_longlong,
        ctypes.c_void_p,
        ctypes.c_void_p,
        ctypes.c_double,
        ctypes.c_void_p,
    ]
    for j in range(8):
        for sigma in (lam[j] * (1 + 1e-7), 0.5 * (lam[j] + lam[j + 1])):
            count = lib.sturm_count(n, kd, Kb.ctypes.data, Mb.ctypes.data, sigma, W.ctypes.data)
            assert count == int(np.sum(lam < sigma)), (j, sigma)
    # and the route obeys it: a shift below the k-th eigenvalue counts k - 1, so the solve is declined (None:
    # the caller's dense route answers)
    assert linalg.lowest_pairs_banded(K, M, 8, perm, kd) is not None
    saved = linalg.STURM_GAP
    try:
        linalg.STURM_GAP = -1e-3
        assert linalg.lowest_pairs_banded(K, M, 8, perm, kd) is None
    finally:
        linalg.STURM_GAP = saved
