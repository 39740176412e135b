"""Pareto fronts (optim/pareto.py): the drive stiffness's exact gradient, the front's feasibility and
non-dominance checked on independently computed exact curves, its end points against a grid search, the
NSGA-II check, the CLI and the figure."""

from __future__ import annotations

import concurrent.futures as cf
import importlib.util
import json
import math

import numpy as np
import pytest
from flexopt.model import Analysis, template
from flexopt.optim.pareto import ParetoSpec, drive_stiffness, pareto
from flexopt.service.cli.main import main

PIVOT = {
    "template": "cross-spring-pivot",
    "design": {"length": [0.03, 0.07], "thickness": [2e-4, 4e-4]},
    "fixed": {"segments": 4},
}  # a coarse mesh: the tests compare methods on the same mesh
PROBLEM = {"families": [PIVOT], "stroke": 30, "samples": 5, "starts": 1, "verify_points": 31, "max_iterations": 20}
HAS_PYMOO = importlib.util.find_spec("pymoo") is not None
SPEC = {
    "problem": PROBLEM,
    "points": 4,
    "check": {"population": 8, "generations": 4, "tolerance": 0.02} if HAS_PYMOO else None,
}
TOL = PROBLEM.get("tolerance", 1e-3)  # the problem's tolerance (its default): search and verification


def _exact(design: dict, points: int) -> tuple[float, float, float]:
    """Independent of optim/: worst-case first parasitic frequency [Hz], drive stiffness [N m/rad] (peak
    |reaction| / stroke) and peak stress / (allowable / 1.5) of an exact curve on ``points`` stroke points."""
    scene = template("cross-spring-pivot", segments=4, stroke=30.0, **design)
    c = Analysis(scene).frequency_curve(stroke=np.linspace(-30.0, 30.0, points))
    assert c.status == "complete"
    vm = np.nan_to_num(np.array(list(c.max_von_mises.values())), nan=0.0)
    allow = min(m.allowable_stress for m in scene.materials) / 1.5
    return (
        float(np.min(c.parasitic_hz)),
        float(np.max(np.abs(c.drive_reaction))) / math.radians(30.0),
        float(np.max(vm)) / allow,
    )


@pytest.mark.slow
def test_drive_stiffness_gradient_matches_finite_differences():
    """dK/dp from the implicit-function derivative of the drive reaction, against Richardson-extrapolated
    central differences of independent exact curves (steps 1 % and 0.5 % of each parameter's range): the
    peak is at the stroke's end at every nearby design (a fixed sample), so K is smooth there; truncation
    O(h^4) ~ 1e-8 relative and Newton noise (~1e-8) over the step stay well below 1e-4, which a missing term
    of the derivative (the equilibrium's move changes dR by tens of per cent) exceeds."""
    design = {"length": 0.05, "thickness": 3e-4}
    k, grad = drive_stiffness(PROBLEM, design)
    assert k == pytest.approx(_exact(design, 5)[1], rel=1e-9)  # the same samples, the same equilibria
    for name, (lo, hi) in PIVOT["design"].items():

        def central(h: float, name: str = name) -> float:
            up, dn = dict(design), dict(design)
            up[name] += h
            dn[name] -= h
            return (_exact(up, 5)[1] - _exact(dn, 5)[1]) / (2 * h)

        h = 0.01 * (hi - lo)
        fd = (4 * central(h / 2) - central(h)) / 3
        assert grad[name] == pytest.approx(fd, rel=1e-4), name


EVENTS: list[dict] = []  # the front's progress events (the fixture's run)


@pytest.fixture(scope="module")
def front() -> dict:
    with cf.ThreadPoolExecutor(2) as ex:  # any Executor; threads run the same worker code without start-up
        return pareto(SPEC, executor=ex, progress=EVENTS.append)


@pytest.mark.slow
def test_progress_names_each_phase_in_order(front):
    """Every progress event names its phase: the two optima (one case each per start), the levels between them
    (points - 2), then NSGA-II's generations and the verification of its points (when checked); a front point's
    record carries its kind and verified drive stiffness, the numbers of the result's points."""
    phases = [e["phase"] for e in EVENTS]
    order = ["optima", "levels"] + (["check", "check verification"] if SPEC["check"] else [])
    assert [p for i, p in enumerate(phases) if i == 0 or p != phases[i - 1]] == order
    assert phases.count("optima") == 2 * PROBLEM["starts"] and phases.count("levels") == (SPEC["points"] - 2)
    points = sorted(
        (e["record"]["drive_stiffness"], e["record"]["kind"]) for e in EVENTS if e["phase"] in ("optima", "levels")
    )
    assert [k for k, _ in points] == sorted(p["drive_stiffness"] for p in front["points"])
    assert points[0][1] == "min_drive" and points[-1][1] == "max_frequency"


