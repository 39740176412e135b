"""Shear deformation of the beam (a general section's ``shear_y``, ``shear_z``: SPACAR's ESTIFF Sy, Sz) against
Timoshenko's closed form for a cantilever, and carried through a SPACAR .dat import and export."""

from __future__ import annotations

import numpy as np
import pytest
from flexopt.model.curve import Analysis
from flexopt.model.io import scene_from_dict
from flexopt.model.spacar import read_dat, write_dat
from flexopt.model.statics import reference_equilibrium

# A stocky steel bar 10 x 10 mm, 30 mm long (L/h = 3, where shear matters): E 210 GPa, G 80 GPa,
# k = 5/6 (Timoshenko's coefficient of a rectangle); SPACAR's shear flexibility S = E I / (k G A).
E, G, K = 210e9, 80e9, 5.0 / 6.0
B = 0.01
A, I = B * B, B**4 / 12
L = 0.03
S = E * I / (K * G * A)
P = 100.0  # N: tip deflection / L about 2e-4, so geometric nonlinearity is of order 4e-8


def _cantilever(n: int, shear: float, direction: str = "z") -> dict:
    force = [0.0, 0.0, -P] if direction == "z" else [0.0, -P, 0.0]
    section = {"kind": "general", "A": A, "Iy": I, "Iz": I, "J": 0.1406 * B**4, "shear_y": shear, "shear_z": shear}
    return {
        "name": "timoshenko",
        "materials": [{"name": "steel", "E": E, "G": G, "density": 7800.0, "allowable_stress": 1e9}],
        "nodes": [{"name": "A", "position": [0, 0, 0]}, {"name": "B", "position": [L, 0, 0]}],
        "elements": [
            {
                "kind": "beam",
                "name": "bar",
                "nodes": ["A", "B"],
                "material": "steel",
                "section": section,
                "y_axis": [0, 1, 0],
                "segments": n,
            }
        ],
        # clamped at A; its rotation about y held by the drive at stroke 0
        "supports": [{"node": "A", "dofs": ["x", "y", "z", "rx", "rz"]}],
        "stroke": {"kind": "rotation", "node": "A", "axis": [0, 1, 0], "start": -1, "stop": 1, "points": 3},
        "loads": [{"node": "B", "force": force}],
    }


def _tip(scene: dict) -> np.ndarray:
    """Equilibrium position of the node at (L, 0, 0) (named B here, n3 once imported)."""
    sc = scene_from_dict(scene)
    tip = next(nd.name for nd in sc.nodes if nd.position[0] == L)
    an = Analysis(sc)
    eq = reference_equilibrium(an.system, an.options)
    return eq.state.X[an.structure.master_names.index(tip)]


@pytest.mark.parametrize("n", [1, 3])
@pytest.mark.parametrize("direction", ["z", "y"])
def test_cantilever_tip_deflection_is_timoshenkos(n, direction):
    """Tip deflection under a tip force: P L^3 / (3 E I) + P L / (k G A) (Timoshenko beam, closed form; the
    shear term is 8.75 % of the bending term here), in both bending planes (z: eps3, eps4 with Sy; y: eps5,
    eps6 with Sz) and for 1 and 3 elements (the shear-deformable element is exact for end loads, so the mesh
    does not matter). Tolerance 1e-6: geometric nonlinearity at this load is of order (delta/L)^2 = 4e-8 and
    Newton's tolerance 1e-10; without shear the deflection is 8 % short, so the test can fail."""
    k = 2 if direction == "z" else 1
    ref = P * L**3 / (3 * E * I) + P * L / (K * G * A)
    got = -_tip(_cantilever(n, S, direction))[k]
    assert got == pytest.approx(ref, rel=1e-6), f"tip {got:.9g} m, Timoshenko {ref:.9g} m"
    bernoulli = -_tip(_cantilever(n, 0.0, direction))[k]
    assert bernoulli == pytest.approx(P * L**3 / (3 * E * I), rel=1e-6)


def test_shear_flexibilities_survive_a_spacar_round_trip():
    """ESTIFF's Sy, Sz are read into the general section (the same model: the tip deflection to 1e-12) and
    written back."""
    sc = _cantilever(2, S)
    sc["stroke"]["start"] = 0.0
    text = write_dat(scene_from_dict(sc))
    assert f" {S!r} {S!r}" in text.split("ESTIFF 1 ", 1)[1].splitlines()[0]
    back = read_dat(text).scene
    assert back["elements"][0]["section"]["shear_y"] == pytest.approx(S, rel=1e-15)
    np.testing.assert_allclose(_tip(back), _tip(sc), rtol=1e-12)


def test_no_shear_warning_for_a_section_that_carries_shear():
    """The stocky bar (L/h = 3) is outside Euler-Bernoulli theory and flagged so without shear flexibility;
    with it the beam is Timoshenko's and the warning that shear is neglected would be false."""
    from flexopt.model.checks import slenderness_warnings

    assert any(w.kind == "validity" for w in slenderness_warnings(scene_from_dict(_cantilever(1, 0.0))))
    assert not slenderness_warnings(scene_from_dict(_cantilever(1, S)))
