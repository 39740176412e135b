"""The optimiser's rotational hinge families (model/templates.py): converged curves, independent checks,
traceability and exact design derivatives."""

from __future__ import annotations

import itertools

import casadi as ca
import numpy as np
import pytest
from flexopt.model import DESIGN_SPACES, Analysis, template
from flexopt.model.modal import modes_at
from flexopt.model.statics import solve_point
from flexopt.model.templates import TEMPLATES

from tests.helpers import coarse
from tests.test_design import H_REL, TOL, _at

FAMILIES = sorted(DESIGN_SPACES)
MIRROR = ["cross-spring-pivot", "cartwheel-hinge", "double-cross-hinge"]  # even in the stroke by symmetry


@pytest.mark.parametrize("name", FAMILIES)
def test_default_curve_converges_over_the_stroke(name):
    c = Analysis(template(name)).frequency_curve()
    assert c.status == "complete", c.failures
    assert c.stroke[0] == -45.0 and c.stroke[-1] == 45.0
    assert np.all(c.parasitic_hz > 0)


@pytest.mark.parametrize("name", MIRROR)
def test_mirror_symmetric_families_have_even_curves(name):
    """A mirror x -> -x maps the design onto itself and the stroke onto its negative: f(s) = f(-s) to the
    equilibrium tolerance (relative 1e-9 increments; 1e-6 on frequencies leaves a wide margin)."""
    ph = Analysis(template(name, points=31, **coarse(name))).frequency_curve().parasitic_hz  # any mesh
    assert np.max(np.abs(ph - ph[::-1])) <= 1e-6 * ph.max()


def _reference_modes(name: str, drive: str, k: int = 3, **kw) -> np.ndarray:
    an = Analysis(template(name, **kw))
    eq = solve_point(an.system, an.system.reference_state(), 0.0, an.options, 0.0)
    return modes_at(an.system, eq, k, drive).hz


def test_cross_pivot_drive_frequency_matches_wittrick():
    """Drive mode of the cross-spring pivot with the drive free, crossing at the midpoints: rotational
    stiffness 2 EI/L (Wittrick 1948, 'The theory of symmetrical crossed flexure pivots'; each leaf EI/L)
    against the rotor's inertia about the axis, J = m r^2/2 + m h^2. The leaves' own inertia (under 1 % of
    J here) and the finite centre-shift stiffness lower the model's value slightly: within 3 %."""
    p = TEMPLATES["cross-spring-pivot"][1]
    EI = p["E"] * p["width"] * p["thickness"] ** 3 / 12
    h = np.cos(np.radians(p["angle"] / 2)) * p["length"] / 2 + p["body_offset"]
    J = p["body_mass"] * (p["body_radius"] ** 2 / 2 + h**2)
    f_ref = np.sqrt(2 * EI / p["length"] / J) / (2 * np.pi)
    f = _reference_modes("cross-spring-pivot", "free", 1)[0]
    assert 0.97 < f / f_ref <= 1.0 + 1e-6, (f, f_ref)


def test_double_cross_intermediate_body_mode():
    """With the rotor locked, the double cross hinge's lowest mode is the intermediate body turning
    between two crossed stages in parallel: stiffness 4 EI/L (two stages of 2 EI/L, Wittrick) on the body's
    inertia m r^2/2 gives the upper bound f_ref; the leaves' inertia (two halves of four leaves, about a
    fifth of the body's) lowers it: 0.8 < f / f_ref <= 1."""
    p = TEMPLATES["double-cross-hinge"][1]
    EI = p["E"] * p["width"] * p["thickness"] ** 3 / 12
    J = p["mid_mass"] * p["body_radius"] ** 2 / 2
    f_ref = np.sqrt(4 * EI / p["length"] / J) / (2 * np.pi)
    f = _reference_modes("double-cross-hinge", "locked", 1)[0]
    assert 0.8 < f / f_ref <= 1.0 + 1e-6, (f, f_ref)


@pytest.mark.parametrize("name", FAMILIES)
def test_families_are_traceable(name):
    """Called with CasADi symbols the template gives symbolic scene numbers, numerically identical."""
    fn, defaults = TEMPLATES[name]
    names = list(DESIGN_SPACES[name])
    sym = ca.SX.sym("p", len(names))
    traced = fn({**defaults, **{k: sym[i] for i, k in enumerate(names)}})
    pos = ca.vertcat(*[ca.SX(c) for n in traced["nodes"] for c in n["position"]])
    val = ca.Function("f", [sym], [pos])([defaults[k] for k in names]).full().ravel()
    ref = np.array([c for n in fn(defaults)["nodes"] for c in n["position"]], float)
    np.testing.assert_allclose(val, ref, rtol=0, atol=1e-15)
    J = ca.Function("J", [sym], [ca.jacobian(pos, sym)])([defaults[k] for k in names]).full()
    for i, k in enumerate(names):
        if k in ("length", "angle", "crossing"):
            assert np.abs(J[:, i]).max() > 0, f"{name}: node positions do not depend on '{k}'"


@pytest.mark.parametrize(
    "name,param",
    [
        ("cartwheel-hinge", "angle"),
        ("three-fold-cross-hinge", "crossing"),
        ("double-cross-hinge", "length"),
        ("cross-spring-pivot", "angle"),
    ],
)
def test_design_derivative_of_new_parameters(name, param):
    """Exact frequency derivative against central differences of the whole pipeline (tests/test_design.py
    explains the step and the tolerance). Modes closer than 1 % (the three-fold hinge's symmetric pair, in
    an avoided crossing) are compared by their sum: within the finite-difference step their branches
    exchange character, so only the trace of the pair is smooth (its exact derivative is the sum)."""
    base = {param: TEMPLATES[name][1][param]}
    mesh = coarse(name)  # exact against finite differences on one mesh: any mesh
    r0 = _at(name, {**mesh, **base}, [param], 30.0, True)
    h = H_REL * base[param]
    rp = _at(name, {**mesh, param: base[param] + h}, [param], 30.0, False)
    rm = _at(name, {**mesh, param: base[param] - h}, [param], 30.0, False)
    lam = r0["lam"]
    groups: list[list[int]] = []
    for i in np.argsort(lam):
        if groups and lam[i] - lam[groups[-1][-1]] < 1e-2 * lam[i]:
            groups[-1].append(int(i))
        else:
            groups.append([int(i)])
    for g in groups:
        exact = r0["ps"].dlam[0][g].sum()
        fd = (rp["lam"][g].sum() - rm["lam"][g].sum()) / (2 * h)
        assert abs(exact - fd) < TOL * lam[g].sum() / base[param], (name, param, g, exact, fd)


@pytest.mark.slow
@pytest.mark.parametrize("name", FAMILIES)
def test_design_box_corners_converge(name):
    """The two opposite corners of the box and the corners of (length, thickness) at a mid design: every
    curve converges over +-45 deg (31 points)."""
    box = DESIGN_SPACES[name]
    mid = {k: 0.5 * (lo + hi) for k, (lo, hi) in box.items()}
    designs = [{k: lo for k, (lo, _) in box.items()}, {k: hi for k, (_, hi) in box.items()}]
    for L, t in itertools.product(box["length"], box["thickness"]):
        designs.append({**mid, "length": L, "thickness": t})
    for d in designs:
        c = Analysis(template(name, points=31, **coarse(name), **d)).frequency_curve()  # continuation: any mesh
        assert c.status == "complete", (name, d, c.failures)
