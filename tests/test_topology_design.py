"""Topology search, issue 30: per-stage and per-leaf dimensions (template, grammar, design spaces), pruning,
bound origins and validity constraints, case keys, and the multi-fidelity schedule against the exhaustive
run with the refined verification's order checked on a 4x finer mesh."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from flexopt.model.templates import template
from flexopt.optim import Problem, cases
from flexopt.optim.topology import enumerate_topologies, parse, screen_topology
from flexopt.optim.topology.grammar import crosses, design_parameters
from flexopt.optim.topology.rank import bound_origins, candidate_problem, design_space
from flexopt.optim.topology.screen import screen_key
from flexopt.optim.topology.spec import TopologySpec, example_spec


def _pos(scene) -> dict[str, np.ndarray]:
    return {n.name: np.asarray(n.position, float) for n in scene.nodes}


def test_per_stage_dimensions_keep_todays_scenes() -> None:
    """Every per-stage and per-leaf parameter defaults to 'as stage 1': a descriptor's scene without them is
    today's, and giving them stage 1's values gives the same scene."""
    for d in ("R:+-@", "R:+-|-+", "R:x+-|+-@", "R:-+2-@", "R:+r-r|-+"):
        base = template("topology-hinge", topology=d).model_dump()
        same = template(
            "topology-hinge",
            topology=d,
            length_s2=0.05,
            width_s2=0.02,
            thickness_s2=0.3e-3,
            angle_s2=90.0,
            thickness_s1l1=0.3e-3,
            thickness_s2l2=0.3e-3,
        ).model_dump()
        assert same == base, d


def test_per_stage_dimensions_place_the_stages_by_hand() -> None:
    """R:+-|-+ with stage 2 of length L2 = 40 mm, width w2 = 10 mm, angle 60 deg, thickness 0.2 mm (leaf 1 of
    stage 2: 0.25 mm) and stage 1 at the defaults (L 50 mm, w 20 mm, 90 deg, 0.3 mm, gap g 2 mm). The stack
    from the top is s2l1, s1l1, s1l2, s2l2 (stage 2's first half above stage 1), height 2 w1 + 2 w2 + 3 g =
    66 mm, so s2l1 sits at z = 33 - 5 = 28 mm and s1l1 at z = 33 - 10 - 2 - 10 = 11 mm; the '-' leaf of stage
    2 runs from (sin 30 L2/2, -cos 30 L2/2) to its mirror through the axis."""
    sc = template(
        "topology-hinge",
        topology="R:+-|-+",
        length_s2=0.04,
        width_s2=0.01,
        angle_s2=60.0,
        thickness_s2=0.2e-3,
        thickness_s2l1=0.25e-3,
    )
    p = _pos(sc)
    np.testing.assert_allclose(p["s2l1_0"], [0.5 * 0.02, -np.cos(np.pi / 6) * 0.02, 0.028], atol=1e-12)
    np.testing.assert_allclose(p["s2l1_1"], [-0.5 * 0.02, np.cos(np.pi / 6) * 0.02, 0.028], atol=1e-12)
    np.testing.assert_allclose(p["s2l2_0"][2], -0.028, atol=1e-12)
    np.testing.assert_allclose(p["s1l1_0"], [-np.sqrt(0.5) * 0.025, -np.sqrt(0.5) * 0.025, 0.011], atol=1e-12)
    sec = {e.name: (e.section.width, e.section.thickness) for e in sc.elements}
    assert sec == {"s1l1": (0.02, 0.3e-3), "s1l2": (0.02, 0.3e-3), "s2l1": (0.01, 0.25e-3), "s2l2": (0.01, 0.2e-3)}


@pytest.mark.parametrize(
    "descriptor, dimensions, expected",
    [
        # shared: length, thickness, width, angle (4); designed crossing adds 'crossing'
        ("R:+-|-+", "shared", ["length", "thickness", "width", "angle"]),
        # per stage: stage 2 adds its own four (8)
        (
            "R:+-|-+",
            "stage",
            ["length", "thickness", "width", "angle", "length_s2", "thickness_s2", "width_s2", "angle_s2"],
        ),
        # per leaf: each of the 4 leaves its thickness in place of its stage's (2 x (length, 2 thicknesses, width,
        # angle) = 10)
        (
            "R:+-|-+",
            "leaf",
            [
                "length",
                "thickness_s1l1",
                "thickness_s1l2",
                "width",
                "angle",
                "length_s2",
                "thickness_s2l1",
                "thickness_s2l2",
                "width_s2",
                "angle_s2",
            ],
        ),
        # one stage: 'stage' is 'shared'; a stage of radial leaves only has no angle of its own
        ("R:+-@", "stage", ["length", "thickness", "width", "angle", "crossing"]),
        ("R:+-|0", "stage", ["length", "thickness", "width", "angle", "length_s2", "thickness_s2", "width_s2"]),
        ("R:+r-r", "leaf", ["length", "thickness_s1l1", "thickness_s1l2", "width", "angle", "rigid_fraction"]),
    ],
)
def test_design_parameters_by_hand(descriptor: str, dimensions: str, expected: list[str]) -> None:
    assert design_parameters(parse(descriptor), dimensions) == expected


def test_design_parameters_are_template_parameters_and_traceable() -> None:
    """Every designed name is a parameter of topology-hinge and moves the scene (a non-zero derivative):
    a parameter the scene ignored would be a flat, degenerate direction for the solver."""
    from flexopt.model.design import trace_template
    from flexopt.optim.search import FamilyEvaluator

    spec = TopologySpec(dimensions="leaf", segments=2)
    for d in ("R:+-|-+", "R:x+-@|+-"):
        prob = candidate_problem(parse(d), spec)
        fam = FamilyEvaluator(prob, prob.families[0])
        ds = trace_template("topology-hinge", fam.params(fam.default_x()), fam.names)
        for j, name in enumerate(fam.names):
            moved = any(np.any(np.asarray(n["position"]) != 0) for n in ds.dscene[j]["nodes"]) or any(
                e["section"]["width"] != 0 or e["section"]["thickness"] != 0 for e in ds.dscene[j]["elements"]
            )
            assert moved, (d, name)


@pytest.mark.parametrize(
    "n, s, expected",
    [
        # one stage of at most 2 leaves, pruned: '+' and '++' cross nothing (no '@'); '+-', '+-@', 'x+-', 'x+-@':
        # 2 + 4 = 6 (8 unpruned: tests/test_topology.py)
        (2, 1, 6),
        # two stages of one leaf each add (+,+) and (+,-), neither with '@' (a single leaf crosses nothing): 6 + 2 = 8
        (2, 2, 8),
    ],
)
def test_pruned_enumeration_counts_by_hand(n: int, s: int, expected: int) -> None:
    tops = enumerate_topologies(n, s, prune=True)
    assert len(tops) == expected, [str(t) for t in tops]
    assert all(crosses(st) for t in tops for st in t.stages if st.free_crossing)


def test_screen_key_shares_the_verdict() -> None:
    """A designed crossing and a reinforcement do not change the flexure-level scene the screen sees: the
    verdicts of the variants and of their key are equal (computed independently here)."""
    for d, key in (("R:+-@", "R:+-"), ("R:+r-r", "R:+-"), ("R:x+-@|+-", "R:x+-|+-")):
        assert screen_key(parse(d)) == key
        a, b = screen_topology(parse(d)), screen_topology(parse(key))
        assert (a["status"], a["dof"], a["overconstraints"]) == (b["status"], b["dof"], b["overconstraints"])


def test_bounds_say_where_they_come_from() -> None:
    """R:+-|-+ in the default envelope (half height 20 mm), 4 layers and 3 gaps of 2 mm: the shared width's
    bound is (40 - 6) / 4 = 8.5 mm; the smallest width is half of it, 4.25 mm (below 5 mm); per stage, the
    other stage at its smallest: (34 - 2 x 4.25) / 2 = 12.75 mm. The width's upper bound is the envelope's
    height, and the warning for an optimum there says so instead of 'widen them'."""
    from flexopt.optim.search import FamilyEvaluator, _case_warnings

    t = parse("R:+-|-+")
    shared = design_space(t, TopologySpec(dimensions="shared"))
    assert shared["width"] == pytest.approx((4.25e-3, 8.5e-3), rel=1e-12)
    stage = design_space(t, TopologySpec(dimensions="stage"))
    assert stage["width"] == pytest.approx((4.25e-3, 12.75e-3), rel=1e-12) == stage["width_s2"]
    origins = bound_origins(t, TopologySpec())
    assert "envelope's height" in origins["width"][1] and "envelope's radius" in origins["length"][1]
    assert "min_thickness" in origins["thickness_s2"][0]
    prob = candidate_problem(t, TopologySpec())
    fam = FamilyEvaluator(prob, prob.families[0])
    opt = {"active_bounds": {"width": "upper", "angle": "lower"}, "active_kinds": [], "active": []}
    msgs = [w.message for w in _case_warnings(fam, 0, "optimal", "", {}, opt)]
    assert any("width is on its upper bound, which is the envelope's height" in m for m in msgs), msgs
    assert not any("widen them" in m for m in msgs), msgs
    # a family without origins keeps the old advice
    plain = Problem.model_validate(
        {"families": [{"template": "cross-spring-pivot", "design": {"width": [0.01, 0.04]}}]}
    )
    msgs = [
        w.message
        for w in _case_warnings(
            FamilyEvaluator(plain, plain.families[0]),
            0,
            "optimal",
            "",
            {},
            {"active_bounds": {"width": "upper"}, "active_kinds": [], "active": []},
        )
    ]
    assert any("widen them" in m for m in msgs)


def test_validity_constraint_row_and_gradient() -> None:
    """The validity row 1 - k w / L >= 0 (k = min_length_over_width = 3) at a design: its value by hand from
    the design's length and width, and its gradient against central differences of that value through the
    problem's own scaling (a step of 1e-6 of the unit box; the row is smooth, so 1e-6 is far above the
    rounding)."""
    from flexopt.optim.search import FamilyEvaluator

    spec = TopologySpec(dimensions="shared", min_length_over_width=3.0, segments=2, samples=3, stroke=10.0)
    prob = candidate_problem(parse("R:+-@"), spec)
    assert [(r.numerator, r.denominator, r.minimum) for r in prob.families[0].ratios] == [("length", "width", 3.0)]
    fam = FamilyEvaluator(prob, prob.families[0])
    x = np.full(len(fam.names), 0.5)
    ev = fam.evaluate(x)
    assert ev.ok, ev.message
    row = int(np.flatnonzero(ev.kinds == "validity")[0])
    p = fam.params(x)
    assert ev.con[row] == pytest.approx(1 - 3 * p["width"] / p["length"], rel=1e-12)

    def value(z: np.ndarray) -> float:
        q = fam.params(z)
        return 1 - 3 * q["width"] / q["length"]

    for j in range(len(x)):
        e = np.zeros(len(x))
        e[j] = 1e-6
        fd = (value(x + e) - value(x - e)) / 2e-6
        assert ev.jac[row, j] == pytest.approx(fd, rel=1e-6, abs=1e-9), fam.names[j]


def test_adding_starts_reuses_every_case() -> None:
    """A case's id does not depend on the number of starts: 3 starts are the 2 starts' cases and one more."""
    from flexopt.optim.batch import case_id

    prob = candidate_problem(parse("R:+-@"), TopologySpec(starts=2)).model_dump(mode="json")
    two = [case_id(c) for c in cases(prob)]
    three = [case_id(c) for c in cases({**prob, "starts": 3})]
    assert three[:2] == two and len(set(three)) == 3


def test_the_default_and_quick_specs() -> None:
    """The default spec is the broad space (6 leaves, 3 stages, per-stage dimensions, verified on a mesh
    within 0.2 %); the quick one today's 4-leaf, 2-stage space with shared dimensions."""
    d, q = example_spec(), example_spec("quick")
    assert (d["max_flexures"], d["max_stages"], d["dimensions"]) == (6, 3, "stage")
    assert (d["refine_segments"], d["refine_tolerance"]) == ("auto", 2e-3)
    assert (q["max_flexures"], q["max_stages"], q["dimensions"]) == (4, 2, "shared")