@pytest.mark.slow
def test_every_point_is_a_verified_feasible_design(front):
    """Each point's worst case, drive stiffness and stress, recomputed from an independent exact curve of its
    design on the verification grid, are what the front reports (the same computation: 1e-9), the stress is
    within allowable / safety factor (to the search tolerance) and the drive within its level."""
    assert len(front["points"]) == SPEC["points"], front["warnings"]
    for p in front["points"]:
        assert p["status"] == "optimal", p["message"]
        f, k, s = _exact(p["design"], PROBLEM["verify_points"])
        assert p["worst_hz"] == pytest.approx(f, rel=1e-9)
        assert p["drive_stiffness"] == pytest.approx(k, rel=1e-9)
        assert s <= 1 + TOL
        if p["level"] is not None:
            assert k <= p["level"] * (1 + TOL)


@pytest.mark.slow
def test_no_point_dominates_another(front):
    """Pairwise Pareto dominance (at least as good in both objectives, better in one), written out here."""
    pts = front["points"]
    for a in pts:
        for b in pts:
            if a is not b:
                assert not (a["worst_hz"] >= b["worst_hz"] and a["drive_stiffness"] <= b["drive_stiffness"]), (a, b)
    ks = [p["drive_stiffness"] for p in sorted(pts, key=lambda p: p["drive_stiffness"])]
    assert len(set(ks)) == len(ks)


@pytest.mark.slow
def test_end_points_are_the_single_objective_optima(front):
    """Against a 5 x 5 grid of independent exact curves over the design box (feasible = stress within the
    limit): the max-frequency end is no lower than the grid's best (0.5 %, test_optim's criterion for a search
    against a grid), and the min-drive end no stiffer than the grid's least stiff (1e-3, the search tolerance:
    the minimum is the box corner of longest, thinnest leaves, a grid point)."""
    grid = []
    for L in np.linspace(0.03, 0.07, 5):
        for t in np.linspace(2e-4, 4e-4, 5):
            f, k, s = _exact({"length": float(L), "thickness": float(t)}, PROBLEM["verify_points"])
            if s <= 1.0:
                grid.append((f, k))
    assert grid
    top, bottom = front["max_frequency"], front["min_drive_stiffness"]
    assert top["worst_hz"] >= max(f for f, _ in grid) * (1 - 5e-3)
    assert bottom["drive_stiffness"] <= min(k for _, k in grid) * (1 + 1e-3)
    ks = sorted(p["drive_stiffness"] for p in front["points"])
    assert (ks[0], ks[-1]) == (bottom["drive_stiffness"], top["drive_stiffness"])


@pytest.mark.slow
@pytest.mark.skipif(not HAS_PYMOO, reason="pymoo (the optional extra 'pareto') is not installed")
def test_nsga2_finds_nothing_that_dominates_the_front(front):
    """NSGA-II (8 x 4 exact curves, gradient-free) through the same executor: none of its verified
    non-dominated points beats a front point by more than 2 % in one objective while no worse in the other.
    The front's points are KKT points verified to 1e-3, so a 2 % margin is a missed optimum, not rounding."""
    chk = front["check"]
    assert chk["evaluations"] == 8 * 4 and chk["points"]
    for q in chk["points"]:
        f, k, _ = _exact(q["design"], PROBLEM["verify_points"])
        assert (q["worst_hz"], q["drive_stiffness"]) == pytest.approx((f, k), rel=1e-9)
        for p in front["points"]:
            assert not (f > p["worst_hz"] * 1.02 and k <= p["drive_stiffness"]), (q, p)
            assert not (k < p["drive_stiffness"] * 0.98 and f >= p["worst_hz"]), (q, p)
    assert chk["passed"], chk["summary"]


@pytest.mark.slow
def test_figure_and_table(front, tmp_path):
    from flexopt.service.cli.pareto import _table
    from flexopt.service.plots import pareto_figure, save

    save(pareto_figure(front), str(tmp_path / "f.png"))
    assert (tmp_path / "f.png").stat().st_size > 10_000
    text = _table(front)
    assert "min drive stiffness" in text and "max frequency" in text and "N m/rad" in text


