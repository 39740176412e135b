"""Design sensitivities (model/design.py) against finite differences of the whole pipeline.

Each finite difference rebuilds the scene from the template, solves the equilibrium at the same stroke and
solves the eigenproblem again: an independent computation that shares none of the derivative code.
Central differences with a step of 1e-3 of the parameter: truncation error ~ (h/p)^2 times the relative
curvature, measured below 3e-5 on these cases, and rounding noise ~ 1e-9 (solver tolerance) / 1e-3 =
1e-6; the tolerance 2e-4 (relative to |value| / |parameter|) sits above both and far below the size of any
missing term (a dropped mass or geometric-stiffness derivative changes results by 1e-2 or more).
"""

from __future__ import annotations

import numpy as np
import pytest
from flexopt.model import Analysis
from flexopt.model.analysis import beam_end_stresses
from flexopt.model.design import point_sensitivity, structure_derivative, trace_template
from flexopt.model.elements import beam_segment_design
from flexopt.model.errors import FlexoptError
from flexopt.model.structure import compile_scene
from flexopt.model.templates import TEMPLATES

H_REL = 1e-3
TOL = 2e-4


def _at(name: str, params: dict, design: list[str], s0: float, sens: bool, extra: dict | None = None) -> dict:
    ds = trace_template(name, params, design, extra)
    an = Analysis(ds.scene)
    target = float(ds.scene.stroke.to_internal(np.array([s0]))[0])
    out: dict = {}

    def visit(eq, modes, labels):
        if abs(eq.stroke - target) > 1e-12:
            return
        # the four lowest by value (not by tracked branch: tracking along the stroke may pair crossing
        # branches differently in the perturbed designs, while the sorted eigenvalues are what changes smoothly)
        which = list(np.argsort(modes.omega2)[:4])
        out["lam"] = modes.omega2[which].copy()
        out["vm"] = beam_end_stresses(an.structure, an.system, eq)
        out["reaction"] = eq.drive_reaction
        if sens:
            d = [structure_derivative(an.structure, ds.scene_dict, dd) for dd in ds.dscene]
            out["ps"] = point_sensitivity(an.system, eq, modes, which, d)

    an.frequency_curve(stroke=np.array([s0]), visit=visit)
    assert "lam" in out, f"{name}: the stroke {s0} was not reached"
    return out


CASES = [
    ("leaf-spring", ["thickness", "length", "width"], 30.0),
    ("cross-spring-pivot", ["length", "thickness", "body_mass", "body_offset"], 30.0),
    ("parallel-leaf-spring", ["length", "thickness", "spacing", "body_mass"], 0.008),
    ("wire-guide-5", ["wire_length", "wire_diameter", "body_mass"], 0.004),  # drive free in the eigenproblem
]


@pytest.mark.parametrize("name,design,s0", CASES, ids=[c[0] for c in CASES])
def test_frequency_stress_and_reaction_derivatives_match_finite_differences(name, design, s0):
    base = {k: TEMPLATES[name][1][k] for k in design}
    r0 = _at(name, base, design, s0, True)
    ps = r0["ps"]
    i = np.unravel_index(np.argmax(r0["vm"]), r0["vm"].shape)
    for j, k in enumerate(design):
        h = H_REL * base[k]
        rp = _at(name, {**base, k: base[k] + h}, design, s0, False)
        rm = _at(name, {**base, k: base[k] - h}, design, s0, False)
        fd = (rp["lam"] - rm["lam"]) / (2 * h)
        scale = np.abs(r0["lam"]) / base[k]
        err = np.abs(ps.dlam[j] - fd) / scale
        assert err.max() < TOL, f"{name} d lambda / d {k}: exact {ps.dlam[j]}, central differences {fd}"
        fd_vm = (rp["vm"][i] - rm["vm"][i]) / (2 * h)
        assert abs(ps.dvm[j][i] - fd_vm) < TOL * r0["vm"][i] / base[k], f"{name} d sigma / d {k}"
        fd_r = (rp["reaction"] - rm["reaction"]) / (2 * h)
        assert abs(ps.dreaction[j] - fd_r) < TOL * abs(r0["reaction"]) / base[k], f"{name} d reaction / d {k}"


