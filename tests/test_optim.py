"""The optimiser (optim/): problem validation, gradients of the epigraph constraints, optima against an
independent grid search of exact curves."""

from __future__ import annotations

import numpy as np
import pytest
from flexopt.model import Analysis, template
from flexopt.model.errors import FlexoptError
from flexopt.optim import Problem, cases, run_case
from flexopt.optim.search import FamilyEvaluator
from pydantic import ValidationError

LEAF = {
    "families": [{"template": "leaf-spring", "design": {"thickness": [3e-4, 6e-4]}}],
    "stroke": 20,
    "samples": 5,
    "starts": 1,
    "max_iterations": 10,
}


@pytest.mark.parametrize(
    "bad,words",
    [
        ({"families": []}, "at least 1"),
        ({"families": [{"template": "leaf-spring", "design": {"thickness": [6e-4, 3e-4]}}]}, "lower < upper"),
        ({"families": [{"template": "leaf-spring", "design": {"thickness": [3e-4, float("inf")]}}]}, "finite"),
        (
            {
                "families": [
                    {"template": "leaf-spring", "design": {"thickness": [3e-4, 6e-4]}, "fixed": {"thickness": 5e-4}}
                ]
            },
            "both designed and fixed",
        ),
        ({**LEAF, "samples": 2}, "greater than or equal to 3"),
        ({**LEAF, "colour": "red"}, "Extra inputs"),
    ],
)
def test_bad_problems_name_the_field(bad, words):
    with pytest.raises(ValidationError, match=words):
        Problem.model_validate(bad)


@pytest.mark.parametrize(
    "family,words",
    [
        ({"template": "no-such", "design": {"x": [0, 1]}}, "unknown template 'no-such'"),
        ({"template": "leaf-spring", "design": {"lenght": [0.05, 0.1]}}, r"no parameters \['lenght'\]"),
        ({"template": "leaf-spring", "design": {"thickness": [1e-6, 2e-5]}}, "minimum manufacturable thickness"),
    ],
)
def test_bad_families_get_a_clear_error(family, words):
    prob = Problem.model_validate({"families": [family]})
    with pytest.raises(FlexoptError, match=words):
        FamilyEvaluator(prob, prob.families[0])


def test_epigraph_constraint_jacobian_matches_finite_differences():
    """Every frequency, stress, drive and envelope constraint's gradient in the scaled design, against Richardson-
    extrapolated central differences of re-solved designs (steps 4e-3 and 2e-3 of the unit box): the
    truncation error is O(h^4) ~ 1e-9 and the rounding noise of re-solved equilibria and eigenvalues (about
    2e-8 relative) divided by the step stays near 1e-5, so 1e-4 absolute on constraints of order 1 is a
    bound that any missing derivative term (1e-2 or more) exceeds."""
    prob = Problem.model_validate(
        {
            "families": [
                {
                    "template": "cross-spring-pivot",
                    "design": {"length": [0.03, 0.07], "thickness": [2e-4, 4e-4], "body_offset": [0.0, 0.02]},
                }
            ],
            "samples": 5,
            "max_drive": 1.0,
            "envelope": 0.06,
        }
    )
    fam = FamilyEvaluator(prob, prob.families[0])
    x = np.array([0.4, 0.5, 0.3])
    ev = fam.evaluate(x)
    assert ev.ok, ev.message

    def central(j: int, h: float) -> np.ndarray:
        e = np.zeros(len(x))
        e[j] = h
        return (fam.evaluate(x + e).con - fam.evaluate(x - e).con) / (2 * h)

    for j in range(len(x)):
        fd = (4 * central(j, 2e-3) - central(j, 4e-3)) / 3
        np.testing.assert_allclose(
            ev.jac[:, j], fd, rtol=1e-4, atol=1e-4, err_msg=f"constraint gradients along {fam.names[j]}"
        )


