"""Tapered leaves (issue 30 item 1): thickness zones along a leaf in the topology-hinge template, the grammar's
design spaces and the spec; today's specs unchanged; zones modelled right (a stepped beam's closed form) and
differentiated exactly (against finite differences)."""

from __future__ import annotations

import numpy as np
import pytest
from flexopt.model.errors import SceneError
from flexopt.model.templates import template
from flexopt.optim import cases
from flexopt.optim.topology import parse
from flexopt.optim.topology.grammar import design_parameters
from flexopt.optim.topology.rank import bound_origins, candidate_problem, design_space
from flexopt.optim.topology.spec import TopologySpec

from tests.references import stepped_cantilever_compliance, stepped_guided_compliance


@pytest.mark.parametrize(
    "descriptor, dimensions, taper, symmetric, expected",
    [
        # 3 zones mirrored about the middle: ceil(3/2) = 2 thicknesses in place of 'thickness'
        ("R:+-|-+", "shared", 3, True, ["length", "thickness_z1", "thickness_z2", "width", "angle"]),
        # 4 zones, each its own: 4 thicknesses
        (
            "R:+-@",
            "shared",
            4,
            False,
            ["length", "thickness_z1", "thickness_z2", "thickness_z3", "thickness_z4", "width", "angle", "crossing"],
        ),
        # per stage, 2 zones mirrored: one thickness per stage (zones 1 and 2 mirror each other)
        (
            "R:+-|-+",
            "stage",
            2,
            True,
            ["length", "thickness_z1", "width", "angle", "length_s2", "thickness_s2_z1", "width_s2", "angle_s2"],
        ),
        # an in-plane crossing keeps its one thickness; the stacked stage is tapered
        (
            "R:x+-|+-",
            "stage",
            3,
            True,
            [
                "length",
                "thickness",
                "width",
                "angle",
                "length_s2",
                "thickness_s2_z1",
                "thickness_s2_z2",
                "width_s2",
                "angle_s2",
            ],
        ),
        # shared: the in-plane stage keeps 'thickness', the stacked one's leaves take the zones
        ("R:x+-|+-", "shared", 3, True, ["length", "thickness", "thickness_z1", "thickness_z2", "width", "angle"]),
        # per leaf: a reinforced leaf keeps its thickness, the plain one is tapered
        (
            "R:+r-",
            "leaf",
            3,
            True,
            ["length", "thickness_s1l1", "thickness_s1l2_z1", "thickness_s1l2_z2", "width", "angle", "rigid_fraction"],
        ),
        # taper 1: today's space
        ("R:+-|-+", "shared", 1, True, ["length", "thickness", "width", "angle"]),
    ],
)
def test_design_parameters_with_taper_by_hand(
    descriptor: str, dimensions: str, taper: int, symmetric: bool, expected: list[str]
) -> None:
    assert design_parameters(parse(descriptor), dimensions, taper, symmetric) == expected


def test_spec_round_trip_and_errors() -> None:
    from pydantic import ValidationError

    spec = TopologySpec(taper=3, taper_symmetric=False, max_taper=1.5, topologies=["R:+-|-+"])
    again = TopologySpec.model_validate_json(spec.model_dump_json())
    assert again == spec and (again.taper, again.taper_symmetric, again.max_taper) == (3, False, 1.5)
    assert TopologySpec().taper == 1  # the default: uniform leaves
    for bad, field in (({"taper": 0}, "taper"), ({"taper": 6}, "taper"), ({"max_taper": 1.0}, "max_taper")):
        with pytest.raises(ValidationError) as exc:
            TopologySpec.model_validate(bad)
        assert exc.value.errors()[0]["loc"][0] == field