@pytest.mark.slow
def test_schedule_matches_the_exhaustive_run_and_refinement_keeps_the_order(tmp_path) -> None:
    """The multi-fidelity schedule against the exhaustive run on the 3-leaf, 2-stage space (10 survivors; the
    default space is the benchmark's, bench/bench_topology.py): the same winner and the same top 5 of
    distinct designs, and no two optimised candidates of the schedule with the same design. Then every one
    of the top 5 re-verified on 4 times the refined mesh: the order is unchanged (the ranking survives
    refinement). Coarse settings for the test's time; the two runs share one store, so the schedule's full
    pass reuses the exhaustive run's cases (keyed by content)."""
    from flexopt.optim.topology import run_topology_search
    from flexopt.optim.topology.rank import refine_case

    base = {
        "max_flexures": 3,
        "max_stages": 2,
        "dimensions": "shared",
        "segments": 6,
        "samples": 5,
        "starts": 1,
        "verify_points": 31,
        "refine_rounds": 0,
        "max_iterations": 20,
        "refine_points": 9,
        "refine_tolerance": 5e-3,
        "promote_min": 5,
        "promote": 0.1,
    }
    store = tmp_path / "store"
    full = run_topology_search({**base, "schedule": "exhaustive"}, workers=2, store=store, echo=False)
    sched = run_topology_search(base, workers=2, store=store, echo=False)
    by = {r["topology"]: r for r in full["candidates"]}
    distinct = [n for n in full["ranking"] if by[n]["same_design_as"] is None]
    assert sched["counts"]["first_pass"] == full["counts"]["optimised"] + full["counts"]["failed"]
    assert sched["counts"]["promoted"] < full["counts"]["promoted"]
    assert sched["ranking"][0] == distinct[0]
    assert sched["ranking"][:5] == distinct[:5], (sched["ranking"], distinct)
    sby = {r["topology"]: r for r in sched["candidates"]}
    designs = [tuple(round(v, 6) for v in sby[n]["design"].values()) + (n.replace("@", ""),) for n in sched["ranking"]]
    assert len(set(designs)) == len(designs)
    # the top 5 at 4x the refined mesh: same order
    top = [sby[n] for n in sched["ranking"][:5]]
    fine = []
    for r in top:
        ref = r["refined"]
        params = {
            **candidate_problem(parse(r["topology"]), TopologySpec(**base)).families[0].fixed,
            **r["design"],
            "body_mass": 0.1,
            "stroke": 45.0,
        }
        out = refine_case(
            {
                "params": params,
                "stroke": 45.0,
                "points": base["refine_points"],
                "extra": [r["stroke_at_worst"]],
                "segments": 4 * max(ref["segments_used"]),
                "tolerance": None,
                "safety_factor": 1.5,
            }
        )
        fine.append(out["worst_hz"])
    assert all(a > b for a, b in itertools.pairwise(fine)), (sched["ranking"][:5], fine)


