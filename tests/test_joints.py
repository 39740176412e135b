"""Ideal joints (issue 28, item 2): hinges and sliders as exact constraints, in statics, eigen analysis and the
exact-constraint diagnosis."""

from __future__ import annotations

import math

import numpy as np
import pytest
from flexopt.model.curve import Analysis
from flexopt.model.diagnosis import diagnose
from flexopt.model.errors import SceneError
from flexopt.model.io import scene_from_dict

STEEL = {"name": "steel", "E": 210e9, "G": 79e9, "density": 7800.0, "allowable_stress": 5e8}
# a nearly massless spring material (density 1 kg/m^3: its inertia is 1e-9 of the bodies')
LIGHT = {**STEEL, "name": "light", "density": 1.0}


def _curve(scene: dict, stroke=(0.0,)):
    return Analysis(scene_from_dict(scene)).frequency_curve(np.array(stroke, dtype=float), mesh_error=False)


# ---------------------------------------------------------------------------------------- hinged pendulum
G_, LB, J, D, M, IYY = 79e9, 0.05, 1e-12, 0.04, 0.2, 1e-4


def _pendulum(g: float) -> dict:
    # a body hinged at the origin about y, its centre of mass D below the pin, with a torsion spring: a beam
    # along the hinge axis from a clamp to the body (GJ / L about y; its other stiffness meets the hinge's
    # constraints), swinging under gravity; the drive (the body's rotation about y) is free in the eigen analysis
    return {
        "name": "hinged pendulum",
        "materials": [LIGHT],
        "nodes": [
            {"name": "G0", "position": [0, -LB, 0]},
            {"name": "P0", "position": [0, 0, 0]},
            {"name": "P1", "position": [0, 0, 0]},
        ],
        "bodies": [
            {
                "name": "bob",
                "mass": M,
                "center_of_mass": [0, 0, -D],
                "inertia": [[2e-4, 0, 0], [0, IYY, 0], [0, 0, 1.5e-4]],
                "nodes": ["P1"],
            }
        ],
        "elements": [
            {
                "kind": "beam",
                "name": "spring",
                "nodes": ["G0", "P1"],
                "material": "light",
                "section": {"kind": "general", "A": 1e-6, "Iy": 1e-12, "Iz": 1e-12, "J": J},
                "y_axis": [1, 0, 0],
                "segments": 2,
            }
        ],
        "joints": [{"kind": "hinge", "name": "pin", "nodes": ["P0", "P1"], "axis": [0, 1, 0]}],
        "supports": [{"node": "G0"}, {"node": "P0"}],
        "stroke": {
            "kind": "rotation",
            "body": "bob",
            "axis": [0, 1, 0],
            "start": -1,
            "stop": 1,
            "points": 3,
            "drive": "free",
        },
        "gravity": [0, 0, -g],
        "modes": 3,
    }


@pytest.mark.parametrize("g", [0.0, 9.81, -1.0])
def test_hinged_pendulum_with_torsion_spring(g):
    """omega^2 = (GJ/L + m g d) / (I_yy + m d^2) (a compound pendulum about a fixed pin with a torsion spring;
    g < 0: inverted, gravity softens it). The pin's stiffness comes from its multipliers' curvature (the
    hinge force m g times the offset of the pin from the body's centre of mass). Tolerance 1e-9: the spring's
    own inertia (density 1 kg/m^3) is 1e-10 of the body's; measured 4e-11."""
    ref = math.sqrt((G_ * J / LB + M * g * D) / (IYY + M * D * D)) / (2 * math.pi)
    c = _curve(_pendulum(g))
    assert c.mode_labels[0, 0] == "drive"
    assert c.modes_hz[0, 0] == pytest.approx(ref, rel=1e-9)