def test_a_spec_without_taper_is_todays() -> None:
    """Regression pin: the hash of each candidate problem's families (template, design bounds, their origins,
    validity rows, fixed parameters: all a topology spec decides of a problem), computed on 10a10b5 (main before
    tapered leaves; the same script on that checkout and on this one). Equal hashes mean the same problems,
    hence the same results (bench/bench_taper.py's taper-1 rows reproduce the published 57.12 and 75.89 Hz).
    A spec with taper 1 given explicitly is the same problem, case for case."""
    from flexopt.optim.batch import case_id

    today = {
        ("R:+-|-+", False): "31c5decb8ba6d26c97fa",
        ("R:+-|-+", True): "44d510f6fe419b9be1a6",
        ("R:+-|-+|+-", False): "f5ddcff232e72ca77ccb",
        ("R:+-|-+|+-", True): "a9ee68fc74814f5568e9",
        ("R:x+-@|+-", False): "a97748041510e3a4e797",
        ("R:x+-@|+-", True): "d4c493ac386baaacff8d",
    }
    for (d, first), pin in today.items():
        prob = candidate_problem(parse(d), TopologySpec(), first_pass=first).model_dump(mode="json")
        assert case_id({"families": prob["families"]}) == pin, (d, first)
        same = candidate_problem(parse(d), TopologySpec(taper=1), first_pass=first).model_dump(mode="json")
        assert [case_id(c) for c in cases(same)] == [case_id(c) for c in cases(prob)]
    # the first pass stays in the cheapest space (no zones); the full pass has them
    tapered = TopologySpec(taper=3)
    assert "taper" not in candidate_problem(parse("R:+-|-+"), tapered, first_pass=True).families[0].fixed
    assert candidate_problem(parse("R:+-|-+"), tapered).families[0].fixed["taper"] == 3


def test_zone_bounds_and_taper_rows() -> None:
    """Every zone's bounds are its leaf's thickness bounds with their origins (the manufacturing minimum, 1 mm);
    the taper is bounded both ways between neighbouring zones (t_a >= t_b / max_taper)."""
    t, spec = parse("R:+-|-+"), TopologySpec(taper=3, max_taper=1.5, min_thickness=80e-6)
    space, origins = design_space(t, spec), bound_origins(t, spec)
    for z in ("thickness_z1", "thickness_z2", "thickness_s2_z1", "thickness_s2_z2"):
        assert space[z] == (80e-6, 1e-3)
        assert "min_thickness" in origins[z][0] and "1 mm" in origins[z][1]
    rows = {(r.numerator, r.denominator): r.minimum for r in candidate_problem(t, spec).families[0].ratios}
    assert rows == {
        ("thickness_z1", "thickness_z2"): pytest.approx(1 / 1.5),
        ("thickness_z2", "thickness_z1"): pytest.approx(1 / 1.5),
        ("thickness_s2_z1", "thickness_s2_z2"): pytest.approx(1 / 1.5),
        ("thickness_s2_z2", "thickness_s2_z1"): pytest.approx(1 / 1.5),
    }


def test_zones_in_the_scene_by_hand() -> None:
    """R:+-|-+ with 3 zones (segments 8: ceil(8/3) = 3 per zone), zone 1 and 3 at 0.4 mm, zone 2 at 0.25 mm
    (mirrored), stage 2's middle its own 0.2 mm: every leaf is three beams joined at its thirds, each its own
    section. The in-plane and reinforced leaves keep one beam per part; taper 1 is today's scene."""
    sc = template(
        "topology-hinge",
        topology="R:+-|-+",
        segments=8,
        taper=3,
        thickness_z1=0.4e-3,
        thickness_z2=0.25e-3,
        thickness_s2_z2=0.2e-3,
    )
    pos = {n.name: np.asarray(n.position, float) for n in sc.nodes}
    beams = {e.name: e for e in sc.elements}
    assert sorted(beams) == sorted(f"s{k}l{i}z{j}" for k in (1, 2) for i in (1, 2) for j in (1, 2, 3))
    for k in (1, 2):
        for i in (1, 2):
            tag = f"s{k}l{i}"
            a, b = pos[f"{tag}_0"], pos[f"{tag}_1"]
            np.testing.assert_allclose(pos[f"{tag}_z1"], a + (b - a) / 3, atol=1e-15)
            np.testing.assert_allclose(pos[f"{tag}_z2"], a + 2 * (b - a) / 3, atol=1e-15)
            assert [beams[f"{tag}z{j}"].nodes for j in (1, 2, 3)] == [
                (f"{tag}_0", f"{tag}_z1"),
                (f"{tag}_z1", f"{tag}_z2"),
                (f"{tag}_z2", f"{tag}_1"),
            ]
            mid = 0.25e-3 if k == 1 else 0.2e-3
            assert [beams[f"{tag}z{j}"].section.thickness for j in (1, 2, 3)] == [0.4e-3, mid, 0.4e-3]
            assert all(beams[f"{tag}z{j}"].segments == 3 for j in (1, 2, 3))
    other = template("topology-hinge", topology="R:x+-|+r-", taper=3, thickness_z1=0.4e-3)
    names = sorted(e.name for e in other.elements)
    assert names == ["s1l1a", "s1l1b", "s1l2a", "s1l2b", "s2l1a", "s2l1b", "s2l2z1", "s2l2z2", "s2l2z3"]
    for d in ("R:+-|-+", "R:x+-@|+r-"):
        assert (
            template("topology-hinge", topology=d, taper=1).model_dump()
            == template("topology-hinge", topology=d).model_dump()
        )
    with pytest.raises(SceneError, match="taper"):
        template("topology-hinge", topology="R:+-", taper=7)