def test_progress_is_one_line_per_event_in_logs(capsys) -> None:
    """Not on a terminal (pytest captures stderr), every event of every phase is one line with the counts
    and the best so far, and the callback gets the phase, the counts and the best with the batch's event."""
    from flexopt.optim.topology.rank import _Tracker

    events: list[dict] = []
    tr = _Tracker(events.append, generated=3, echo=True)
    tr.counts.update(screened=3, passed=1)
    tr.event("screen", {"done": 1, "total": 1, "id": "a", "status": "done", "record": {"verdicts": {}}})
    tr.offer("R:+-|-+", 52.0, "first pass")
    tr.offer("R:+-", 23.0, "first pass")  # lower: not the best
    tr.counts["first_pass"] = 1
    tr.event("first pass", {"done": 1, "total": 2, "id": "b", "status": "done", "record": {}})
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 2
    assert "screen 1/1: generated 3, screened 3, passed 1, first pass 0" in err[0]
    assert "first pass 1/2" in err[1] and "best R:+-|-+ 52.00 Hz (first pass)" in err[1]
    assert [e["phase"] for e in events] == ["screen", "first pass"] and "record" not in events[0]
    assert events[1]["best"] == {"topology": "R:+-|-+", "worst_hz": 52.0, "phase": "first pass"}
    assert events[1]["counts"]["first_pass"] == 1