#: payloads: gravity on every mass (the body's weight, each segment's), a dead force at an offset point of the
#: body and one on a leaf's tip node, large enough that dropping any load term changes a derivative by far more
#: than the tolerance (asserted below)
LOADED = [
    (
        "cross-spring-pivot",
        ["length", "thickness", "body_mass", "body_offset"],
        20.0,
        {
            "gravity": [0.0, -30.0, 0.0],
            "loads": [{"body": "rotor", "point": [0.01, 0.03, 0.0], "force": [0.5, -2.0, 0.3]}],
        },
    ),
    (
        "leaf-spring",
        ["thickness", "length", "width"],
        20.0,
        {"gravity": [0.0, 0.0, -200.0], "loads": [{"node": "tip", "force": [-3.0, 0.0, -0.2]}]},
    ),
    (
        "parallel-leaf-spring",
        ["length", "thickness", "spacing", "body_mass"],
        0.006,
        {"gravity": [-40.0, 0.0, 0.0]},
    ),
]


@pytest.mark.parametrize("name,design,s0,extra", LOADED, ids=[c[0] for c in LOADED])
def test_derivatives_under_gravity_and_dead_loads_match_finite_differences(name, design, s0, extra):
    """As above with a payload: gravity on the body and the leaves and dead forces (model.loads), through the
    load kernels' directional derivatives (model.design, step 6). Same step and tolerance. The loads matter:
    the derivatives without them differ from these by more than 50 times the tolerance (asserted); dropping
    the loads' gradient derivative fails every case (by 7x to 280x the tolerance), dropping their Hessian
    derivative the pivot's (its force at an offset point of the body: 6.5x)."""
    base = {k: TEMPLATES[name][1][k] for k in design}
    r0 = _at(name, base, design, s0, True, extra)
    bare = _at(name, base, design, s0, True)["ps"]
    ps = r0["ps"]
    i = np.unravel_index(np.argmax(r0["vm"]), r0["vm"].shape)
    gap = 0.0
    for j, k in enumerate(design):
        h = H_REL * base[k]
        rp = _at(name, {**base, k: base[k] + h}, design, s0, False, extra)
        rm = _at(name, {**base, k: base[k] - h}, design, s0, False, extra)
        fd = (rp["lam"] - rm["lam"]) / (2 * h)
        scale = np.abs(r0["lam"]) / base[k]
        err = np.abs(ps.dlam[j] - fd) / scale
        assert err.max() < TOL, f"{name} d lambda / d {k}: exact {ps.dlam[j]}, central differences {fd}"
        gap = max(gap, float((np.abs(bare.dlam[j] - ps.dlam[j]) / scale).max()))
        fd_vm = (rp["vm"][i] - rm["vm"][i]) / (2 * h)
        assert abs(ps.dvm[j][i] - fd_vm) < TOL * r0["vm"][i] / base[k], f"{name} d sigma / d {k}"
        fd_r = (rp["reaction"] - rm["reaction"]) / (2 * h)
        assert abs(ps.dreaction[j] - fd_r) < TOL * abs(r0["reaction"]) / base[k], f"{name} d reaction / d {k}"
    assert gap > 50 * TOL, f"{name}: the loads change the derivatives by only {gap:.2e}"


def test_nonconservative_loads_are_outside_the_design_scope():
    extra = {"loads": [{"node": "tip", "force": [0.0, 0.0, -1.0], "follower": True}]}
    ds = trace_template("leaf-spring", {}, ["thickness"], extra)
    with pytest.raises(FlexoptError, match="non-conservative load"):
        structure_derivative(compile_scene(ds.scene), ds.scene_dict, ds.dscene[0])


@pytest.mark.parametrize("name", ["leaf-spring", "cross-spring-pivot", "parallel-leaf-spring"])
def test_design_kernel_reproduces_the_structure_arrays(name):
    """The segment-constant kernel evaluates the same formulas as compile_scene: identical numbers."""
    an = Analysis(trace_template(name, {}, ["thickness"]).scene)
    s = an.structure
    scene = s.scene
    pos = {n.name: np.array(n.position) for n in scene.nodes}
    mats = {m.name: m for m in scene.materials}
    for ie, el in enumerate(scene.elements):
        rows = np.flatnonzero(s.beam_member == ie)
        m = mats[el.material]
        x = np.concatenate(
            [
                pos[el.nodes[0]],
                pos[el.nodes[1]],
                el.y_axis,
                [el.section.width, el.section.thickness, m.E, m.G, m.density],
            ]
        )
        out = np.asarray(beam_segment_design(el.section.warping)(x, el.segments)[0]).ravel()
        np.testing.assert_allclose(
            s.beam_const[rows][:, :15], np.tile(out[:15], (len(rows), 1)), rtol=1e-14, atol=1e-300
        )
        np.testing.assert_allclose(s.beam_mass[rows], out[15], rtol=1e-14)
        np.testing.assert_allclose(s.beam_stress[rows], np.tile(out[25:32], (len(rows), 1)), rtol=1e-14)