# ---------------------------------------------------------------------------------------------- slider
def test_slider_with_axial_spring():
    """A body on a slider along x, held by a truss spring along x: omega^2 = (EA/L) / (m + m_t/3) (the truss's
    consistent mass m_t/6 [[2, 1], [1, 2]] puts m_t/3 on the moving end; m_t = 2e-7 m); the slider's other
    five relative coordinates are rigid. Tolerance 1e-9: the same discrete model, to the eigen solver's
    rounding."""
    L, A, m = 0.1, 1e-6, 0.5
    scene = {
        "name": "slider",
        "materials": [LIGHT],
        "nodes": [
            {"name": "G", "position": [-L, 0, 0]},
            {"name": "S0", "position": [0, 0, 0]},
            {"name": "S1", "position": [0, 0, 0]},
        ],
        "bodies": [
            {
                "name": "carriage",
                "mass": m,
                "center_of_mass": [0, 0, 0.01],
                "inertia": [[1e-4, 0, 0], [0, 1e-4, 0], [0, 0, 1e-4]],
                "nodes": ["S1"],
            }
        ],
        "elements": [{"kind": "truss", "name": "spring", "nodes": ["G", "S1"], "material": "light", "area": A}],
        "joints": [{"kind": "slider", "name": "guide", "nodes": ["S0", "S1"], "axis": [1, 0, 0]}],
        "supports": [{"node": "G"}, {"node": "S0"}],
        "stroke": {
            "kind": "translation",
            "body": "carriage",
            "axis": [1, 0, 0],
            "start": -0.001,
            "stop": 0.001,
            "points": 3,
            "drive": "free",
        },
        "modes": 1,
    }
    ref = math.sqrt(210e9 * A / L / (m + 1.0 * A * L / 3)) / (2 * math.pi)
    c = _curve(scene)
    assert c.modes_hz[0, 0] == pytest.approx(ref, rel=1e-9)


# ------------------------------------------------------------------------------ four-bar, one flexible link
A_, B_, C_, D_ = 0.03, 0.1, 0.06, 0.1  # crank, coupler, rocker, ground


def _rocker_point(th: float) -> np.ndarray:
    """The coupler-rocker pin C of a four-bar at crank angle th (open branch): the intersection of the circles
    |C - B| = b and |C - D| = c (the closed-form position analysis)."""
    B = np.array([A_ * math.cos(th), A_ * math.sin(th)])
    v = np.array([D_, 0.0]) - B
    L = float(np.linalg.norm(v))
    x = (B_**2 - C_**2 + L**2) / (2 * L)
    e = v / L
    return B + x * e + math.sqrt(B_**2 - x**2) * np.array([-e[1], e[0]])


TH0 = math.pi / 2


def _four_bar(rigid=(), segments=2, stroke=True) -> dict:
    B0 = [A_ * math.cos(TH0), A_ * math.sin(TH0), 0.0]
    C0 = [*_rocker_point(TH0), 0.0]
    return {
        "name": "four-bar",
        "materials": [STEEL],
        "nodes": [
            {"name": n, "position": p}
            for n, p in (
                ("A0", [0, 0, 0]),
                ("A1", [0, 0, 0]),
                ("B1", B0),
                ("B2", B0),
                ("C1", C0),
                ("C2", C0),
                ("D0", [D_, 0, 0]),
                ("D1", [D_, 0, 0]),
            )
        ],
        "bodies": [
            {
                "name": "crank",
                "mass": 0.05,
                "center_of_mass": [B0[0] / 2, B0[1] / 2, 0],
                "inertia": [[1e-5, 0, 0], [0, 1e-5, 0], [0, 0, 1e-5]],
                "nodes": ["A1", "B1"],
            },
            {
                "name": "rocker",
                "mass": 0.08,
                "center_of_mass": [(C0[0] + D_) / 2, C0[1] / 2, 0],
                "inertia": [[2e-5, 0, 0], [0, 2e-5, 0], [0, 0, 2e-5]],
                "nodes": ["C1", "D1"],
            },
        ],
        "elements": [
            {
                "kind": "beam",
                "name": "coupler",
                "nodes": ["B2", "C2"],
                "material": "steel",
                "section": {"kind": "rectangular", "width": 0.005, "thickness": 0.002},
                "y_axis": [0, 0, 1],
                "segments": segments,
                "rigid": list(rigid),
            }
        ],
        "joints": [
            {"name": f"j{k}", "nodes": list(pair), "axis": [0, 0, 1]}
            for k, pair in (("A", ("A0", "A1")), ("B", ("B1", "B2")), ("C", ("C1", "C2")), ("D", ("D0", "D1")))
        ],
        "supports": [{"node": "A0"}, {"node": "D0"}],
        "stroke": {"kind": "rotation", "body": "crank", "axis": [0, 0, 1], "start": 0, "stop": 40, "points": 5}
        if stroke
        else None,
        "modes": 3,
    }