def test_a_guide_is_shape_optimised_like_a_hinge() -> None:
    """Issue 30 item 6: seed 002's five-wire guide (Figure 3a) optimised for its worst-case parasitic frequency
    over +-2 mm (wire side and length designed): feasible, ranked by it, and at least the worst case of the
    start design, the template's own wires (1 mm x 50 mm), computed independently here on the same 31 points
    (within the search tolerance, 1e-3)."""
    from flexopt.model.curve import Analysis
    from flexopt.optim.topology import run_topology_search

    spec = {
        "motion": "translation",
        "topologies": ["T:z--,z-+,z+0,y-0,y+0"],
        "optimise_guides": 1,
        "segments": 4,
        "samples": 5,
        "starts": 1,
        "verify_points": 31,
        "refine_rounds": 0,
    }
    res = run_topology_search(spec, workers=1, echo=False)
    best = res["best"]
    assert best["optimised"] and best["stress_ratio"] <= 1 + 1e-3 and res["counts"]["optimised"] == 1
    start = Analysis(
        template("wire-guide-topology", topology="T:z--,z-+,z+0,y-0,y+0", segments=4, points=31)
    ).frequency_curve()
    assert best["worst_case_hz"] >= float(np.min(start.parasitic_hz)) * (1 - 1e-3)
    assert "wire_length" in best["bound_origins"]