def test_scenes_outside_the_scope_get_a_clear_error():
    """Trusses are outside the sensitivities' scope: a clear error, not a wrong number."""
    ds = trace_template("truss12", {}, ["height"])
    with pytest.raises(FlexoptError, match="rectangular sections"):
        structure_derivative(compile_scene(ds.scene), ds.scene_dict, ds.dscene[0])


def test_unknown_design_parameter_is_named():
    with pytest.raises(FlexoptError, match="no parameter 'thicknes'"):
        trace_template("leaf-spring", {}, ["thicknes"])


def test_gradient_only_jvp_kernel_equals_the_full_kernel() -> None:
    """The implicit-function step uses a kernel for ``dg`` alone (model.elements.beam_input_jvp_gradient); it
    must give the full kernel's first 12 outputs exactly (the same forward derivative of the same
    expressions). Reference: the full JVP kernel on the same random inputs."""
    from flexopt.model import elements as el
    from flexopt.model.kernels import compiled
    from flexopt.model.templates import template

    rng = np.random.default_rng(3)
    full, grad = compiled(el.beam_jvp_spec()), compiled(el.beam_jvp_gradient_spec())
    sys_ = Analysis(template("cross-spring-pivot")).system
    sys_.fill_inputs(sys_.reference_state())
    a = np.hstack([sys_.beam_in, rng.standard_normal(sys_.beam_in.shape)])
    assert np.array_equal(grad(a), full(a)[:, :12])
    assert np.abs(grad(a)).max() > 0


def test_the_scene_trace_is_kept_per_candidate_gives_a_fresh_traces_numbers_and_is_bounded() -> None:
    """trace_template keeps the traced scene Jacobian per (template, fixed parameters, design names): another
    design of the same candidate reuses it with exactly the numbers of a fresh trace (reference: the same call
    after the store is emptied); a fixed parameter's other value is another trace; the store keeps the most
    recent SCENE_JAC_ENTRIES."""
    from flexopt.model import design

    names = ["length", "thickness"]
    base = {"length": 0.05, "thickness": 3e-4}
    moved = {"length": 0.055, "thickness": 3.2e-4}
    design._SCENE_JAC.clear()
    trace_template("cross-spring-pivot", base, names)
    kept = trace_template("cross-spring-pivot", moved, names)
    assert len(design._SCENE_JAC) == 1, "another design of the same candidate: the same trace"
    design._SCENE_JAC.clear()
    fresh = trace_template("cross-spring-pivot", moved, names)
    assert kept.dscene == fresh.dscene and kept.scene_dict == fresh.scene_dict
    assert any(v != 0 for v in kept.dscene[0]["nodes"][-1]["position"]), "a derivative that is not all zeros"
    trace_template("cross-spring-pivot", {**moved, "width": 0.012}, names)
    assert len(design._SCENE_JAC) == 2, "another fixed width: another trace"
    for i in range(design.SCENE_JAC_ENTRIES + 5):
        trace_template("cross-spring-pivot", {**base, "width": 0.01 + 1e-4 * i}, names)
    assert len(design._SCENE_JAC) == design.SCENE_JAC_ENTRIES


def test_structure_derivatives_of_every_direction_equal_each_directions_own() -> None:
    """structure_derivatives evaluates the segment formulas' Jacobians once for all directions: the same numbers
    as structure_derivative direction by direction (reference: that per-direction call)."""
    from dataclasses import fields

    from flexopt.model.design import structure_derivatives

    ds = trace_template("cross-spring-pivot", {}, ["length", "thickness", "width", "body_mass"])
    s = compile_scene(ds.scene)
    together = structure_derivatives(s, ds.scene_dict, ds.dscene)
    assert len(together) == 4
    for d, one in zip(ds.dscene, together):
        alone = structure_derivative(s, ds.scene_dict, d)
        for f in fields(alone):
            a, b = getattr(alone, f.name), getattr(one, f.name)
            assert np.array_equal(a, b) if isinstance(a, np.ndarray) else a == b, f.name
    assert np.abs(together[1].beam_const).max() > 0, "the thickness changes the beams' constants"
