"""Loads and gravity (issue 28, item 1): statics, continuation and eigen analysis against closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest
from flexopt.model.curve import Analysis
from flexopt.model.errors import FlexoptError, SceneError
from flexopt.model.io import scene_from_dict
from flexopt.model.methods import curve_with_method
from flexopt.model.statics import reference_equilibrium

from .references import (
    BECK_FLUTTER_PUBLISHED,
    beck_flutter_load,
    elastica_tip,
    follower_elastica_tip,
    tensioned_cantilever_stiffness,
    tip_moment_arc,
)

E, G = 210e9, 79e9


def _beam_scene(
    L: float,
    w: float,
    t: float,
    n: int,
    *,
    axis=(1, 0, 0),
    supports,
    stroke,
    density=7800.0,
    bodies=(),
    loads=(),
    gravity=None,
    rigid=(),
    modes=2,
) -> dict:
    return {
        "name": "loaded",
        "materials": [{"name": "steel", "E": E, "G": G, "density": density, "allowable_stress": 1e9}],
        "nodes": [{"name": "A", "position": [0, 0, 0]}, {"name": "B", "position": list(L * np.array(axis))}],
        "bodies": list(bodies),
        "elements": [
            {
                "kind": "beam",
                "name": "leaf",
                "nodes": ["A", "B"],
                "material": "steel",
                "section": {"kind": "rectangular", "width": w, "thickness": t},
                "y_axis": [0, 1, 0],
                "segments": n,
                "rigid": list(rigid),
            }
        ],
        "supports": supports,
        "stroke": stroke,
        "loads": list(loads),
        "gravity": gravity,
        "modes": modes,
    }


# --------------------------------------------------------------------------------- elastica
L_E, W_E, T_E = 0.1, 0.01, 0.0005
EI_E = E * W_E * T_E**3 / 12


def _elastica(P: float, n: int, **extra) -> dict:
    # clamped at A: x, y, z, rx, rz supported and ry held by the drive (rotation about y at stroke 0), so the
    # drive reaction is the root's bending moment
    return _beam_scene(
        L_E,
        W_E,
        T_E,
        n,
        supports=[{"node": "A", "dofs": ["x", "y", "z", "rx", "rz"]}],
        stroke={"kind": "rotation", "node": "A", "axis": [0, 1, 0], "start": -1, "stop": 1, "points": 3},
        **extra,
        loads=[{"node": "B", "force": [0, 0, -P]}],
    )


def _tip(P: float, n: int):
    an = Analysis(scene_from_dict(_elastica(P, n)))
    eq = reference_equilibrium(an.system, an.options)
    return eq.state.X[an.structure.master_names.index("B")], eq.drive_reaction


def test_elastica_tip_force_large_deflection():
    """A cantilever under a dead tip force at alpha^2 = P L^2 / EI = 3 (tip angle 56.5 deg) against Bisshopp
    and Drucker's elliptic-integral solution (tests/references.py: elastica_tip). Meshes of 10 and 20
    elements and their Richardson extrapolation (the beam converges at O(h^2), PHYSICS.md): the 20-element
    tip is within 1e-3 of the closed form (measured 3.7e-4 in x, 5.4e-4 in delta), the extrapolation within
    1e-4 (measured 1e-5; the test fails unless the error falls at second order towards the closed form). The drive reaction (the root moment)
    with the load applied is the load's moment about the root, -P x_tip (statics of the whole leaf), to the
    Newton tolerance."""
    P = 3.0 * EI_E / L_E**2
    x_ref, d_ref, _ = elastica_tip(3.0)
    (x10, _, z10), _ = _tip(P, 10)
    (x20, _, z20), m20 = _tip(P, 20)
    for got, ref, what in ((x20 / L_E, x_ref, "x/L"), (-z20 / L_E, d_ref, "delta/L")):
        assert abs(got - ref) <= 1e-3 * ref, f"20 elements: {what} {got:.7f}, Bisshopp-Drucker {ref:.7f}"
    xr, dr = (4 * x20 - x10) / 3 / L_E, -(4 * z20 - z10) / 3 / L_E
    assert abs(xr - x_ref) <= 1e-4 * x_ref, f"Richardson x/L {xr:.7f}, Bisshopp-Drucker {x_ref:.7f}"
    assert abs(dr - d_ref) <= 1e-4 * d_ref, f"Richardson delta/L {dr:.7f}, Bisshopp-Drucker {d_ref:.7f}"
    assert m20 == pytest.approx(-P * x20, rel=1e-8), "root moment with the load applied: -P x_tip"


def test_gravity_on_a_cantilever_is_the_uniform_load_deflection():
    """A cantilever under its own weight, small deflection: tip deflection q L^4 / (8 EI), q = rho A g
    (Euler-Bernoulli, Roark Table 8.1 case 2a). Cubic elements with the consistent load vector
    (model.elements.beam_gravity_spec) give the exact nodal deflection of the linear problem; the tolerance
    1e-5 is the geometric nonlinearity at delta/L ~ 1e-3 (relative effect of order (delta/L)^2) plus margin."""
    g = 9.81
    scene = _beam_scene(
        L_E,
        W_E,
        T_E,
        4,
        supports=[{"node": "A", "dofs": ["x", "y", "z", "rx", "rz"]}],
        stroke={"kind": "rotation", "node": "A", "axis": [0, 1, 0], "start": -1, "stop": 1, "points": 3},
        gravity=[0, 0, -g],
    )
    an = Analysis(scene_from_dict(scene))
    eq = reference_equilibrium(an.system, an.options)
    z = eq.state.X[an.structure.master_names.index("B")][2]
    q = 7800.0 * W_E * T_E * g
    ref = q * L_E**4 / (8 * EI_E)
    assert -z == pytest.approx(ref, rel=1e-5), f"tip deflection {-z:.6g}, q L^4 / 8EI = {ref:.6g}"
    # the root moment is the weight's moment about the root, -q L^2 / 2 (to the deflection's share)
    assert eq.drive_reaction == pytest.approx(-q * L_E**2 / 2, rel=1e-5)


# ------------------------------------------------------------------------------------- Euler column
L_C, W_C, T_C = 0.2, 0.01, 0.002
P_CR = math.pi**2 * E * (W_C * T_C**3 / 12) / L_C**2  # Euler load of a pinned-pinned column


def _column(P: float) -> dict:
    # pinned-pinned along x: A holds x, y, z (twist held by the drive about x), B holds y, z; inextensible
    # (rigid elongation), as the closed form assumes
    return _beam_scene(
        L_C,
        W_C,
        T_C,
        10,
        rigid=["elongation"],
        supports=[{"node": "A", "dofs": ["x", "y", "z"]}, {"node": "B", "dofs": ["y", "z"]}],
        stroke={"kind": "rotation", "node": "A", "axis": [1, 0, 0], "start": -1, "stop": 1, "points": 3},
        loads=[{"node": "B", "force": [-P, 0, 0]}],
    )


def test_column_frequency_falls_to_zero_at_the_euler_load():
    """A pinned-pinned column under a dead axial load: omega^2(P) / omega^2(0) = 1 - P / P_cr with P_cr =
    pi^2 EI / L^2 (the buckling and vibration modes are the same sine; exact also with rotary inertia:
    omega^2 = (EI k^4 - P k^2) / (rho A (1 + r^2 k^2))). 10 elements: the ratio's discretisation error is
    1.3e-5 at 0.95 P_cr and falls at fourth order (8e-7 with 20), hence 2e-5. Past P_cr the straight column
    is unstable: the curve stops at stroke 0."""
    f0 = Analysis(scene_from_dict(_column(0.0))).frequency_curve(np.array([0.0]), mesh_error=False).modes_hz[0, 0]
    for frac in (0.25, 0.5, 0.75, 0.95):
        c = Analysis(scene_from_dict(_column(frac * P_CR))).frequency_curve(np.array([0.0]), mesh_error=False)
        ratio = (c.modes_hz[0, 0] / f0) ** 2
        assert abs(ratio - (1 - frac)) <= 2e-5, f"P = {frac} P_cr: omega^2 ratio {ratio:.7f}, 1 - P/P_cr {1 - frac}"
    c = Analysis(scene_from_dict(_column(1.05 * P_CR))).frequency_curve(np.array([0.0, 0.5]), mesh_error=False)
    assert c.status == "truncated" and c.failures[0].reason == "unstable"


# ---------------------------------------------------------------------------------------- pendulum
L_P, W_P, T_P, M_P = 0.05, 0.01, 0.0002, 0.05


def _pendulum(g: float) -> dict:
    # a leaf hanging from A along -z with a bob of mass M_P (no rotary inertia) at its tip; the leaf's
    # density 1 kg/m^3 makes its mass 1e-5 of the bob's (the closed form has a massless leaf)
    return _beam_scene(
        L_P,
        W_P,
        T_P,
        10,
        axis=(0, 0, -1),
        density=1.0,
        bodies=[{"name": "bob", "mass": M_P, "center_of_mass": [0, 0, -L_P], "nodes": ["B"]}],
        supports=[{"node": "A", "dofs": ["x", "y", "z", "rx", "ry"]}],
        stroke={"kind": "rotation", "node": "A", "axis": [0, 0, 1], "start": -1, "stop": 1, "points": 3},
        gravity=[0, 0, -g],
    )


@pytest.mark.parametrize("g", [0.0, 9.81, 100.0])
def test_hanging_flexure_frequency_rises_with_gravity(g):
    """A bob hanging on a leaf: omega^2 = k / m with k the lateral stiffness of a cantilever under the
    bob's weight as tension (tests/references.py: tensioned_cantilever_stiffness; 4.13 Hz at g = 0, 4.79 Hz
    at 9.81, 8.71 Hz at 100 m/s^2). Tolerance 2e-5: the closed form neglects the leaf's stretch under the
    tension (T / EA = 1.2e-5 at 100 m/s^2) and its mass (1e-5 of the bob's); measured 2e-7 to 7e-6."""
    ref = math.sqrt(tensioned_cantilever_stiffness(M_P * g, E * W_P * T_P**3 / 12, L_P) / M_P) / (2 * math.pi)
    c = Analysis(scene_from_dict(_pendulum(g))).frequency_curve(np.array([0.0]), mesh_error=False)
    assert c.modes_hz[0, 0] == pytest.approx(ref, rel=2e-5)


# ----------------------------------------------------------------------------- loads along the stroke
def _driven(load: dict, points=5) -> dict:
    # the seed-like leaf driven by an end rotation about y at B (A clamped), with a load on B
    return _beam_scene(
        L_E,
        0.01,
        0.0005,
        6,
        supports=[{"node": "A"}],
        stroke={"kind": "rotation", "node": "B", "axis": [0, 1, 0], "start": 0, "stop": 20, "points": points},
        loads=[{"node": "B", **load}],
        modes=3,
    )


def test_a_ramp_is_the_constant_load_at_each_stroke_point():
    """A force ramped along the stroke gives, at the last stroke point, the frequencies and drive reaction
    of the same scene with that force constant (an independent solve: different continuation history).
    Tolerance 1e-8: both are converged equilibria of the same equations (Newton tolerance 1e-9)."""
    ramp = Analysis(scene_from_dict(_driven({"ramp": {"start": [0, 0, -0.5], "stop": [3.0, 0, -2.0]}})))
    c_ramp = ramp.frequency_curve(mesh_error=False)
    const = Analysis(scene_from_dict(_driven({"force": [3.0, 0, -2.0]}, points=3)))
    c_const = const.frequency_curve(np.array([0.0, 10.0, 20.0]), mesh_error=False)
    np.testing.assert_allclose(c_ramp.modes_hz[-1], c_const.modes_hz[-1], rtol=1e-8)
    assert c_ramp.drive_reaction[-1] == pytest.approx(c_const.drive_reaction[-1], rel=1e-8)
    # and the table form of the same ramp gives the same curve
    table = {"stroke": [0.0, 20.0], "force": [[0, 0, -0.5], [3.0, 0, -2.0]]}
    c_table = Analysis(scene_from_dict(_driven({"table": table}))).frequency_curve(mesh_error=False)
    np.testing.assert_allclose(c_table.modes_hz, c_ramp.modes_hz, rtol=1e-8)


def test_path_tangent_includes_the_load_rate():
    """The continuation tangent d xi / d s with a ramped load equals the central difference of the
    equilibria at s +- h (finite differences in tests only; h = 1e-4 rad: truncation ~h^2 ~ 1e-8, rounding
    1e-9 / h ~ 1e-5 of a tangent of order 1, hence 1e-4 relative to the tangent's largest entry)."""
    an = Analysis(scene_from_dict(_driven({"ramp": {"start": [0, 0, -0.5], "stop": [3.0, 0, -2.0]}})))
    sys, opts = an.system, an.options
    from flexopt.model.statics import solve_point

    eq0 = reference_equilibrium(sys, opts)
    s, h = 0.1, 1e-4
    eq = solve_point(sys, eq0.state, s, opts, 0.0)
    plus = solve_point(sys, eq.state, s + h, opts, s)
    minus = solve_point(sys, eq.state, s - h, opts, s)
    fd = (sys.difference(plus.state, eq.state) - sys.difference(minus.state, eq.state)) / (2 * h)
    scale = np.abs(eq.tangent).max()
    assert np.abs(eq.tangent - fd).max() <= 1e-4 * scale


def test_load_gradient_is_the_energy_gradient():
    """The loads' gradient (point load on a body's offset point, gravity on beams and bodies) is the gradient
    of the total energy including their potential (central differences along each DOF's chart direction,
    h = 1e-6 of its scale: agreement to 1e-6 of the largest entry)."""
    scene = _pendulum(9.81)
    scene["loads"] = [{"body": "bob", "point": [0.01, 0.0, -L_P], "force": [0.3, -0.2, 0.1]}]
    scene["gravity"] = [0.5, 0.2, -9.81]
    an = Analysis(scene_from_dict(scene))
    sys = an.system
    rng = np.random.default_rng(0)
    st = sys.update(sys.reference_state(), 1e-3 * rng.standard_normal(sys.n) * sys.scale)
    g = sys.evaluate(st).g
    fd = np.zeros(sys.n)
    for i in range(sys.n):
        e = np.zeros(sys.n)
        e[i] = 1e-6 * sys.scale[i]
        fd[i] = (sys.energy(sys.update(st, e)) - sys.energy(sys.update(st, -e))) / (2 * e[i])
    assert np.abs(g - fd).max() <= 1e-6 * np.abs(g).max()


# ------------------------------------------------------------------------------------ input and methods
@pytest.mark.parametrize(
    "load, words",
    [
        ({"node": "Q", "force": [1, 0, 0]}, "loads[0].node: unknown node 'Q'"),
        ({"node": "B", "force": [1, 0, 0], "ramp": {"start": [0, 0, 0], "stop": [1, 0, 0]}}, "exactly one of 'force'"),
        ({"node": "B", "point": [0, 0, 0], "force": [1, 0, 0]}, "'point' is for body loads"),
        ({"node": "B", "table": {"stroke": [5, 20], "force": [[0, 0, 0], [1, 0, 0]]}}, "extend the table"),
        (
            {"node": "B", "table": {"stroke": [0, 10, 20], "force": [[0, 0, 0], [1, 0, 0]]}},
            "one force per stroke value",
        ),
        ({"node": "B", "force": [1, 0, 0], "moment": [0, 0, 1]}, "exactly one of 'force', 'moment'"),
        ({"node": "B", "moment": [0, 0, 1], "kind": "force"}, "kind 'force' contradicts the moment given"),
        (
            {"node": "B", "table": {"stroke": [0, 20], "force": [[0, 0, 0], [1, 0, 0]], "moment": [[0, 0, 0]] * 2}},
            "exactly one of 'force' or 'moment' in a load table",
        ),
        ({"node": "B", "moment": [0, 1]}, "loads[0].moment[2]: required field is missing"),
    ],
)
def test_bad_loads_are_one_line_naming_the_field(load, words):
    scene = _driven({"force": [0, 0, 0]})
    scene["loads"] = [load]
    with pytest.raises(SceneError) as info:
        scene_from_dict(scene)
    assert words in str(info.value)


def test_a_moment_ramp_is_the_constant_moment_at_each_stroke_point():
    """A moment ramped along the stroke (kind 'moment') and the same moment as a table give, at the last stroke
    point, the frequencies and drive reaction of that moment held constant (independent solves; tolerance
    1e-8 as for forces). The moment is non-conservative in 3D: the general eigenproblem runs throughout."""
    ramp = {"kind": "moment", "ramp": {"start": [0, 0.0, 0], "stop": [0.002, -0.02, 0.001]}}
    c_ramp = Analysis(scene_from_dict(_driven(ramp))).frequency_curve(mesh_error=False)
    const = Analysis(scene_from_dict(_driven({"moment": [0.002, -0.02, 0.001]}, points=3)))
    c_const = const.frequency_curve(np.array([0.0, 10.0, 20.0]), mesh_error=False)
    np.testing.assert_allclose(c_ramp.modes_hz[-1], c_const.modes_hz[-1], rtol=1e-8)
    assert c_ramp.drive_reaction[-1] == pytest.approx(c_const.drive_reaction[-1], rel=1e-8)
    table = {"table": {"stroke": [0.0, 20.0], "moment": [[0, 0.0, 0], [0.002, -0.02, 0.001]]}}
    c_table = Analysis(scene_from_dict(_driven(table))).frequency_curve(mesh_error=False)
    np.testing.assert_allclose(c_table.modes_hz, c_ramp.modes_hz, rtol=1e-8)
    assert const.system.loads.nonconservative


def test_path_tangent_includes_a_follower_load_rate():
    """As test_path_tangent_includes_the_load_rate, for a ramped follower force and a moment (the tangent solves
    the unsymmetric Newton matrix)."""
    scene = _driven({"ramp": {"start": [0, 0, -0.5], "stop": [3.0, 0, -2.0]}, "follower": True})
    scene["loads"].append({"node": "B", "kind": "moment", "ramp": {"start": [0, 0, 0], "stop": [0, 0.01, 0.002]}})
    an = Analysis(scene_from_dict(scene))
    sys, opts = an.system, an.options
    from flexopt.model.statics import solve_point

    eq0 = reference_equilibrium(sys, opts)
    s, h = 0.1, 1e-4
    eq = solve_point(sys, eq0.state, s, opts, 0.0)
    plus = solve_point(sys, eq.state, s + h, opts, s)
    minus = solve_point(sys, eq.state, s - h, opts, s)
    fd = (sys.difference(plus.state, eq.state) - sys.difference(minus.state, eq.state)) / (2 * h)
    assert np.abs(eq.tangent - fd).max() <= 1e-4 * np.abs(eq.tangent).max()


def test_units_block_converts_loads_and_gravity():
    """A scene in mm with a force unit of kN: forces x 1000, gravity in mm/s^2 x 1e-3, points x 1e-3."""
    scene = _pendulum(9.81)
    scene["loads"] = [{"body": "bob", "point": [10.0, 0.0, -50.0], "force": [0.001, 0, 0]}]
    scene["gravity"] = [0, 0, -9810.0]
    scene["units"] = {"length": "mm", "force": "kN"}
    for n in scene["nodes"]:
        n["position"] = [1000 * v for v in n["position"]]
    scene["bodies"][0]["center_of_mass"] = [0, 0, -50.0]
    scene["elements"][0]["section"] = {"kind": "rectangular", "width": 10.0, "thickness": 0.2}
    scene["materials"][0].update(E=210e3 * 1e-3, G=79e3 * 1e-3, allowable_stress=1.0, density=1e-9)
    s = scene_from_dict(scene)
    assert s.gravity == pytest.approx((0, 0, -9.81))
    assert s.loads[0].force == pytest.approx((1.0, 0, 0)) and s.loads[0].point == pytest.approx((0.01, 0, -0.05))
    # moments are force x length: kN mm = N m; a moment ramp (kind 'moment') and table likewise
    scene["loads"] = [
        {"node": "B", "moment": [0, 0, 2.0], "follower": True},
        {"node": "B", "kind": "moment", "ramp": {"start": [0, 0, 0], "stop": [0, 3.0, 0]}},
        {"node": "B", "ramp": {"start": [0, 0, 0], "stop": [0, 3.0, 0]}},
    ]
    s = scene_from_dict(scene)
    assert s.loads[0].moment == pytest.approx((0, 0, 2.0)) and s.loads[0].follower
    assert s.loads[1].ramp.stop == pytest.approx((0, 3.0, 0)) and s.loads[1].is_moment
    assert s.loads[2].ramp.stop == pytest.approx((0, 3000.0, 0)) and not s.loads[2].is_moment


def test_fast_methods_refuse_a_loaded_scene_and_auto_runs_exact():
    an = Analysis(scene_from_dict(_pendulum(9.81)))
    with pytest.raises(FlexoptError, match="loads or gravity"):
        curve_with_method(an, "fd2", stroke=np.array([0.0, 0.5]))
    c = curve_with_method(an, "auto", stroke=np.array([0.0, 0.5]))
    assert c.solver["auto_method"] == "exact"


def test_design_sensitivities_take_gravity_and_refuse_followers():
    """Gravity and dead forces are in the design sensitivities' scope (tests/test_design.py checks them against
    finite differences); a follower load is not: one line naming it."""
    from flexopt.model.design import _check_scope

    scene = _pendulum(9.81)
    _check_scope(Analysis(scene_from_dict(scene)).structure)
    scene["loads"] = [{"node": "B", "force": [0.1, 0, 0], "follower": True}]
    with pytest.raises(FlexoptError, match=r"non-conservative load\(s\) loads\[0\] \(follower force on node 'B'\)"):
        _check_scope(Analysis(scene_from_dict(scene)).structure)


def test_stress_includes_the_load():
    """A small tip force (alpha^2 = 1e-4): the root's von Mises bound is the bending stress P L (t/2) / Iy
    (Euler-Bernoulli; the cubic elements carry the linear moment exactly); tolerance 1e-3 for the geometric
    nonlinearity (relative effect of order alpha^2) and the axial term's share (N/A, about 1e-4 here)."""
    P = 1e-4 * EI_E / L_E**2
    c = Analysis(scene_from_dict(_elastica(P, 4))).frequency_curve(np.array([0.0]), mesh_error=False)
    Iy = W_E * T_E**3 / 12
    assert c.max_von_mises["leaf"][0] == pytest.approx(P * L_E * (T_E / 2) / Iy, rel=1e-3)


# ------------------------------------------------------------------------ moments and follower loads
def _clamped(n: int, load: dict) -> dict:
    """The leaf of the elastica test clamped at A (the drive about y at A holds the root), loaded at B."""
    return _beam_scene(
        L_E,
        W_E,
        T_E,
        n,
        supports=[{"node": "A", "dofs": ["x", "y", "z", "rx", "rz"]}],
        stroke={"kind": "rotation", "node": "A", "axis": [0, 1, 0], "start": -1, "stop": 1, "points": 3},
        loads=[{"node": "B", **load}],
    )


def _tip_state(scene: dict, stress: bool = False):
    """Tip position / L, tip angle in the x-z plane (from x towards z) and the root moment at stroke 0 (and the
    leaf's largest von Mises stress, with ``stress``)."""
    from flexopt.model.analysis import von_mises

    an = Analysis(scene_from_dict(scene))
    eq = reference_equilibrium(an.system, an.options)
    i = an.structure.master_names.index("B")
    R = eq.state.R[i]
    out = eq.state.X[i] / L_E, math.atan2(R[2, 0], R[0, 0]), eq.drive_reaction
    return (*out, float(von_mises(an.structure, an.system, eq)[0])) if stress else out


def test_tip_moment_bends_a_quarter_circle():
    """A dead end moment M about -y bends the cantilever into a circular arc of radius EI / M (tests/
    references.py: tip_moment_arc), here a quarter circle (M L / EI = pi/2). The beam converges at O(h^2)
    (PHYSICS.md): the 20-element tip is within 1e-3 L (measured 6.6e-4 in x, 3.7e-4 in z), the tip angle
    within 2e-3 rad (measured 1.6e-3), and the Richardson extrapolation of 10 and 20 elements within 3e-5 L
    (measured 7.8e-6; it fails unless the error is second order towards the closed form). The root moment
    (the drive reaction) is M exactly (statics of the whole leaf, to the Newton tolerance). The stress is the
    pure-bending stress M (t/2) / Iy (Euler-Bernoulli; no axial force): the elements' curvature converges at
    O(h^2) too (3.1e-3 high with 10 elements, 7.7e-4 with 20), so the Richardson value is asserted within
    5e-5 (measured 5e-6). The discretisation error itself has a closed form: a chain of n elements bent into
    an arc carries M = EI (n / L) sin(theta / n) (tests/test_physics.py, from seed 002 eq. 2), so under the
    moment the tip angle is n asin(m / n) (asserted to 1e-12; measured 3e-16) and the tip lies on the arc of
    that angle (within 1e-6 L, the chain's fourth-order error; measured 7e-8). A follower moment gives the same
    planar equilibrium."""
    m = math.pi / 2
    M = m * EI_E / L_E
    xr, zr = tip_moment_arc(m)
    x10, _, _, s10 = _tip_state(_clamped(10, {"moment": [0, -M, 0]}), stress=True)
    x20, a20, m20, s20 = _tip_state(_clamped(20, {"moment": [0, -M, 0]}), stress=True)
    assert abs(x20[0] - xr) <= 1e-3 and abs(x20[2] - zr) <= 1e-3, f"20 elements: tip {x20}, arc ({xr}, {zr})"
    assert abs(a20 - m) <= 2e-3, f"tip angle {a20:.6f}, M L / EI = {m:.6f}"
    rich = (4 * x20 - x10) / 3
    assert abs(rich[0] - xr) <= 3e-5 and abs(rich[2] - zr) <= 3e-5, f"Richardson {rich}, arc ({xr}, {zr})"
    assert m20 == pytest.approx(M, rel=1e-9), "root moment with the moment applied: M"
    th = 20 * math.asin(m / 20)
    assert a20 == pytest.approx(th, rel=1e-12)
    assert np.hypot(x20[0] - tip_moment_arc(th)[0], x20[2] - tip_moment_arc(th)[1]) <= 1e-6
    sigma = M * (T_E / 2) / (W_E * T_E**3 / 12)
    assert (4 * s20 - s10) / 3 == pytest.approx(sigma, rel=5e-5)
    # a follower moment about y stays about y in this planar bending: the same equilibrium (to the Newton
    # tolerance), though solved with its own (unsymmetric) stiffness
    xf, af, mf = _tip_state(_clamped(20, {"moment": [0, -M, 0], "follower": True}))
    np.testing.assert_allclose(xf, x20, atol=1e-9)
    assert af == pytest.approx(a20, rel=1e-9) and mf == pytest.approx(m20, rel=1e-9)


@pytest.mark.slow
def test_tip_moment_rolls_the_cantilever_into_a_full_circle():
    """M L / EI = 2 pi: the arc closes, the tip returns to the root (tip_moment_arc(2 pi) = (0, 0)). The loads
    are applied in steps (model.statics.reference_equilibrium). The tip's distance from the closed form falls
    at second order (20 -> 40 elements: ratio 4.09, asserted between 3.5 and 4.5), is within 5e-3 L with 40
    elements (measured 4.1e-3: 9 degrees of arc per element) and the Richardson extrapolation within 5e-4 L
    (measured 2.6e-4, the third-order remainder at this coarse angle per element). The discrete closed form
    (see the quarter circle) holds to 1e-6 L (measured 8e-9): the 40-element chain overshoots to the tip
    angle 40 asin(2 pi / 40) = 2 pi + 0.0261."""
    m = 2 * math.pi
    M = m * EI_E / L_E
    ref = np.array([tip_moment_arc(m)[0], 0.0, tip_moment_arc(m)[1]])
    x20, _, m20 = _tip_state(_clamped(20, {"moment": [0, -M, 0]}))
    x40, _, _ = _tip_state(_clamped(40, {"moment": [0, -M, 0]}))
    e20, e40 = np.linalg.norm(x20 - ref), np.linalg.norm(x40 - ref)
    assert 3.5 <= e20 / e40 <= 4.5, f"error 20 elements {e20:.3e}, 40 elements {e40:.3e}: not second order"
    assert e40 <= 5e-3
    assert np.linalg.norm((4 * x40 - x20) / 3 - ref) <= 5e-4
    assert m20 == pytest.approx(M, rel=1e-9)
    xd, zd = tip_moment_arc(40 * math.asin(m / 40))
    assert np.hypot(x40[0] - xd, x40[2] - zd) <= 1e-6


def test_follower_force_elastica_against_an_independent_integration():
    """A tip force that follows the tip's rotation, perpendicular to the leaf at the reference (alpha^2 = P L^2
    / EI = 3, tip angle 80 deg against 56.5 for the dead force), against the elastica integrated by scipy's
    solve_bvp (tests/references.py: follower_elastica_tip, tolerance 1e-10). 20 elements: within 3e-3
    relative (measured 2.2e-3 in x, 9e-4 in z), tip angle within 5e-3 rad; the Richardson extrapolation of 10
    and 20 elements within 2e-4 relative (measured 3.5e-5; second-order convergence towards the integral).
    The root moment is the follower force's moment about the root, x F_z - z F_x with F = R_tip F_ref (as
    -P x_tip for the dead force above)."""
    P = 3.0 * EI_E / L_E**2
    xr, zr, ar = follower_elastica_tip(3.0)
    load = {"force": [0, 0, -P], "follower": True}
    x10, _, _ = _tip_state(_clamped(10, load))
    x20, a20, m20 = _tip_state(_clamped(20, load))
    assert abs(x20[0] / xr - 1) <= 3e-3 and abs(x20[2] / zr - 1) <= 3e-3, f"tip {x20}, integral ({xr}, {zr})"
    assert abs(a20 - ar) <= 5e-3, f"tip angle {a20:.6f}, integral {ar:.6f}"
    rich = (4 * x20 - x10) / 3
    assert abs(rich[0] / xr - 1) <= 2e-4 and abs(rich[2] / zr - 1) <= 2e-4, f"Richardson {rich}"
    F = P * np.array([math.sin(a20), -math.cos(a20)])  # (x, z) components of R_tip (0, -P)
    assert m20 == pytest.approx((x20[0] * F[1] - x20[2] * F[0]) * L_E, rel=1e-8)


def test_nonconservative_load_jacobian_is_exact():
    """The Newton matrix H + chart (model.assembly) is the exact Jacobian of the residual g under a follower
    force on a body's offset point, a dead moment on the body and a follower moment on a node: central
    differences of g along each DOF's chart direction (h = 1e-6 of its scale: truncation ~1e-12, rounding
    ~1e-10 of the largest entry), agreement to 1e-7 of the largest entry; the load stiffness is unsymmetric
    (asserted: antisymmetric part above 1e-3 of the load's entries)."""
    scene = _pendulum(9.81)
    scene["loads"] = [
        {"body": "bob", "point": [0.01, 0.0, -L_P], "force": [0.3, -0.2, 0.1], "follower": True},
        {"body": "bob", "moment": [0.002, -0.001, 0.003]},
        {"node": "B", "moment": [0.001, 0.002, -0.001], "follower": True},
    ]
    an = Analysis(scene_from_dict(scene))
    sys = an.system
    rng = np.random.default_rng(0)
    st = sys.update(sys.reference_state(), 0.2 * rng.standard_normal(sys.n) * sys.scale)
    ev = sys.evaluate(st)
    J = ev.H + ev.chart
    fd = np.zeros_like(J)
    for i in range(sys.n):
        e = np.zeros(sys.n)
        e[i] = 1e-6 * sys.scale[i]
        fd[:, i] = (sys.evaluate(sys.update(st, e)).g - sys.evaluate(sys.update(st, -e)).g) / (2 * e[i])
    assert np.abs(J - fd).max() <= 1e-7 * np.abs(J).max()
    sys.load_scale = 0.0
    K_load = ev.H - sys.evaluate(st).H
    assert np.abs(K_load - K_load.T).max() >= 1e-3 * np.abs(K_load).max()
    with pytest.raises(ValueError, match="no potential"):
        sys.energy(st)


# ------------------------------------------------------------------------------------------ Beck's column
L_B, W_B, T_B = 1.0, 0.002, 0.001
EI_B = E * W_B * T_B**3 / 12  # the weak plane (x-z) buckles and flutters first: EI_z = 4 EI_B


def _beck(P: float, n: int, follower: bool = True) -> dict:
    # a cantilever along x clamped at A (x, y, z, ry, rz supported; the twist held by the drive), a tip force
    # -P along x, tangential (follower) or dead; slender (L / t = 1000), so rotary inertia and the axial
    # shortening shift the loads by about (t / L)^2 / 12 ~ 1e-7 relative
    return _beam_scene(
        L_B,
        W_B,
        T_B,
        n,
        supports=[{"node": "A", "dofs": ["x", "y", "z", "ry", "rz"]}],
        stroke={"kind": "rotation", "node": "A", "axis": [1, 0, 0], "start": -1, "stop": 1, "points": 3},
        loads=[{"node": "B", "force": [-P, 0, 0], "follower": follower}],
        modes=4,
    )


def _onset(n: int, follower: bool, lo: float, hi: float, tol: float = 1e-6) -> float:
    """P L^2 / EI where the straight column loses stability: flutter (a complex pair, follower) or divergence
    (a negative eigenvalue, dead), by bisection on the eigen analysis at stroke 0 with the load scaled."""
    from flexopt.model.modal import modes_at
    from flexopt.model.statics import solve_point

    an = Analysis(scene_from_dict(_beck(EI_B / L_B**2, n, follower)))
    sys = an.system

    def unstable(p: float) -> bool:
        sys.load_scale = p  # the straight column is the equilibrium for any axial load
        eq = solve_point(sys, sys.reference_state(), 0.0, an.options, 0.0)
        m = modes_at(sys, eq, 4)
        return bool(len(m.complex_omega2)) if follower else bool(m.omega2[0] <= 0)

    assert unstable(hi) and not unstable(lo)
    while hi - lo > tol * lo:
        mid = (lo + hi) / 2
        lo, hi = (lo, mid) if unstable(mid) else (mid, hi)
    return (lo + hi) / 2


def test_beck_column_flutters_where_the_dead_load_column_diverges():
    """Beck's column: under a tangential (follower) tip force the straight cantilever loses stability by flutter,
    the two lowest frequencies of the weak plane meeting at P L^2 / EI = 20.051 (Beck 1952: 20.05; recomputed
    from the characteristic equation in tests/references.py: beck_flutter_load); under the same dead force it
    diverges at the Euler load pi^2 / 4 (a real eigenvalue through zero). Mesh convergence: the flutter load
    reads 20.0982, 20.0612, 20.0543, 20.0516, 20.0512 with 4, 6, 8, 12, 16 elements (relative errors 2.4e-3,
    5.1e-4, 1.7e-4, 3.4e-5, 1.1e-5: fourth order, the cubic elements' eigenvalue rate, from above); asserted:
    12 elements within 5e-5 and the ratio of the 6- and 12-element errors between 8 and 20 (measured 14.9;
    2^3 to 2^4.3). The Euler load with 12 elements within 2e-6 (measured 6.3e-7; 6.7e-6 with 6). The
    published 20.05 agrees with the recomputed value to its rounding (5e-3). Bisection to 1e-6."""
    p_ref = beck_flutter_load()
    assert abs(p_ref - BECK_FLUTTER_PUBLISHED) <= 5e-3
    e6 = _onset(6, True, 19.0, 21.0) / p_ref - 1
    e12 = _onset(12, True, 19.0, 21.0) / p_ref - 1
    assert 0 < e12 <= 5e-5, f"12 elements: flutter load {e12:+.2e} from the reference"
    assert 8 <= e6 / e12 <= 20, f"errors {e6:.2e} (6 elements), {e12:.2e} (12): not fourth order"
    euler = math.pi**2 / 4
    p_dead = _onset(12, False, 2.0, 3.0)
    assert abs(p_dead / euler - 1) <= 2e-6, f"dead load: divergence at {p_dead:.7f}, pi^2/4 = {euler:.7f}"
    # past the Euler load the follower column is still stable: no divergence, no flutter
    c = Analysis(scene_from_dict(_beck(10 * EI_B / L_B**2, 8))).frequency_curve(np.array([0.0]), mesh_error=False)
    assert c.status == "complete" and not c.warnings


def test_beck_column_frequencies_coalesce_and_the_flutter_is_reported():
    """Approaching the flutter load the two lowest weak-plane frequencies meet as the square root of the distance
    (a coalescence of two real eigenvalues): their gap at 1e-3 and 1e-5 below the onset has the ratio 10
    (asserted within 15 %: the next term of the expansion). Beyond it the curve reports the real eigenvalues
    only and says so in a warning naming the load."""
    from flexopt.model.modal import modes_at
    from flexopt.model.statics import solve_point

    p_f = _onset(6, True, 19.0, 21.0, tol=1e-9)
    an = Analysis(scene_from_dict(_beck(EI_B / L_B**2, 6)))
    sys = an.system
    gaps = []
    for d in (1e-3, 1e-5):
        sys.load_scale = p_f * (1 - d)
        eq = solve_point(sys, sys.reference_state(), 0.0, an.options, 0.0)
        w = np.sort(modes_at(sys, eq, 4).omega2)
        # the weak plane's pair: the two lowest omega^2 above the first (which stays apart, 16 Hz)
        gaps.append(w[2] - w[1])
    assert gaps[0] / gaps[1] == pytest.approx(10.0, rel=0.15)
    c = Analysis(scene_from_dict(_beck(1.01 * p_f * EI_B / L_B**2, 6))).frequency_curve(
        np.array([0.0]), mesh_error=False
    )
    (w,) = [w for w in c.warnings if w.message.startswith("flutter")]
    assert "loads[0] (follower force on node 'B')" in w.message
    assert "non-conservative: loads[0] (follower force on node 'B')" in c.conventions["loads"]


def test_divergence_under_nonconservative_loads_names_them():
    """A real eigenvalue through zero with a non-conservative load present (the dead-force column past pi^2/4
    EI/L^2 with a small follower force beside it) ends the curve as unstable, and the failure names the
    non-conservative load (never silent about the unsymmetric stiffness behind it)."""
    scene = _beck(1.1 * math.pi**2 / 4 * EI_B / L_B**2, 6, follower=False)
    scene["loads"].append({"name": "pusher", "node": "B", "force": [-1e-3 * EI_B / L_B**2, 0, 0], "follower": True})
    c = Analysis(scene_from_dict(scene)).frequency_curve(np.array([0.0]), mesh_error=False)
    assert c.status == "truncated" and c.failures[0].reason == "unstable"
    assert "loads[1] 'pusher' (follower force on node 'B')" in c.failures[0].message
    assert "divergence" in c.failures[0].message