def test_epigraph_gradients_with_a_payload_under_gravity_match_finite_differences():
    """The problem's gravity (the payload's and the leaves' weight, model.loads) in the search's constraints and
    their exact gradients (model.design, step 6): as the test above, same steps and tolerance, with gravity
    across the pivot's axis (30 m/s^2: the weight changes the scaled constraints by up to 0.26, asserted above
    1e-2, a hundred times the tolerance)."""
    spec = {
        "families": [{"template": "cross-spring-pivot", "design": {"length": [0.03, 0.07], "thickness": [2e-4, 4e-4]}}],
        "samples": 5,
        "max_drive": 1.0,
    }
    prob = Problem.model_validate({**spec, "gravity": [0.0, -30.0, 0.0]})
    fam = FamilyEvaluator(prob, prob.families[0])
    x = np.array([0.4, 0.5])
    ev = fam.evaluate(x)
    assert ev.ok, ev.message
    bare = FamilyEvaluator(Problem.model_validate(spec), prob.families[0]).evaluate(x)
    assert np.abs(ev.con - bare.con).max() > 1e-2

    def central(j: int, h: float) -> np.ndarray:
        e = np.zeros(len(x))
        e[j] = h
        return (fam.evaluate(x + e).con - fam.evaluate(x - e).con) / (2 * h)

    for j in range(len(x)):
        fd = (4 * central(j, 2e-3) - central(j, 4e-3)) / 3
        np.testing.assert_allclose(
            ev.jac[:, j], fd, rtol=1e-4, atol=1e-4, err_msg=f"constraint gradients along {fam.names[j]}"
        )


def test_leaf_thickness_optimum_beats_a_grid_of_exact_curves():
    """One parameter: frequencies rise with thickness and the stress limit is far at 20 degrees, so the
    optimum is the upper bound; the verified worst case must be at least the best of an 11-point grid of
    independently computed exact curves (within 0.5 %, the benchmark's criterion)."""
    r = run_case(cases(LEAF)[0])
    assert r["status"] == "optimal", r["message"]
    assert r["design"]["thickness"] == pytest.approx(6e-4, rel=1e-6)
    grid = []
    for t in np.linspace(3e-4, 6e-4, 11):
        c = Analysis(template("leaf-spring", thickness=float(t), stroke=20.0, points=41)).frequency_curve()
        grid.append(float(np.min(c.parasitic_hz)))
    assert r["verified"]["worst_hz"] >= max(grid) * (1 - 5e-3)
    assert r["verified"]["points"] == 181
    assert r["searched"]["worst_hz"] == pytest.approx(r["verified"]["worst_hz"], rel=1e-3)


@pytest.mark.slow
def test_two_parameter_pivot_optimum_beats_a_grid_search():
    """Two parameters (length and thickness of the cross-spring pivot) with the stress constraint active:
    the optimiser's verified worst case is at least that of a 7 x 7 grid of feasible designs (exact
    31-point curves, stress checked), within 0.5 %."""
    # optimum against a grid on one mesh, the pivot's former default (tests.helpers.COARSE_MESH): any mesh
    spec = {
        "families": [
            {
                "template": "cross-spring-pivot",
                "fixed": {"segments": 8},
                "design": {"length": [0.03, 0.07], "thickness": [1.5e-4, 4e-4]},
            }
        ],
        "starts": 2,
    }
    prob = Problem.model_validate(spec)
    best = max((run_case(c) for c in cases(prob)), key=lambda r: r["verified"].get("worst_hz", -1))
    assert best["status"] == "optimal", best["message"]
    allow = 600e6 / prob.safety_factor
    grid_best = 0.0
    for L in np.linspace(0.03, 0.07, 7):
        for t in np.linspace(1.5e-4, 4e-4, 7):
            c = Analysis(
                template("cross-spring-pivot", length=float(L), thickness=float(t), points=31, segments=8)
            ).frequency_curve()
            stress = max(float(np.max(v)) for v in c.max_von_mises.values())
            if c.status == "complete" and stress <= allow:
                grid_best = max(grid_best, float(np.min(c.parasitic_hz)))
    assert grid_best > 0
    assert best["verified"]["worst_hz"] >= grid_best * (1 - 5e-3), (best["verified"]["worst_hz"], grid_best)
    # the start design's curve (for the plot) comes from method auto at the search tolerance (1e-3) and says
    # so; against its exact curve on the same 181 points
    ini = best["initial"]
    assert ini["method"] == "hermite" and ini["estimated_error"] <= prob.tolerance
    ex = Analysis(template("cross-spring-pivot", segments=8, **best["x0"])).frequency_curve(
        stroke=np.array(ini["stroke"])
    )
    np.testing.assert_allclose(ini["parasitic_hz"], ex.parasitic_hz, rtol=prob.tolerance)
    assert ini["worst_hz"] == pytest.approx(float(np.min(ex.parasitic_hz)), rel=prob.tolerance)