def _dense_modes(scene, grid: np.ndarray, k: int = 6) -> np.ndarray:
    """The k lowest frequencies at each stroke point by the dense eigen driver on the curve's own equilibria
    (the same pencil for both models, whatever the DOF numbering; the banded Lanczos route has a convergence
    tolerance of its own)."""
    from flexopt.model.curve import Analysis
    from flexopt.model.modal import _lowest_pairs

    an = Analysis(scene)
    sys = an.system
    out = []

    def visit(eq, modes, labels) -> None:  # noqa: ANN001 - the curve's callback
        K = np.array(sys.free_block(eq.ev.H, True))
        M = np.array(sys.free_block(sys.mass(eq.state), True))
        w, _ = _lowest_pairs(K, M, k)
        out.append(np.sqrt(w) / (2 * np.pi))

    an.frequency_curve(stroke=grid, visit=visit)
    return np.array(out)


def test_uniform_taper_is_the_uniform_leaf() -> None:
    """Three zones of equal thickness with 2 segments each are the uniform leaf of 6 segments: the same beam
    segments (constants and masses equal to rounding, 1e-15, matched one to one) and so the same frequencies
    at every stroke. Tolerance of the frequencies, 1e-10: the zone nodes are placed as a + (b - a) j / 3 and the
    uniform leaf's as a + (b - a) i / 6, which differ in the last bit, and the lowest eigenvalues of a thin
    leaf amplify such rounding by about its axial over bending stiffness (12 (l / t)^2, 1e4 here): measured
    3e-11 at zero stroke, where no equilibrium is solved."""
    from flexopt.model.curve import Analysis

    uniform = template("topology-hinge", topology="R:+-|-+", segments=6)
    zoned = template(
        "topology-hinge", topology="R:+-|-+", segments=6, taper=3, thickness_z1=0.3e-3, thickness_z2=0.3e-3
    )
    sa, sb = Analysis(uniform).structure, Analysis(zoned).structure
    assert sa.n_beams == sb.n_beams == 24
    ia, ib = np.lexsort(np.round(sa.beam_const, 6).T), np.lexsort(np.round(sb.beam_const, 6).T)
    np.testing.assert_allclose(sb.beam_const[ib], sa.beam_const[ia], rtol=1e-15, atol=1e-15)
    np.testing.assert_allclose(sb.beam_mass[ib], sa.beam_mass[ia], rtol=1e-15)
    grid = np.array([-45.0, -20.0, 0.0, 30.0, 45.0])
    np.testing.assert_allclose(_dense_modes(zoned, grid), _dense_modes(uniform, grid), rtol=1e-10)