def test_warm_start_inherits_the_shared_design() -> None:
    """A full pass's warm start (issue 30 speed): the first pass's shared design mapped into the per-leaf space
    (stage k's and each leaf's parameters inherit stage 1's, as the template's 0 defaults mean), a parameter
    the design lacks at the template's default (crossing 0.5), and the same scene as the shared design."""
    from flexopt.optim.search import FamilyEvaluator, warm_point

    shared = {"length": 0.041, "thickness": 2.2e-4, "width": 0.006, "angle": 100.0}
    spec = TopologySpec(dimensions="leaf")
    prob = candidate_problem(parse("R:+-@|-+"), spec)
    fam = FamilyEvaluator(prob, prob.families[0])
    p = fam.params(warm_point(fam, shared))
    for k in fam.names:
        if k == "crossing":
            assert p[k] == pytest.approx(0.5, abs=1e-12)
        else:  # length_s2 -> length, thickness_s2l1 -> thickness, ...
            assert p[k] == pytest.approx(shared[k.split("_s")[0]], rel=1e-12), k
    a = template("topology-hinge", **{**p, "segments": 2})
    b = template("topology-hinge", topology="R:+-@|-+", segments=2, body_mass=p["body_mass"], **shared)

    def leaves(v, path=""):  # (path, value) of every leaf of the scene's JSON
        if isinstance(v, dict):
            return [x for k in sorted(v) for x in leaves(v[k], f"{path}.{k}")]
        if isinstance(v, list):
            return [x for i, e in enumerate(v) for x in leaves(e, f"{path}[{i}]")]
        return [(path, v)]

    la, lb = leaves(a.model_dump(mode="json")), leaves(b.model_dump(mode="json"))
    assert [k for k, _ in la] == [k for k, _ in lb]
    for (k, u), (_, v) in zip(la, lb):  # the same scene, to round-off of the unit-box round trip
        assert u == pytest.approx(v, rel=1e-12, abs=1e-15) if isinstance(u, float) else u == v, k
    # a per-stage value present in the design wins over stage 1's (thickness_s2l1 -> thickness_s2)
    q = fam.params(warm_point(fam, {**shared, "thickness_s2": 3e-4}))
    assert q["thickness_s2l1"] == pytest.approx(3e-4) and q["thickness_s1l1"] == pytest.approx(2.2e-4)