def test_cli_optimise_prints_the_ranking_and_writes_scenes(tmp_path, capsys):
    import json

    from flexopt.service.cli.main import main

    spec = tmp_path / "spec.json"
    spec.write_text(json.dumps(LEAF))
    assert main(["optimise", str(spec), "--workers", "1", "--scenes", str(tmp_path / "out"), "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["ranking"][0]["template"] == "leaf-spring"
    scene = json.loads((tmp_path / "out" / "leaf-spring.json").read_text())
    assert scene["elements"][0]["section"]["thickness"] == pytest.approx(6e-4, rel=1e-6)


def test_cli_optimise_bad_spec_is_one_line_naming_the_field(tmp_path, capsys):
    import json

    from flexopt.service.cli.main import main

    spec = tmp_path / "spec.json"
    spec.write_text(json.dumps({**LEAF, "samples": 1}))
    assert main(["optimise", str(spec)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "samples" in err, err


def _extent(scene: dict, radial: bool) -> float:
    """Largest distance of the nodes and leaf edges (node +- width/2 along y_axis) from the origin (or the z axis)."""
    pos = {n["name"]: np.asarray(n["position"], float) for n in scene["nodes"]}
    pts = list(pos.values())
    for el in scene["elements"]:
        u = np.asarray(el["y_axis"], float) / np.linalg.norm(el["y_axis"])
        pts += [pos[n] + s * el["section"]["width"] / 2 * u for n in el["nodes"] for s in (1, -1)]
    return max(float(np.hypot(p[0], p[1]) if radial else np.linalg.norm(p)) for p in pts)


def test_envelope_limits_the_optimum():
    """Without an envelope the pivot's best length is the upper bound (bench/bench_optim.py); a 30 mm sphere
    must stop it: the farthest point of the leaves (a leaf edge) lies on it (active constraint, to the search
    tolerance) and never outside."""
    spec = {
        "families": [
            {"template": "cross-spring-pivot", "design": {"length": [0.03, 0.07], "thickness": [1.5e-4, 4e-4]}}
        ],
        "starts": 1,
        "envelope": 0.03,
    }
    r = run_case(cases(spec)[0])
    assert r["status"] == "optimal", r["message"]
    assert "envelope" in r["optimality"]["active_kinds"]
    assert r["verified"]["stress_ratio"] <= 1 + 1e-3
    far = _extent(r["verified"]["scene"], radial=False)
    assert 0.03 * (1 - 1e-3) <= far <= 0.03 * (1 + 1e-6), far


def test_fast_screening_picks_the_best_estimated_start():
    """The screening rung evaluates each start's candidates with the 'auto' method (fd2 is within 5 % on the
    leaf over +-20 deg, so it is used) and starts from the best estimate; the verified optimum is the same
    upper-bound thickness as without screening."""
    r = run_case(cases({**LEAF, "screen": 4, "screen_tolerance": 0.05})[0])
    s = r["screening"]
    assert s["candidates"] == s["scored"] == 4 and sum(s["methods"].values()) == 4
    assert set(s["methods"]) <= {"fd1", "fd2", "manifold", "reduced", "exact"} and "exact" not in s["methods"]
    assert r["design"]["thickness"] == pytest.approx(6e-4, rel=1e-6)


# ---------------------------------------------------------------------------------------------------------------
# The audit's eight points (issue 16), one test each

# the cartwheel at its former default mesh (tests.helpers.COARSE_MESH): these tests check gradients and starts
CARTWHEEL = {
    "families": [
        {
            "template": "cartwheel-hinge",
            "design": {"thickness": [1e-4, 4e-4], "angle": [60, 120]},
            "fixed": {"segments": 8},
        }
    ],
    "stroke": 10,
    "samples": 3,
    "starts": 1,
    "verify_points": 31,
}


def test_1_every_constraint_gradient_is_finite_at_zero_stress():
    """The cartwheel's and the leaf's segment ends are exactly unstressed at stroke 0, where the root of the von
    Mises bound has a 0/0 gradient (it gave NaN rows there, and a NaN made dedupe keep one row). The squared
    rows are finite at every sample, stroke 0 included, for a stressed and an unstressed design."""
    from flexopt.model.design import point_sensitivity, structure_derivative, trace_template

    for spec in (CARTWHEEL, LEAF):
        prob = Problem.model_validate(spec)
        fam = FamilyEvaluator(prob, prob.families[0])
        assert np.any(fam.samples == 0.0)
        for x in (np.full(len(fam.names), 0.5), np.zeros(len(fam.names))):
            ev = fam.evaluate(x)
            assert ev.ok, ev.message
            assert np.all(np.isfinite(ev.jac)) and np.all(np.isfinite(ev.con)), fam.fam.template
            fam.select(ev)
            assert len(fam.keep) > 1
    ds = trace_template("cartwheel-hinge", {"stroke": 10.0, "segments": 8}, ["thickness"])
    an = Analysis(ds.scene)
    d = [structure_derivative(an.structure, ds.scene_dict, ds.dscene[0])]
    seen = []

    def visit(eq, modes, labels):
        ps = point_sensitivity(an.system, eq, modes, [0], d)
        seen.append((float(ps.vm.min()), bool(np.all(np.isfinite(ps.dvm2)))))

    an.frequency_curve(stroke=np.array([0.0]), visit=visit)
    assert seen[0][0] == 0.0, "an exactly unstressed segment end at stroke 0 (the case of the audit)"
    assert seen[0][1], "d(vm^2)/dp is finite where the stress vanishes"


def test_1_select_refuses_a_nan_row_instead_of_dropping_rows():
    prob = Problem.model_validate(LEAF)
    fam = FamilyEvaluator(prob, prob.families[0])
    ev = fam.evaluate(np.array([0.5]))
    ev.jac = ev.jac.copy()
    ev.jac[-1, 0] = np.nan
    with pytest.raises(FlexoptError, match="not finite"):
        fam.select(ev)


def test_2_refinement_never_reruns_the_same_problem(monkeypatch):
    """A verified stress overrun at a stroke the search already samples (the audit's +-45 deg case): nothing can
    be added, so the round stops with the reason (it used to rerun the identical problem every round)."""
    from flexopt.optim import search

    real = search.verify

    def overrun_at_a_sample(fam, x, points, *more):
        v = real(fam, x, points, *more)
        if v.get("status") == "complete":
            v.update(stress_ratio=1.2, stroke_at_max_stress=fam.stroke, member_at_max_stress="leaf")
        return v

    monkeypatch.setattr(search, "verify", overrun_at_a_sample)
    r = run_case(cases({**LEAF, "refine_rounds": 3})[0])
    assert len(r["history"]) == 1 and r["status"] == "infeasible", r["history"]
    assert "sampled stroke 20" in r["message"]
    assert any(w["kind"] == "stress" for w in r["warnings"])


def test_2_refinement_adds_an_unsampled_stroke_once():
    from flexopt.optim.search import _refine

    prob = Problem.model_validate(LEAF)
    fam = FamilyEvaluator(prob, prob.families[0])
    v = {"worst_hz": 1.0, "stroke_at_worst": 7.0, "stroke_at_max_stress": 20.0, "member_at_max_stress": "leaf"}
    added, why = _refine(fam, v, low=True, stressed=False, symmetric=False)
    assert added and not why and {7.0, -7.0} <= set(fam.samples)
    added, why = _refine(fam, v, low=True, stressed=False, symmetric=False)
    assert not added and "sampled stroke 7" in why


def test_3_stress_limits_are_smooth_rows_per_segment_end():
    """One row per segment end and sample (never the maximum over segments, whose kinks stall SLSQP), each a
    smooth function: its gradient matches central differences (the pivot's crossing, where the maximum over
    segments had its V-shaped kink at the optimum)."""
    prob = Problem.model_validate(
        {
            "families": [{"template": "cross-spring-pivot", "design": {"crossing": [0.3, 0.7]}}],
            "samples": 3,
            "stroke": 30,
        }
    )
    fam = FamilyEvaluator(prob, prob.families[0])
    x = np.array([0.5])
    ev = fam.evaluate(x)
    nb = Analysis(template("cross-spring-pivot")).structure.n_beams
    assert int(np.sum(ev.kinds == "stress")) == 3 * 2 * nb
    h = 1e-3
    fd = (fam.evaluate(x + h).con - fam.evaluate(x - h).con) / (2 * h)
    stress = ev.kinds == "stress"
    # central differences of a smooth row: O(h^2) truncation; 1e-4 absolute on rows of order 1 (as above)
    np.testing.assert_allclose(ev.jac[stress, 0], fd[stress], atol=1e-4, rtol=1e-4)


def test_4_unconverged_starts_are_reported_not_ranked():
    """A start stopped by the iteration limit reports its status and KKT residual and is not ranked; a converged
    one has a residual within kkt_tolerance."""
    from flexopt.optim import summarise

    spec = {
        "families": [
            {"template": "cross-spring-pivot", "design": {"length": [0.03, 0.07], "thickness": [1.5e-4, 4e-4]}}
        ],
        "samples": 3,
        "starts": 1,
        "verify_points": 31,
        "refine_rounds": 0,
    }
    stopped = run_case(cases({**spec, "max_iterations": 1})[0])
    # one iteration: SLSQP stops at the limit, at a design that is either feasible (unconverged) or not
    assert stopped["status"] in ("unconverged", "infeasible"), stopped["message"]
    assert stopped["solver"]["converged"] is False and "Iteration limit" in stopped["solver"]["message"]
    assert stopped["optimality"]["kkt_residual"] >= 0 and stopped["optimality"]["kkt_residual"] >= 0
    prob = Problem.model_validate({**spec, "max_iterations": 1})
    res = summarise(prob, [stopped])
    assert res["ranking"] == [] and res["families"][0]["failed"][0]["status"] == stopped["status"]
    assert any("not ranked" in w["message"] for w in res["warnings"])
    done = run_case(cases(spec)[0])
    assert done["status"] == "optimal", done["message"]
    assert done["optimality"]["kkt_residual"] <= 1e-2 and done["optimality"]["max_violation"] <= 1e-3
    assert len(done["provenance"]["problem_sha256"]) == 64 and done["provenance"]["solver"]["method"] == "slsqp"


def test_5_active_bounds_and_a_common_envelope_and_mass():
    """The pivot's length runs into its upper bound: the report says so (the bound's result, not the family's).
    A cylinder around the axis bounds it instead, and the problem's body_mass reaches every family."""
    spec = {
        "families": [
            {"template": "cross-spring-pivot", "design": {"length": [0.03, 0.07], "thickness": [1.5e-4, 4e-4]}}
        ],
        "samples": 3,
        "starts": 1,
        "verify_points": 31,
    }
    r = run_case(cases(spec)[0])
    assert r["optimality"]["active_bounds"] == {"length": "upper"}
    assert any("stopped by the design bounds length (upper)" in w["message"] for w in r["warnings"])
    env = run_case(cases({**spec, "envelope": {"radius": 0.025, "half_height": 0.03}, "body_mass": 0.05})[0])
    assert env["status"] == "optimal", env["message"]
    assert "length" not in env["optimality"]["active_bounds"] and "envelope" in env["optimality"]["active_kinds"]
    assert _extent(env["verified"]["scene"], radial=True) == pytest.approx(0.025, rel=1e-3)
    assert env["moving_mass"] == 0.05 and env["verified"]["scene"]["bodies"][0]["mass"] == 0.05
    with pytest.raises(FlexoptError, match="body_mass is set by the problem"):
        p = Problem.model_validate(
            {
                **spec,
                "body_mass": 0.05,
                "families": [
                    {"template": "cross-spring-pivot", "design": {"length": [0.03, 0.07]}, "fixed": {"body_mass": 0.1}}
                ],
            }
        )
        FamilyEvaluator(p, p.families[0])


def test_6_adding_starts_keeps_the_earlier_ones():
    from flexopt.optim.search import start_point

    two, five = (Problem.model_validate({**CARTWHEEL, "starts": n}) for n in (2, 5))
    fa, fb = FamilyEvaluator(two, two.families[0]), FamilyEvaluator(five, five.families[0])
    for k in range(2):
        np.testing.assert_array_equal(start_point(fa, two, 0, k), start_point(fb, five, 0, k))
    pts = np.array([start_point(fb, five, 0, k) for k in range(1, 5)])
    assert len({tuple(p) for p in pts}) == 4 and np.all((pts >= 0) & (pts <= 1))
    other = Problem.model_validate({**CARTWHEEL, "starts": 2, "seed": 1})
    assert not np.array_equal(start_point(fa, two, 0, 1), start_point(fa, other, 0, 1))


def test_8_a_failed_evaluation_stops_the_solver_and_steps_back(monkeypatch):
    """Designs thicker than 5.2e-4 m 'lose equilibrium' (patched): the solver never receives a value there (it
    used to get every constraint at -1 with the last good point's gradient); the search steps back to the last
    good design and ends below the failure, reported as not converged (the bound was not reached)."""
    from flexopt.optim import search

    real = search.FamilyEvaluator._evaluate

    def fails_when_thick(self, x):
        if self.params(x)["thickness"] > 5.2e-4:
            raise FlexoptError("equilibrium lost at stroke 3 (patched for the test)")
        return real(self, x)

    monkeypatch.setattr(search.FamilyEvaluator, "_evaluate", fails_when_thick)
    prob = Problem.model_validate(LEAF)
    fam = FamilyEvaluator(prob, prob.families[0])
    assert fam.evaluate(np.array([0.1])).ok
    with pytest.raises(search._EvaluationFailed):
        fam.fun(np.array([0.9, 1.0]))
    r = run_case(cases(LEAF)[0])
    assert r["history"][0]["step_backs"], "the failure was met and stepped back from"
    assert r["design"]["thickness"] <= 5.2e-4 and r["status"] in ("unconverged", "failed"), r["status"]


def test_trust_constr_reaches_the_same_optimum():
    r = run_case(cases({**LEAF, "solver": "trust-constr"})[0])
    assert r["status"] == "optimal", r["message"]
    assert r["design"]["thickness"] == pytest.approx(6e-4, rel=1e-4)


def test_cylinder_envelope_rows_match_finite_differences():
    """The envelope's rows (nodes and leaf edges in a cylinder around the axis) are algebraic in the design:
    their gradients along width, angle and crossing match central differences to rounding (quadratic
    functions: the O(h^2) truncation is below 1e-8 at h = 1e-4)."""
    prob = Problem.model_validate(
        {
            "families": [
                {
                    "template": "cross-spring-pivot",
                    "design": {"width": [0.01, 0.04], "angle": [60, 120], "crossing": [0.3, 0.7]},
                }
            ],
            "samples": 3,
            "envelope": {"radius": 0.04, "half_height": 0.03},
        }
    )
    fam = FamilyEvaluator(prob, prob.families[0])
    x = np.array([0.4, 0.3, 0.6])
    ev = fam.evaluate(x)
    env = ev.kinds == "envelope"
    assert int(env.sum()) == 2 * (4 + 2 * 2 * 2), "radius and end rows of 4 nodes and 8 leaf-edge points"
    h = 1e-4
    for j in range(3):
        e = np.zeros(3)
        e[j] = h
        fd = (fam.evaluate(x + e).con - fam.evaluate(x - e).con) / (2 * h)
        np.testing.assert_allclose(ev.jac[env, j], fd[env], atol=1e-7, err_msg=fam.names[j])


def test_kkt_residual_of_one_active_frequency_row_is_its_gradient_norm():
    """Independent closed form: at an interior design where only the worst frequency rows are active (all with
    the same design gradient g, the leaf's mirrored samples), stationarity asks -e_t = s (g, -1) with
    s = sum mu_i >= 0; the least-squares residual (1 - s)^2 + s^2 g^2 is least at s = 1 / (1 + g^2), where
    it is |g| / sqrt(1 + g^2). At the thickness bound the bound's multiplier absorbs g (frequencies rise with
    thickness) and the residual is 0."""
    from flexopt.optim.search import _optimality

    prob = Problem.model_validate(LEAF)
    fam = FamilyEvaluator(prob, prob.families[0])
    ev = fam.evaluate(np.array([0.5]))
    nf = fam.n_frequency()
    act = np.flatnonzero(ev.con[:nf] - ev.con[:nf].min() <= 1e-3)
    g = ev.jac[act, 0]
    assert np.ptp(g) <= 1e-9 * abs(g[0]) and g[0] > 0
    assert _optimality(fam, ev, 1e-3)["kkt_residual"] == pytest.approx(abs(g[0]) / np.sqrt(1 + g[0] ** 2), rel=1e-9)
    top = _optimality(fam, fam.evaluate(np.array([1.0])), 1e-3)
    assert top["kkt_residual"] == pytest.approx(0.0, abs=1e-12) and top["active_bounds"] == {"thickness": "upper"}


def test_summary_warns_of_unequal_payloads_and_a_missing_envelope():
    """Two families moving different masses, compared without an envelope: the ranking stands, but the summary
    says both (never a silent unfair comparison); it is JSON with the problem's hash in its provenance."""
    import json

    from flexopt.optim import summarise

    prob = Problem.model_validate(
        {
            "families": [
                {"template": "cross-spring-pivot", "design": {"length": [0.03, 0.07]}, "fixed": {"body_mass": 0.2}},
                {"template": "cartwheel-hinge", "design": {"length": [0.04, 0.14]}},
            ]
        }
    )

    def result(i: int, hz: float, mass: float) -> dict:
        return {
            "family_index": i,
            "start": 0,
            "status": "optimal",
            "message": "",
            "design": {"length": 0.05},
            "verified": {"worst_hz": hz, "zero_stroke_hz": 2 * hz, "ratio": 0.5, "stress_ratio": 1.0},
            "optimality": {"kkt_residual": 0.0, "active_bounds": {}, "active": []},
            "moving_mass": mass,
            "warnings": [],
            "seconds": 1.0,
        }

    res = summarise(prob, [result(0, 30.0, 0.2), result(1, 20.0, 0.1)])
    assert [r["template"] for r in res["ranking"]] == ["cross-spring-pivot", "cartwheel-hinge"]
    words = " ".join(w["message"] for w in res["warnings"])
    assert "move different masses" in words and "no envelope" in words
    assert json.loads(json.dumps(res))["provenance"]["problem_sha256"] == res["provenance"]["problem_sha256"]


def test_cli_optimise_a_cluster_without_workers_is_one_line_and_exit_4(tmp_path, capsys, monkeypatch):
    """The batch's NoWorkers (tested on a real cluster in tests/test_batch.py) reaches the user as one line."""
    import json

    import flexopt.optim
    import flexopt.optim.batch as batch
    from flexopt.service.cli.main import main

    class _Executor:
        def shutdown(self) -> None:
            pass

    def no_workers(*args, **kwargs):
        raise batch.NoWorkers([{"id": "a"}, None], kwargs["no_worker_timeout"])

    monkeypatch.setattr(batch, "dask_executor", lambda address: _Executor())
    monkeypatch.setattr(flexopt.optim, "optimise", no_workers, raising=False)
    spec = tmp_path / "spec.json"
    spec.write_text(json.dumps(LEAF))
    assert main(["optimise", str(spec), "--scheduler", "tcp://127.0.0.1:8786", "--no-worker-timeout", "5"]) == 4
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "no workers for 5 s" in err and "1 of 2 cases" in err, err


def test_the_verified_curves_own_warnings_reach_the_start():
    """A validity or mesh warning of the model's checks on the verified curve is the optimum's warning too; a
    stress warning is replaced by the optimiser's own (which applies the safety factor)."""
    from flexopt.optim.search import _case_warnings

    prob = Problem.model_validate(LEAF)
    fam = FamilyEvaluator(prob, prob.families[0])
    verified = {
        "stress_ratio": 0.5,
        "warnings": [
            {
                "kind": "validity",
                "message": "leaf: L/t = 8 is below 10",
                "element": "leaf",
                "stroke_range": None,
                "value": 8.0,
            },
            {
                "kind": "stress",
                "message": "leaf above allowable",
                "element": "leaf",
                "stroke_range": [-20, 20],
                "value": 1.1,
            },
        ],
    }
    out = _case_warnings(fam, 0, "optimal", "", verified, None)
    assert [(w.kind, w.element, w.value) for w in out] == [("validity", "leaf", 8.0)]
    assert "L/t = 8" in out[0].message and "start 0" in out[0].message


def test_a_failing_start_steps_toward_the_template_design(monkeypatch):
    """Start 1's own design 'fails' (patched): the start steps a quarter of the way toward start 0 (the
    template's design, which works) and is optimised from there, saying so; start 0 never moves."""
    from flexopt.optim import search

    prob = Problem.model_validate({**LEAF, "starts": 2})
    x1 = search.start_point(FamilyEvaluator(prob, prob.families[0]), prob, 0, 1)
    real = search.FamilyEvaluator._evaluate

    def start_fails(self, x):
        if np.array_equal(x, x1):
            raise FlexoptError("equilibrium becomes unstable (patched for the test)")
        return real(self, x)

    monkeypatch.setattr(search.FamilyEvaluator, "_evaluate", start_fails)
    r = run_case(cases({**LEAF, "starts": 2})[1])
    assert r["start_moved"]["fraction_toward_defaults"] == 0.25 and "patched" in r["start_moved"]["reason"]
    assert r["status"] == "optimal", r["message"]
    assert any("toward the template's design" in w["message"] for w in r["warnings"])
