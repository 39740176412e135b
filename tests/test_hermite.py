"""The ``hermite`` and ``auto`` methods (model/methods/hermite.py, model/methods/auto.py) against the exact
method, the independent reference here: every hermite number comes from exact samples plus interpolation,
so the exact curve at every point is what it must reproduce."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from flexopt.model import Analysis, template
from flexopt.model.errors import FlexoptError
from flexopt.model.methods import frequency_curve
from flexopt.model.methods.hermite import stroke_slopes
from flexopt.model.methods.taylor import mass_derivatives, mass_slope, projected_mass_slope

from .helpers import HINGES, coarse  # the former default meshes: hermite against exact on one mesh


@pytest.fixture(scope="module")
def exact() -> dict:
    out = {}
    for name in HINGES:
        an = Analysis(template(name, **coarse(name)))
        out[name] = (an, an.frequency_curve())
    return out


@pytest.mark.parametrize(
    "name,stroke", [("leaf-spring", 20.0), ("cross-spring-pivot", 30.0), ("parallel-leaf-spring", 0.004)]
)
def test_stroke_slopes_match_central_differences_of_exact_eigenvalues(name: str, stroke: float) -> None:
    """d lambda/ds from Nelson's formula with exact dK/ds and dM/ds against a central difference of the exact
    eigenvalues (step 1e-3 rad or 1e-5 m; its truncation error measured below 1e-4 relative)."""
    an = Analysis(template(name, **coarse(name)))
    rot = an.scene.stroke.kind == "rotation"
    h_user = float(np.degrees(1e-3)) if rot else 1e-5
    seen: dict = {}
    an.frequency_curve(
        np.array([stroke - h_user, stroke, stroke + h_user]),
        visit=lambda eq, m, lab: seen.setdefault(round(float(eq.stroke), 12), (eq, m)),
    )
    keys = sorted(seen)
    fd = (seen[keys[2]][1].omega2 - seen[keys[0]][1].omega2) / (keys[2] - keys[0])
    eq, modes = seen[keys[1]]
    got = stroke_slopes(an, eq, modes)
    np.testing.assert_allclose(got[:6], fd[:6], rtol=1e-3, atol=1e-6 * np.abs(fd).max())


@pytest.mark.parametrize("name", ["leaf-spring", "cross-spring-pivot", "cartwheel-hinge"])
def test_mass_slope_matches_the_five_point_quartic_and_central_differences(name: str) -> None:
    """dM/ds from two mass evaluations (mass_slope) against (a) mass_derivatives' M1 (the quartic through
    five evaluations along the second-order rotation path: the same derivative by another route, agreement
    to rounding, 1e-11 of |M|) and (b) a central difference of the mass along the exact rotation path
    ``expm(eta [t]) R0`` (step 1e-4: truncation ~ 1e-8 relative, hence 1e-6 of |M1|)."""
    from flexopt.model.assembly import State
    from flexopt.model.rotations import skew
    from scipy.linalg import expm

    an = Analysis(template(name, **coarse(name)))
    sys = an.system
    seen: dict = {}
    an.frequency_curve(np.array([30.0]), visit=lambda eq, m, lab: seen.setdefault("eq", eq))
    eq = seen["eq"]
    t = np.asarray(eq.tangent, dtype=float)
    got = mass_slope(sys, eq.state, t)
    quartic, _ = mass_derivatives(sys, eq.state, t, np.zeros(sys.n))
    M = sys.mass(eq.state)
    np.testing.assert_allclose(got, quartic, rtol=0, atol=1e-11 * np.abs(M).max())
    rot = sys.to_global(t).reshape(-1, 6)[:, 3:]
    h = 1e-4

    def mass_at(eta: float) -> np.ndarray:
        R = np.array([expm(eta * skew(w)) for w in rot]) @ eq.state.R
        return sys.mass(State(eq.state.X, R, eq.state.lam))

    fd = (mass_at(h) - mass_at(-h)) / (2 * h)
    assert np.abs(got).max() > 1e-6 * np.abs(M).max(), "the mass does change along the stroke here"
    np.testing.assert_allclose(got, fd, rtol=0, atol=1e-6 * np.abs(got).max())
    # the projection the stroke slopes use (projected_mass_slope: the two masses projected on the modes before
    # their difference) against P^T M1 P of the matrix above: the same numbers up to the order of the sums
    # (rounding of |P^T M P| ~ 1 for mass-normalised modes, hence 1e-12 of the largest entry of P^T |M| P)
    P = seen_modes(an, eq)
    proj = projected_mass_slope(sys, eq.state, t, P)
    scale = np.abs(P).T @ np.abs(M) @ np.abs(P)
    np.testing.assert_allclose(proj, P.T @ got @ P, rtol=0, atol=1e-12 * scale.max())


def seen_modes(an: Analysis, eq) -> np.ndarray:  # noqa: ANN001 - an Equilibrium
    """The tracked mode shapes at ``eq`` (the scene's modes + 2, drive locked)."""
    from flexopt.model.modal import modes_at

    return modes_at(an.system, eq, an.scene.modes + 2, an.scene.stroke.drive).phi


@pytest.mark.parametrize("name", HINGES)
def test_hermite_within_one_percent_of_exact_over_the_whole_stroke(exact: dict, name: str) -> None:
    """Issue 12 target: the first parasitic frequency within 1 % of exact at all 91 points, with fewer exact
    eigen solves than a fifth of the exact curve's, and an estimate that does not understate the error."""
    an, ex = exact[name]
    c = frequency_curve(an, "hermite", tolerance=0.01)
    assert c.method == "hermite" and c.solver["converged"]
    err = float(np.max(np.abs(c.parasitic_hz / ex.parasitic_hz - 1)))
    assert err <= 0.01, f"{name}: hermite error {err:.3g}"
    assert c.solver["samples"] <= len(ex.stroke) / 4
    assert np.all(
        c.modes_hz[np.isclose(c.stroke, 0.0)] == pytest.approx(ex.modes_hz[np.isclose(ex.stroke, 0.0)], rel=1e-12)
    ), "exact at the samples"


def test_auto_takes_hermite_on_long_curves_and_exact_on_short_ones(exact: dict) -> None:
    an, ex = exact["cross-spring-pivot"]
    c = frequency_curve(an, "auto", tolerance=0.01)
    assert c.method == "hermite" and c.solver["auto_method"] == "hermite"
    assert c.solver["auto_estimate"] <= 0.01 and c.solver["seconds"] > 0
    assert np.max(np.abs(c.parasitic_hz / ex.parasitic_hz - 1)) <= 0.01
    short = frequency_curve(an, "auto", tolerance=0.01, stroke=np.linspace(-45, 45, 11))
    assert short.method == "exact" and short.solver["auto_method"] == "exact"
    tight = frequency_curve(an, "auto", tolerance=1e-5)  # below AUTO_MIN_TOLERANCE: exact, and it says why
    assert tight.method == "exact" and "below" in tight.solver["auto_rejected"]
    np.testing.assert_array_equal(tight.parasitic_hz, ex.parasitic_hz)


@pytest.mark.parametrize("name", ["wire-guide-5", "wire-guide-parallel"])
def test_drive_free_wire_guides_refuse_locked_methods_and_auto_and_hermite_work(name: str) -> None:
    """Service audit: these scenes with method reduced/manifold/auto crashed with a (5,) to (6,) broadcast.
    Their eigen analysis keeps the drive free, which the Taylor/manifold methods (drive locked) cannot
    answer: they now refuse in one line naming the field; auto and hermite match exact."""
    an = Analysis(template(name, **coarse(name)))
    ex = an.frequency_curve()
    for m in ("reduced", "manifold", "fd2"):
        with pytest.raises(FlexoptError, match="stroke.drive"):
            frequency_curve(an, m)
    for m in ("auto", "hermite"):
        c = frequency_curve(an, m)
        assert c.modes_hz.shape == ex.modes_hz.shape
        assert np.max(np.abs(c.parasitic_hz / ex.parasitic_hz - 1)) <= 0.01, m


class _FakeSide:
    """The data ``_error`` reads from a side: two samples, three tracked branches (mu = 1 / omega^2)."""

    def __init__(self, hz0, hz1, slope_hz0, slope_hz1, mac, macs=None):
        w0, w1 = 2 * np.pi * np.asarray(hz0, float), 2 * np.pi * np.asarray(hz1, float)
        # d mu / ds from d f / ds: mu = (2 pi f)^-2, so mu' = -2 mu f' / f
        m0, m1 = w0**-2.0, w1**-2.0
        self.lam = np.array([m0, m1])
        self.slope = np.array(
            [-2 * m0 * np.asarray(slope_hz0) / np.asarray(hz0), -2 * m1 * np.asarray(slope_hz1) / np.asarray(hz1)]
        )
        self.mac = [np.asarray(mac, float)]
        # the MAC matrix of the branches at the two ends (by default each branch matched only with itself)
        self.macs = [np.diag(np.asarray(mac, float)) if macs is None else np.asarray(macs, float)]
        self.labels = [["parasitic"] * 3, ["parasitic"] * 3]
        self.samples = [SimpleNamespace(filled=False), SimpleNamespace(filled=False)]

    def strokes(self):
        return np.array([0.0, 0.1])


def test_crossing_check_refines_only_where_an_uncertain_branch_can_reach_the_lowest() -> None:
    """model.methods.hermite._error on hand-made data (frequencies linear in the stroke, so the estimator
    itself reads almost zero and only the crossing check can return inf): (a) the lowest branch's own
    match uncertain -> inf; (b) two uncertain branches far above the lowest (1.5x, the pivot at stroke 0)
    -> finite; (c) the same two, one falling fast enough that a pairing passes within 10 % of the lowest
    -> inf."""
    from flexopt.model.methods.hermite import _error

    flat = dict(slope_hz0=[0.0, 0.0, 0.0], slope_hz1=[0.0, 0.0, 0.0])
    a = _FakeSide([100.0, 150.0, 151.0], [100.0, 150.0, 151.0], mac=[0.5, 1.0, 1.0], **flat)
    assert _error(a, 0) == float("inf")
    b = _FakeSide([100.0, 150.0, 151.0], [100.0, 150.0, 151.0], mac=[1.0, 0.3, 0.3], **flat)
    assert _error(b, 0) < 1e-6
    # branch 2 leaves 151 Hz falling at 3000 Hz per unit stroke and reaches 130 Hz rising at 1500: its cubic
    # (in mu) dips to 105 Hz inside the interval, within 10 % of the lowest (100 Hz), while its end values
    # stay 1.3 to 1.5 times above it; with slopes of 2500 and 1250 it dips to 109 Hz (also caught), with
    # 2000 and 1000 to 113 Hz (not: clear of the 10 % margin)
    c = _FakeSide(
        [100.0, 150.0, 151.0],
        [100.0, 150.0, 130.0],
        slope_hz0=[0.0, 0.0, -3000.0],
        slope_hz1=[0.0, 0.0, 1500.0],
        mac=[1.0, 0.3, 0.3],
    )
    assert _error(c, 0) == float("inf")
    c.mac = [np.ones(3)]  # the same branches with a certain match: no crossing check, a finite estimate
    assert np.isfinite(_error(c, 0))


def test_the_pair_form_follows_a_veering_that_the_single_branches_cut() -> None:
    """Two modes veering between two samples: the compliance ``C(s) = [[c1 + g s, c], [c, c2]]`` (mu-space,
    M = I, a third mode apart), whose eigenvalues mu_1,2 and slopes ``phi^T C' phi`` (Hellmann-Feynman) are
    the closed-form data at the ends. Each shape's best match at the other end is 31 degrees away (MAC 0.74),
    so single branches are uncertain and :func:`_errors` takes the pair form, which is exact here (its
    T = mu_1 + mu_2 is linear and D = (mu_1 - mu_2)^2 quadratic in s; closed-form eigenvalues at 15 interior
    points agree to 1e-12). The single branches, interpolated one by one, miss the veering by 7.2 %."""
    from flexopt.model.methods import hermite as H

    c1, g, c2, c = 1.0e-6, 2.0e-5, 2.0e-6, 3.0e-7
    C1 = np.diag([g, 0.0, 0.0])

    def at(s):  # eigenpairs of the 3 x 3 compliance (third mode decoupled), largest mu (lowest frequency) first
        C = np.array([[c1 + g * s, c, 0.0], [c, c2, 0.0], [0.0, 0.0, 1.0e-7]])
        w, V = np.linalg.eigh(C)
        return w[::-1], V[:, ::-1]

    (w0, V0), (w1, V1) = at(0.0), at(0.1)
    macs = (V0.T @ V1) ** 2  # (branch at 0, mode at 0.1)
    perm = macs.argmax(axis=1)  # each branch's best match at 0.1: the shapes' tracking
    assert sorted(perm) == [0, 1, 2] and perm[0] == 1  # the lowest branch at 0 continues as the second at 0.1
    hz = lambda w: 1.0 / np.sqrt(w) / (2 * np.pi)  # noqa: E731
    slope = lambda w, V: np.einsum("ik,ij,jk->k", V, C1, V)  # noqa: E731 - d mu / ds of each mode
    side = _FakeSide(hz(w0), hz(w1[perm]), [0.0] * 3, [0.0] * 3, mac=np.diag(macs[:, perm]), macs=macs[:, perm])
    side.slope = np.array([slope(w0, V0), slope(w1, V1)[perm]])  # mu-slopes directly
    assert np.all(np.diag(macs[:, perm])[:2] < H.MAC_MIN)
    est = H._errors(side)
    assert side.pairs[1][0] and np.isfinite(est[0])
    s = np.linspace(0.0, 0.1, 17)[1:-1]
    mu = H._Side.evaluate(side, np.zeros(len(s), dtype=int), s[:, None])[:, 0, :]
    true = np.array([at(x)[0][0] for x in s])  # the largest mu: the lowest frequency
    assert np.max(np.abs(mu.max(axis=1) / true - 1)) < 1e-12
    single = H._interpolate(
        H._basis(np.array([0.0]), np.array([0.1]), s[None, :]),
        side.lam[:1],
        side.lam[1:],
        side.slope[:1],
        side.slope[1:],
    )[0].max(axis=1)
    assert np.max(np.abs(np.sqrt(true / single) - 1)) > 0.05  # in frequency


@pytest.mark.parametrize("name", HINGES)
def test_hermite_meets_a_tenth_of_a_percent_and_its_estimate_is_not_far_below_the_error(exact: dict, name: str) -> None:
    """At tolerance 1e-3 the curve is within 1e-3 of exact, and the reported estimate is at least half the
    true error (the interpolant-in-frequency comparison alone read 7e-5 on the double cross, whose true error
    is 4.4e-4: six times below; hence the quintic comparison, see model.methods.hermite._error)."""
    an, ex = exact[name]
    c = frequency_curve(an, "hermite", tolerance=1e-3)
    err = float(np.max(np.abs(c.parasitic_hz / ex.parasitic_hz - 1)))
    assert c.solver["converged"] and err <= 1e-3, f"{name}: error {err:.3g}"
    assert c.solver["estimated_error"] >= 0.5 * err, f"{name}: estimate {c.solver['estimated_error']:.3g} vs {err:.3g}"


def test_fill_computes_the_points_of_intervals_the_samples_miss_exactly(exact: dict) -> None:
    """At tolerance 1e-4 with a budget of five samples per side the pivot's samples stop with intervals above
    the tolerance; ``fill`` (what auto does when its budget of a third of the points per side runs out)
    computes the requested points inside those exactly instead of the whole curve again. The filled points
    are exact solves (reached by another continuation path: agreement to 1e-9, the Newton tolerance's effect
    on a frequency), the rest within the tolerance."""
    from flexopt.model.methods.hermite import hermite_frequency_curve

    an, ex = exact["cross-spring-pivot"]
    c, extra = hermite_frequency_curve(an, ex.stroke, 1e-4, max_samples=5, fill=True)
    n_fill = extra["exact_points"]
    assert c.method == "hermite" and extra["converged"] and n_fill > 0 and extra["estimated_error"] <= 1e-4
    rel = np.abs(c.parasitic_hz / ex.parasitic_hz - 1)
    assert rel.max() <= 1e-4
    assert np.sum(rel <= 1e-9) >= n_fill  # every filled point (each mirrored once more) is exact


@pytest.mark.parametrize("name", HINGES)
def test_a_probed_interval_estimate_is_not_below_its_error(exact: dict, name: str, monkeypatch) -> None:  # noqa: ANN001
    """Every interval kept on a midpoint probe (model.methods.hermite._Side.probe) at tolerances 1e-2, 1e-3
    and 1e-4: the true error of the interpolated first parasitic frequency at the requested points inside it
    (against the exact curve) is at most its estimate, PROBE_FACTOR (2.5) times the error at the midpoint.
    The factor rests on a measurement: over the 90 intervals the refinement visited on the six templates, the
    largest ratio of an interval's error (exact on a 0.03 deg grid) to its midpoint error was 2.2 (three-fold
    cross hinge, first interval of the negative side), 3.8 on one interval whose error changes sign near the
    midpoint (double cross, at 5e-7); a cubic Hermite error with a constant fourth derivative peaks at the
    midpoint (ratio 1). Intervals kept here: 0 to 11 per template and tolerance (the leaf's and the guide's
    halves of the stroke at 1e-2 and 1e-3, probed at the quarter points)."""
    from flexopt.model.methods import hermite as H

    an, ex = exact[name]
    internal = np.asarray(an.scene.stroke.to_internal(ex.stroke), dtype=float)
    kept = []
    probe = H._Side.probe

    def spy(side, a_s, b_s):  # noqa: ANN001, ANN202 - records every probed interval with its side
        e, smp = probe(side, a_s, b_s)
        kept.append((side, a_s, b_s, e))
        return e, smp

    monkeypatch.setattr(H._Side, "probe", spy)
    for tol in (1e-2, 1e-3, 1e-4):
        kept.clear()
        H.hermite_curve(an, internal, tol)
        for side, a_s, b_s, e in kept:
            if side.checked.get((a_s, b_s)) != e:
                continue  # the probe became a sample
            lo, hi = sorted((a_s, b_s))
            inside = (internal > lo) & (internal < hi)
            if not inside.any():
                continue
            lam, labs = side.interpolate(internal[inside])
            hz = np.where(np.array(labs) == "parasitic", H._hz(lam), np.inf).min(axis=1)
            err = np.max(np.abs(hz / ex.parasitic_hz[inside] - 1))
            assert err <= e, f"{name} at {tol:g}: [{a_s:.4g}, {b_s:.4g}] error {err:.3g}, estimate {e:.3g}"


@pytest.mark.parametrize("name", HINGES)
def test_quarter_points_are_samples_only_where_the_branch_falls_over_the_first_half(
    exact: dict, name: str, monkeypatch
) -> None:  # noqa: ANN001
    """model.methods.hermite._Side.initial: the quarter point s/4 becomes a sample where the first parasitic
    frequency at half the stroke differs from its value at 0 by more than SMOOTH (20 %), read from the exact
    curve here (pivot, cartwheel, three-fold: 71 to 83 %), and the second half is probed at 3s/4; elsewhere
    (leaf 7 %, guide 0.03 %, double cross 0.4 %) both halves of the stroke are probed at their midpoints. A
    probed half's estimate is the probe's (or it was halved). Where s/4 is a sample, the eighth point is one
    too where the frequency at a quarter of the stroke differs from its value at 0 by more than STEEP (60 %;
    pivot and three-fold 68 and 66 to 69 % on the exact curve's nearest point, cartwheel 50 %). 3s/4 is never
    a sample from the start."""
    from flexopt.model.methods import hermite as H

    an, ex = exact[name]
    sides = []
    initial = H._Side.initial

    def spy(side, smax):  # noqa: ANN001, ANN202 - records each side after its initial samples
        initial(side, smax)
        sides.append((side, smax, [x.s for x in side.samples]))

    monkeypatch.setattr(H._Side, "initial", spy)
    H.hermite_curve(an, np.asarray(an.scene.stroke.to_internal(ex.stroke), dtype=float), 0.01)
    s = np.asarray(an.scene.stroke.to_internal(ex.stroke), dtype=float)
    at = lambda first, f: any(abs(abs(v) - f * abs(smax)) < 1e-12 for v in first)  # noqa: E731
    for side, smax, first in sides:
        f0 = ex.parasitic_hz[np.argmin(np.abs(s))]
        fh = ex.parasitic_hz[np.argmin(np.abs(s - smax / 2))]
        flat = abs(fh / f0 - 1) <= H.SMOOTH
        assert at(first, 0.25) == (not flat) and not at(first, 0.75), (name, smax, first)
        halves = {(0.0, first[-2]), (first[-2], first[-1])} if flat else {(first[-2], first[-1])}
        assert side.coarse == halves, (name, side.coarse)
        assert all(iv in side.checked or iv not in side.estimates() for iv in side.coarse)
        fq = ex.parasitic_hz[np.argmin(np.abs(s - smax / 4))]
        assert at(first, 0.125) == (not flat and abs(fq / f0 - 1) > H.STEEP), (name, smax, first)
    # the classification the docstring quotes (from the exact curves above): 0, s/2, s; 0, s/4, s/2, s; 0, s/8, s/4,
    # s/2, s
    n = {"leaf-spring": 3, "parallel-leaf-spring": 3, "double-cross-hinge": 3, "cartwheel-hinge": 4}.get(name, 5)
    assert len(sides[0][2]) == n


@pytest.mark.parametrize("name", ["cross-spring-pivot", "double-cross-hinge", "parallel-leaf-spring"])
def test_path_curvature_matches_second_differences_and_brings_the_long_first_step_into_newtons_basin(name):
    """model.statics.path_curvature (d2 xi/ds2 at stroke 0 from the exact third derivative) against the
    central second difference of converged equilibria at +-h (1e-3 rad, 1e-5 m: measured differences
    3e-7 and 1.5e-8 of the largest entry, shrinking as h^2 from 3x larger steps, so truncation dominates;
    1e-4 leaves room for the rounding of the Newton tolerance, while a missing term is of order 1); and on
    the pivot the step to a quarter of the stroke that the tangent
    predictor cannot start converges from the parabola."""
    from flexopt.model.statics import StepFailure, path_curvature, solve_point

    an = Analysis(template(name, **coarse(name)))
    sys = an.system
    eq0 = solve_point(sys, sys.reference_state(), 0.0, an.options, 0.0)
    curv = path_curvature(sys, eq0)
    h = 1e-3 if an.scene.stroke.kind == "rotation" else 1e-5
    xi = [
        sys.difference(solve_point(sys, sys.update(eq0.state, eq0.tangent * s), s, an.options, 0.0).state, eq0.state)
        for s in (h, -h)
    ]
    fd = (xi[0] + xi[1]) / h**2
    scale = np.abs(fd).max()
    assert scale > 0
    np.testing.assert_allclose(curv, fd, rtol=0, atol=1e-4 * scale)
    if name == "cross-spring-pivot":
        s1 = np.radians(45.0) / 4
        with pytest.raises(StepFailure):
            solve_point(sys, sys.update(eq0.state, eq0.tangent * s1), s1, an.options, 0.0)
        eq = solve_point(sys, sys.update(eq0.state, eq0.tangent * s1 + 0.5 * s1**2 * curv), s1, an.options, 0.0)
        assert eq.iterations <= 5


def test_the_quintic_of_the_estimate_is_the_hermite_interpolant_through_three_samples() -> None:
    """model.methods.hermite._quintic_all (cubic plus a correction, no solve; all intervals at once) against
    scipy's Krogh interpolator with doubled nodes (values and slopes at three strokes: the same polynomial of
    degree 5, built independently), for a neighbour on either side and unequal intervals, one call for the
    three; agreement to 1e-10 of the values' scale (rounding of the two constructions)."""
    from flexopt.model.methods.hermite import _basis, _interpolate, _quintic_all
    from scipy.interpolate import KroghInterpolator

    rng = np.random.default_rng(7)
    S = np.array([0.0, 0.3, 0.5, 1.2])
    y, dy = rng.uniform(1, 2, (4, 3)), rng.uniform(-3, 3, (4, 3))
    cases = ((1, 0), (1, 3), (0, 2))
    xs = np.array([np.linspace(S[i], S[i + 1], 18)[1:-1] for i, _ in cases])
    i_, nb_ = np.array([i for i, _ in cases]), np.array([nb for _, nb in cases])
    cubics = _interpolate(_basis(S[i_], S[i_ + 1], xs), y[i_], y[i_ + 1], dy[i_], dy[i_ + 1])
    every = _quintic_all(S, y, dy, i_, nb_, xs, cubics)
    for (i, nb), x, cubic, got in zip(cases, xs, cubics, every):
        for j in range(3):
            nodes = [S[i], S[i], S[i + 1], S[i + 1], S[nb], S[nb]]
            vals = [y[i, j], dy[i, j], y[i + 1, j], dy[i + 1, j], y[nb, j], dy[nb, j]]
            np.testing.assert_allclose(got[:, j], KroghInterpolator(nodes, vals)(x), rtol=0, atol=1e-10)
        assert np.abs(got - cubic).max() > 1e-3  # the next order does differ from the cubic here


@pytest.mark.parametrize(
    "name", ["leaf-spring", "parallel-leaf-spring", "cross-spring-pivot", "cartwheel-hinge", "double-cross-hinge"]
)
def test_slopes_at_stroke_zero_of_a_stroke_symmetric_design_vanish(exact: dict, name: str) -> None:
    """hermite takes every slope at stroke 0 as zero on a design whose symmetry reverses the stroke and whose
    eigenvalues there are simple (model.symmetry: the spectrum at -s is the one at s, so each simple branch is
    even). The computed slopes (model.methods.hermite.stroke_slopes) are zero to rounding there: measured
    1.3e-12 (leaf) to 1.9e-9 (cartwheel, whose 1898.5/1898.7/1898.8 Hz triple is 1.3e-4 apart: close
    eigenvalues amplify rounding) of the eigenvalue per radian (or metre); bounded at 1e-7, far below the
    slopes the hinges reach within the stroke, 1e-1 to 1e1 of it (the three-fold cross hinge, which has no
    such symmetry, has 1.3 at stroke 0)."""
    from flexopt.model.methods.hermite import SLOPE_CLUSTER_GAP
    from flexopt.model.methods.taylor import _multiple
    from flexopt.model.modal import modes_at
    from flexopt.model.statics import solve_point

    an, _ = exact[name]
    assert an.symmetry is not None
    eq0 = solve_point(an.system, an.system.reference_state(), 0.0, an.options, 0.0)
    m0 = modes_at(an.system, eq0, an.scene.modes + 2, an.scene.stroke.drive)
    assert not _multiple(np.sort(m0.omega2), SLOPE_CLUSTER_GAP)
    rel = np.abs(stroke_slopes(an, eq0, m0)) / m0.omega2
    assert rel.max() < 1e-7, rel
    three = Analysis(template("three-fold-cross-hinge", **coarse("three-fold-cross-hinge")))
    assert three.symmetry is None


def test_multiple_equals_the_multi_member_runs_of_clusters() -> None:
    """taylor._multiple (the clusters with more than one member, found without numpy.split) against the runs of
    taylor._clusters longer than one, on random ascending spectra built from exactly and nearly repeated values
    (relative gaps 1e-9 to 2e-7 around a cluster gap of 1e-6, and far apart ones)."""
    from flexopt.model.methods.taylor import _clusters, _multiple

    rng = np.random.default_rng(0)
    values = [1.0, 1.0 + 1e-9, 2.0, 2.0 + 1e-8, 3.0, 5.0, 5.0 + 1e-7, 5.0 + 2e-7]
    for _ in range(2000):
        lam = np.sort(rng.choice(values, rng.integers(0, 9)))
        assert [c.tolist() for c in _multiple(lam, 1e-6)] == [c.tolist() for c in _clusters(lam, 1e-6) if len(c) > 1]


def test_the_floor_benchmarks_oracle_meets_its_tolerance_and_hermite_needs_at_least_its_samples(exact: dict) -> None:
    """bench/bench_hermite_floor.py (the README's floor table): its oracle (bisection by the true error) must
    stop with a curve within the tolerance against the exact curve at the 91 requested points (the
    independent reference; the oracle bisects against 721 points, so this can fail only if its bookkeeping
    is wrong), and hermite, which must meet the same tolerance without knowing the error, never gets by with
    fewer samples than the bisection that knows it (on the pivot, where the table says 4 against 5)."""
    import importlib.util
    from pathlib import Path

    from flexopt.model.symmetry import image_indices, one_side

    path = Path(__file__).resolve().parents[1] / "bench" / "bench_hermite_floor.py"
    spec = importlib.util.spec_from_file_location("bench_hermite_floor", path)
    floor = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(floor)
    an, ex = exact["cross-spring-pivot"]
    internal = an.scene.stroke.to_internal(ex.stroke)
    sides = floor.oracle_samples(an, 1e-2)
    pos = one_side(internal)
    par = floor.oracle_curve(an, pos, sides)[image_indices(pos, internal)]
    assert np.max(np.abs(par / ex.parasitic_hz - 1)) <= 1e-2
    h = frequency_curve(an, "hermite", tolerance=1e-2)
    assert h.solver["samples"] - 1 >= sum(len(s) - 1 for s in sides.values())