@pytest.mark.slow
def test_designed_crossing_warm_started_at_its_midpoint_variant() -> None:
    """The first pass's second tier (issue 30 speed): a designed-crossing variant starts at its midpoint
    variant's first-pass optimum with the crossing at 0.5, a point of its own design space. Where the
    crossing's direction is stationary there (the double cross, its stacked stages symmetric about their
    midpoints) the case stops at once, 'stationary', with the crossing at 0.5 (pruned by the schedule as the
    midpoint variant); where it is not (an in-plane crossing after a stacked stage: the joint moves off the
    middle) it searches on and ends at least as high as the midpoint variant (its optimum is a point of the
    variant's space), with the crossing off the midpoint."""
    from flexopt.optim.search import run_case

    spec = TopologySpec(dimensions="shared")

    def first(desc: str, x0: dict | None = None) -> dict:
        c = cases(candidate_problem(parse(desc), spec, first_pass=True))[0]
        if x0 is not None:
            c.update(x0=x0, stop_if_stationary=True)
        return run_case({**c, "mesh_estimate": False})

    base = first("R:+-|-+")
    assert base["status"] == "optimal"
    var = first("R:+-|-+@", {**base["design"], "crossing": 0.5})
    assert var["status"] == "stationary" and var["evaluations"] <= 2, var["message"]  # the start, and on one side
    assert var["design"]["crossing"] == pytest.approx(0.5, abs=1e-12)
    assert var["optimality"]["kkt_residual"] <= 1e-2
    base = first("R:+-|x+-")
    var = first("R:+-|x+-@", {**base["design"], "crossing": 0.5})
    assert var["status"] == "optimal" and abs(var["design"]["crossing"] - 0.5) > 0.02
    assert var["verified"]["worst_hz"] >= base["verified"]["worst_hz"] * (1 - 1e-3)


@pytest.mark.parametrize("descriptor", ["R:+-|-+", "R:x+-|+-"])
def test_a_mirror_symmetric_start_keeps_its_evaluation_on_the_non_negative_samples(descriptor: str) -> None:
    """reduce_symmetric keeps the start's evaluation restricted to the samples >= 0 instead of evaluating the
    start again (optim.search.FamilyEvaluator._restricted). Reference: that evaluation computed again on the
    reduced samples; every row, its label and the worst case, its stroke and the peak stress must be the same
    numbers (the walk to each side of zero starts at the same reference equilibrium)."""
    from flexopt.optim.search import FamilyEvaluator

    spec = TopologySpec(**{**example_spec("quick"), "samples": 5})
    prob = candidate_problem(parse(descriptor), spec)
    fam = FamilyEvaluator(prob, prob.families[0])
    x = fam.default_x()
    ev = fam.evaluate(x)
    assert fam.reduce_symmetric(ev), "the start design is mirror symmetric in the stroke"
    kept = fam.evaluate(x)
    assert fam.evaluations == 1, "the reduced start is not evaluated again"
    assert np.all(fam.samples >= 0) and len(kept.con) < len(ev.con)
    fam._last = fam._good = None
    again = fam.evaluate(x)
    assert np.array_equal(kept.con, again.con) and np.array_equal(kept.jac, again.jac)
    assert kept.labels == again.labels and list(kept.kinds) == list(again.kinds)
    assert np.array_equal(kept.strokes, again.strokes, equal_nan=True)
    assert (kept.worst_hz, kept.stroke_at_worst, kept.max_stress) == (
        again.worst_hz,
        again.stroke_at_worst,
        again.max_stress,
    )