def test_cli_pareto_one_leaf(tmp_path, capsys):
    """One design parameter (a leaf's thickness; frequency and drive stiffness both rise with it): the front
    runs end to end through the CLI; JSON out, points ordered along the thickness."""
    spec = {
        "problem": {
            "families": [{"template": "leaf-spring", "design": {"thickness": [3e-4, 6e-4]}, "fixed": {"segments": 4}}],
            "stroke": 20,
            "samples": 5,
            "starts": 1,
            "verify_points": 31,
            "max_iterations": 10,
        },
        "points": 3,
    }
    path = tmp_path / "spec.json"
    path.write_text(json.dumps(spec))
    assert main(["pareto", str(path), "--json", "--workers", "1"]) == 0
    out = json.loads(capsys.readouterr().out)
    pts = sorted(out["points"], key=lambda p: p["drive_stiffness"])
    assert len(pts) == 3 and out["drive_stiffness_unit"] == "N m/rad"
    assert pts[0]["design"]["thickness"] == pytest.approx(3e-4, rel=1e-6)  # min drive: the thinnest leaf
    assert pts[-1]["design"]["thickness"] == pytest.approx(6e-4, rel=1e-6)  # max frequency: the thickest
    assert [p["worst_hz"] for p in pts] == sorted(p["worst_hz"] for p in pts)


@pytest.mark.parametrize(
    "bad,words",
    [
        ({"problem": {"families": [PIVOT, PIVOT]}}, "problem.families: a front is drawn for one family"),
        ({"problem": PROBLEM, "points": 1}, "points: Input should be greater than or equal to 2"),
        ({"problem": PROBLEM, "colour": 1}, "colour: Extra inputs"),
    ],
)
def test_cli_bad_spec_is_one_line_naming_the_field(tmp_path, capsys, bad, words):
    path = tmp_path / "spec.json"
    path.write_text(json.dumps(bad))
    assert main(["pareto", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and words in err, err


def test_spec_example_validates():
    from flexopt.optim.pareto import example_spec

    assert ParetoSpec.model_validate(example_spec()).points == 5


@pytest.mark.slow
def test_front_against_stroke(tmp_path, capsys):
    """Worst case against stroke for one leaf (thickness 0.3-0.6 mm, strokes 10-40 deg): each point is the
    frequency optimum at its stroke, its worst case and stress re-verified on an independent exact curve (1e-9,
    the same computation; stress within the limit to the search tolerance), and no point dominated: a longer
    stroke never keeps a higher worst case. The CLI draws and tabulates it."""
    spec = {
        "problem": {
            "families": [{"template": "leaf-spring", "design": {"thickness": [3e-4, 6e-4]}, "fixed": {"segments": 4}}],
            "samples": 5,
            "starts": 1,
            "verify_points": 31,
            "max_iterations": 10,
        },
        "points": 3,
        "against": "stroke",
        "strokes": [10, 40],
    }
    path = tmp_path / "spec.json"
    path.write_text(json.dumps(spec))
    assert main(["pareto", str(path), "--json", "--workers", "1", "--plot", str(tmp_path / "s.png")]) == 0
    out = json.loads(capsys.readouterr().out)
    pts = sorted(out["points"], key=lambda p: p["stroke"])
    assert [p["stroke"] for p in pts] == [10, 25, 40] and out["stroke_unit"] == "deg"
    for p in pts:
        assert p["status"] == "optimal", p["message"]
        scene = template("leaf-spring", segments=4, stroke=p["stroke"], **p["design"])
        c = Analysis(scene).frequency_curve(stroke=np.linspace(-p["stroke"], p["stroke"], 31))
        vm = np.nan_to_num(np.array(list(c.max_von_mises.values())), nan=0.0)
        assert p["worst_hz"] == pytest.approx(float(np.min(c.parasitic_hz)), rel=1e-9)
        assert float(np.max(vm)) <= 600e6 / 1.5 * (1 + TOL)
    assert [p["worst_hz"] for p in pts] == sorted((p["worst_hz"] for p in pts), reverse=True)
    assert (tmp_path / "s.png").stat().st_size > 10_000


@pytest.mark.parametrize(
    "extra,words",
    [
        ({"against": "stroke"}, "strokes: with against 'stroke'"),
        ({"strokes": [10, 20]}, "strokes: only with against 'stroke'"),
        ({"against": "stroke", "strokes": [10, 20], "check": {}}, "check: the NSGA-II check covers"),
    ],
)
def test_stroke_spec_errors_name_the_field(extra, words):
    with pytest.raises(ValueError, match=words):
        ParetoSpec.model_validate({"problem": PROBLEM, **extra})