def test_four_bar_with_a_flexible_coupler_follows_the_closed_form_kinematics():
    """Four hinges and a flexible coupler pinned at both ends: with no load the coupler carries no force, so
    the rocker pin follows the rigid four-bar's position analysis (circle intersection) at every crank angle,
    to the Newton tolerance (1e-9 of the 0.1 m links: 1e-10 m); and the curve has no loss of stability."""
    an = Analysis(scene_from_dict(_four_bar()))
    seen: dict[float, object] = {}
    curve = an.frequency_curve(mesh_error=False, visit=lambda eq, modes, labels: seen.__setitem__(eq.stroke, eq))
    assert curve.status == "complete" and len(seen) == 5
    s = an.structure
    i = s.node_names.index("C1")
    for stroke, eq in seen.items():
        m = s.node_master[i]
        x = eq.state.X[m] + eq.state.R[m] @ s.node_offset[i]
        assert np.abs(x[:2] - _rocker_point(TH0 + stroke)).max() <= 1e-10, f"crank {math.degrees(stroke):.1f} deg"
        assert abs(x[2]) <= 1e-12


def test_four_bar_diagnosis_counts_the_kinematic_pairs():
    """Declared partition with the coupler's elongation rigid (one segment): rows are the four hinges' five
    constrained coordinates (20) and the elongation (21); columns the crank without its drive (5), the rocker
    (6) and the coupler's end nodes (12): 23. By hand: the rocker's swing is fixed by the elongation, so D_cc
    has full row rank 21 (statically determinate) and two kinematic modes, the coupler ends' spins about
    their pins (its bending is flexible, not a row)."""
    d = diagnose(scene_from_dict(_four_bar(rigid=["elongation"], segments=1)))
    assert (len(d.rows), len(d.columns), d.rank) == (21, 23, 21)
    assert len(d.static_modes) == 0 and len(d.kinematic_modes) == 2
    assert sum(r.startswith("jA.") for r in d.rows) == 5 and "jA.about_axis" not in d.rows
    spins = sorted(node for mode in d.kinematic_modes for node, v in mode.items() if abs(v["rotation"][2]) > 0.5)
    assert spins == ["B2", "C2"]


@pytest.mark.parametrize(
    "change, words",
    [
        (
            lambda s: s["joints"].append({"name": "jX", "nodes": ["A1", "B1"], "axis": [0, 0, 1]}),
            "both nodes of joint 'jX' are carried by body 'crank'",
        ),
        (lambda s: s["joints"].append({"name": "jY", "nodes": ["A0", "Q"], "axis": [0, 0, 1]}), "unknown node 'Q'"),
        (lambda s: s["joints"].append({"name": "jZ", "nodes": ["A0", "A0"], "axis": [0, 0, 1]}), "to itself"),
        (
            lambda s: s["joints"].append({"name": "coupler", "nodes": ["A0", "D0"], "axis": [0, 0, 1]}),
            "also an element's name",
        ),
        (lambda s: s["joints"].append({"name": "jW", "nodes": ["A0", "D0"], "axis": [0, 0, 0]}), "zero vector"),
    ],
)
def test_bad_joints(change, words):
    scene = _four_bar()
    change(scene)
    with pytest.raises(SceneError, match=words):
        scene_from_dict(scene)