@pytest.mark.parametrize("t1, t2", [(0.3e-3, 0.3e-3), (0.45e-3, 0.2e-3), (0.2e-3, 0.45e-3)])
def test_two_zone_leaf_against_the_stepped_beam(t1: float, t2: float) -> None:
    """One radial leaf (R:0, length 50 mm, width 20 mm) in two zones, t1 at ground, t2 at the rotor, and a force
    across the leaf at its rotor end. With the drive (the rotor's rotation about the axis) locked, the leaf is
    a stepped clamped-guided beam; with it free, a stepped cantilever, whose compliance depends on which zone
    is at the root (4.4 times between the two orders here). The compliance of the linearised model (the static
    gain over every mode) against the closed forms (tests/references.py, Euler-Bernoulli), I = w t^3 / 12.
    Tolerance 1e-12: cubic beam elements are nodally exact for end loads on a prismatic piece (and a zone
    boundary is a node), so what remains is rounding in the sum over the modes (measured: at most 2e-13)."""
    from flexopt.model.linear import state_space

    L, w, E = 0.05, 0.02, 210e9
    sc = template(
        "topology-hinge",
        topology="R:0",
        taper=2,
        taper_symmetric=0,
        thickness_z1=t1,
        thickness_z2=t2,
        segments=4,
        length=L,
        width=w,
    )
    I1, I2 = w * t1**3 / 12, w * t2**3 / 12
    guided = float(state_space(sc, 0.0, ["s1l1_1.fx"], ["s1l1_1.x"]).static_gain()[0, 0])
    assert guided == pytest.approx(stepped_guided_compliance(L, L / 2, E, I1, I2), rel=1e-12)
    free = sc.model_copy(update={"stroke": sc.stroke.model_copy(update={"drive": "free"})})
    tip = float(state_space(free, 0.0, ["s1l1_1.fx"], ["s1l1_1.x"]).static_gain()[0, 0])
    assert tip == pytest.approx(stepped_cantilever_compliance(L, L / 2, E, I1, I2), rel=1e-12)


def test_design_gradient_of_every_zone_against_finite_differences() -> None:
    """The optimiser's exact design gradient (CasADi through the template, the structure and the equilibrium)
    of every constraint row -- the parasitic frequencies, the stress at every segment end of every zone, the
    taper rows -- with respect to each zone thickness, against central differences of the same rows. R:+-|-+
    with 3 zones each its own thickness (shared by the four leaves), all three different. Step 1e-5
    of the unit box (about 1e-8 m): the truncation error (h^2 times the third derivative) is below 1e-9
    relative, the equilibrium's rounding below 1e-7 relative over 2h; tolerance 1e-5 relative (of the row's
    scale; measured at most 6e-7)."""
    from flexopt.optim.search import FamilyEvaluator

    spec = TopologySpec(
        dimensions="shared", taper=3, taper_symmetric=False, segments=3, samples=3, stroke=20.0, max_taper=3.0
    )
    prob = candidate_problem(parse("R:+-|-+"), spec)
    fam = FamilyEvaluator(prob, prob.families[0])
    zones = [i for i, n in enumerate(fam.names) if "_z" in n]
    assert [fam.names[i] for i in zones] == ["thickness_z1", "thickness_z2", "thickness_z3"]
    x = np.full(len(fam.names), 0.5)
    x[zones] = [0.35, 0.2, 0.3]  # about 0.38, 0.24, 0.33 mm: three different zones
    ev = fam.evaluate(x)
    assert ev.ok, ev.message
    kinds = set(ev.kinds)
    assert {"frequency", "stress", "validity"} <= kinds
    stressed = {lab.split(" (")[0] for lab, k in zip(ev.labels, ev.kinds) if k == "stress"}
    assert {f"stress in s1l1z{j}" for j in (1, 2, 3)} <= stressed  # every zone's stress is a row
    h = 1e-5
    for j in zones:
        e = np.zeros(len(x))
        e[j] = h
        up, down = fam.evaluate(x + e), fam.evaluate(x - e)
        assert up.ok and down.ok
        fd = (up.con - down.con) / (2 * h)
        scale = np.maximum(np.abs(ev.jac[:, j]), np.max(np.abs(ev.jac[:, j])) * 1e-3)
        err = np.abs(ev.jac[:, j] - fd) / scale
        worst = int(np.argmax(err))
        assert err[worst] < 1e-5, (fam.names[j], ev.labels[worst], ev.jac[worst, j], fd[worst])


def test_beam_theory_checks_see_the_leaf_not_the_zone() -> None:
    """The slenderness checks (model.checks) measure a tapered leaf's zones by the leaf's span: three zones of a
    46 mm leaf, 8.3 mm wide, read L/w = 46 / 8.3 = 5.54, as the uniform leaf does (not 1.85, a zone's own),
    with the same shear share (E / (kappa G)) (w / L)^2; a reinforced leaf's parts and an in-plane crossing's
    halves (joined to a body or to the other leaf) stay members of their own."""
    from flexopt.model.checks import slenderness_warnings

    dims = {"topology": "R:+-|-+", "length": 0.046, "width": 0.0083}
    uniform = {w.element: w.value for w in slenderness_warnings(template("topology-hinge", **dims))}
    zoned = {w.element: w.value for w in slenderness_warnings(template("topology-hinge", taper=3, **dims))}
    assert sorted(zoned) == sorted(f"{leaf}z{j}" for leaf in uniform for j in (1, 2, 3))
    for name, value in zoned.items():
        assert value == pytest.approx(uniform[name[:-2]], rel=1e-12)
    msg = next(w.message for w in slenderness_warnings(template("topology-hinge", taper=3, **dims)))
    assert "L/w = 5.54" in msg and "one of the 3 pieces" in msg
    mixed = {
        w.element: w.value for w in slenderness_warnings(template("topology-hinge", topology="R:x+-|+r-", taper=3))
    }
    assert mixed["s1l1a"] > 2 * mixed["s2l2z1"]  # a half leaf (25 mm) against the whole tapered leaf (50 mm)


@pytest.mark.parametrize("dimensions", ["shared", "stage", "leaf"])
def test_every_zone_parameter_moves_its_zones(dimensions: str) -> None:
    """Under every design space each zone thickness is a template parameter that changes the thickness of the
    zones it names and of no other beam (its exact derivative, traced with CasADi): a name the scene ignored
    would be a flat direction for the solver, one that moved another zone a wrong model."""
    from flexopt.model.design import trace_template
    from flexopt.optim.search import FamilyEvaluator

    spec = TopologySpec(dimensions=dimensions, taper=3, segments=3)
    prob = candidate_problem(parse("R:x+-|+-|-+"), spec)
    fam = FamilyEvaluator(prob, prob.families[0])
    ds = trace_template("topology-hinge", fam.params(fam.default_x()), fam.names)
    names = [e["name"] for e in ds.scene_dict["elements"]]
    for j, name in enumerate(fam.names):
        if "_z" not in name:
            continue
        moved = {n for n, e in zip(names, ds.dscene[j]["elements"]) if e["section"]["thickness"] != 0}
        base, zone = name.rsplit("_z", 1)
        stages = {"thickness": ("s2", "s3") if dimensions == "shared" else ("s1",)}.get(base, (base[10:12],))
        leaf = base[12:] if dimensions == "leaf" else ""
        ends = {"1": ("z1", "z3"), "2": ("z2",)}[zone]  # symmetric: zones 1 and 3 share one thickness
        expected = {n for n in names if n[:2] in stages and n.startswith(n[:2] + leaf) and n.endswith(ends)}
        assert moved == expected and moved, (name, moved, expected)


@pytest.mark.slow
def test_mesh_estimate_of_a_tapered_hinge() -> None:
    """The curve's mesh estimate (model.mesh: Richardson at order 2) on the tapered double cross hinge near its
    optimum (bench/bench_taper.py), against the error measured from 32 segments per zone: at 3 segments per zone
    (too coarse to halve: compared with 4 times the mesh) and at 8 (halved), within 10 %, the accuracy model/mesh.py
    documents on the default templates (measured: 1 % and 7 %). Zone boundaries are nodes of every mesh."""
    from flexopt.model.curve import Analysis

    d = dict(
        topology="R:+-|-+",
        taper=3,
        length=0.07,
        thickness_z1=0.494e-3,
        thickness_z2=0.473e-3,
        width=0.00866,
        angle=67.4,
        length_s2=0.046,
        thickness_s2_z1=0.512e-3,
        thickness_s2_z2=0.486e-3,
        width_s2=0.00834,
        angle_s2=112.7,
        points=9,
    )
    grid = np.linspace(-45.0, 45.0, 9)
    ref = Analysis(template("topology-hinge", segments=96, **d)).frequency_curve(stroke=grid)
    for n in (8, 24):
        c = Analysis(template("topology-hinge", segments=n, **d)).frequency_curve(stroke=grid, mesh_error=True)
        true = float(np.max(np.abs(c.parasitic_hz / ref.parasitic_hz - 1)))
        assert c.mesh_error == pytest.approx(true, rel=0.1), (n, c.mesh_error, true)
