"""The right cause (issue 11, item 3): unconnected parts, mechanisms, mass underflow, the stiff-axis drive,
and a stability limit located by extrapolating omega^2 to zero, on the side where it happens."""

from __future__ import annotations

import numpy as np
import pytest
from flexopt.model import Analysis, SceneError, scene_from_dict, template
from flexopt.model.errors import MassUnderflowError

from . import references as ref


def _leaf_plus(nodes: list[dict], elements: list[dict]) -> dict:
    d = template("leaf-spring", points=5).model_dump(mode="json")
    d["nodes"] = list(d["nodes"]) + nodes
    d["elements"] = list(d["elements"]) + elements
    return d


@pytest.fixture(scope="module")
def stiff_axis_curve():
    sc = template("leaf-spring", width=0.5e-3, thickness=0.04, segments=40, points=3, stroke=1.0)
    return Analysis(sc).frequency_curve()


def test_stiff_axis_leaf_loss_within_0p1_percent_of_theory_on_both_sides(stiff_axis_curve):
    c = stiff_axis_curve
    assert c.status == "truncated" and len(c.failures) == 2
    pos, neg = sorted(c.failures, key=lambda f: -f.stroke)
    assert pos.reason == neg.reason == "unstable"
    ref.STIFF_AXIS_LOSS.check(pos.stroke)
    ref.STIFF_AXIS_LOSS.check(-neg.stroke)
    # reported on the side where it happens: the negative side says a negative stroke
    assert neg.stroke < 0 and neg.last_converged <= 0 and "at stroke -0.0343" in neg.message, neg.message
    assert "at stroke +0.0343" in pos.message, pos.message


def test_stiff_axis_leaf_names_the_cause_and_the_vector_to_change(stiff_axis_curve):
    msg = stiff_axis_curve.failures[0].message
    assert "stiff section axis" in msg and "lateral-torsional buckling" in msg
    assert "elements[0].y_axis to (0, 0, 1)" in msg and "swap its width and thickness" in msg


def test_weak_axis_leaf_has_no_stiff_axis_cause():
    from flexopt.model.causes import stiff_axis_drives
    from flexopt.model.structure import compile_scene

    for name in ("leaf-spring", "parallel-leaf-spring", "cross-spring-pivot"):
        assert stiff_axis_drives(compile_scene(template(name))) == [], name


def test_unconnected_part_is_named():
    leaf = template("leaf-spring").model_dump(mode="json")["elements"][0]
    d = _leaf_plus(
        [{"name": "s1", "position": [0, 0.1, 0]}, {"name": "s2", "position": [0.05, 0.1, 0]}],
        [dict(leaf, name="stray", nodes=["s1", "s2"])],
    )
    with pytest.raises(SceneError) as e:
        Analysis(scene_from_dict(d)).frequency_curve()
    msg = str(e.value)
    assert "'stray'" in msg and "not connected" in msg and "elements[1].nodes" in msg, msg
    assert "buckling" not in msg and "unstable" not in msg


def test_body_joined_to_nothing_is_named():
    d = _leaf_plus([{"name": "n9", "position": [0, 0.2, 0]}], [])
    d["bodies"] = [
        {
            "name": "lump",
            "mass": 0.1,
            "center_of_mass": [0, 0.2, 0],
            "inertia": [[1e-5, 0, 0], [0, 1e-5, 0], [0, 0, 1e-5]],
            "nodes": ["n9"],
        }
    ]
    with pytest.raises(SceneError, match=r"bodies\[0\]: 'lump' is not connected"):
        Analysis(scene_from_dict(d)).frequency_curve()


def test_mechanism_is_named():
    # a node hanging from the tip by one truss swings freely across it: two free motions
    d = _leaf_plus(
        [{"name": "bob", "position": [0.1, 0.0, -0.05]}],
        [{"kind": "truss", "name": "rod", "nodes": ["tip", "bob"], "material": "steel", "area": 1e-6}],
    )
    with pytest.raises(SceneError) as e:
        Analysis(scene_from_dict(d)).frequency_curve()
    msg = str(e.value)
    assert "2 free motions beyond the drive" in msg and "'bob'" in msg and "'rod'" in msg, msg


def test_mechanism_beyond_the_search_limit_is_an_equilibrium_error(monkeypatch):
    """Models too large for the SVD search (model.causes.MECHANISM_MAX_COLUMNS) still get a named error,
    not a traceback, when the reference equilibrium is singular."""
    import flexopt.model.causes as causes
    from flexopt.model import EquilibriumError

    monkeypatch.setattr(causes, "MECHANISM_MAX_COLUMNS", 0)
    d = _leaf_plus(
        [{"name": "bob", "position": [0.1, 0.0, -0.05]}],
        [{"kind": "truss", "name": "rod", "nodes": ["tip", "bob"], "material": "steel", "area": 1e-6}],
    )
    with pytest.raises(EquilibriumError, match="stress-free reference.*a mechanism or an unconnected part"):
        Analysis(scene_from_dict(d)).frequency_curve()


def test_density_1e_300_is_mass_underflow():
    with pytest.raises(MassUnderflowError) as e:
        Analysis(template("leaf-spring", density=1e-300, points=5)).frequency_curve()
    msg = str(e.value)
    assert msg.startswith("materials[0].density: mass underflow") and "buckling" not in msg, msg


def test_thickness_1e_103_is_mass_underflow_of_the_section():
    # steel's density is a real solid's: what underflows is the section (rotary inertia ~ t^3 = 1e-309), so
    # the error names the thickness, not the material
    with pytest.raises(MassUnderflowError) as e:
        Analysis(template("leaf-spring", thickness=1e-103, points=5)).frequency_curve()
    msg = str(e.value)
    assert msg.startswith("elements[0].section.thickness: mass underflow") and "metres" in msg, msg


def test_stable_curve_unchanged_by_the_checks():
    c = Analysis(template("leaf-spring", points=5)).frequency_curve()
    assert c.status == "complete" and not c.failures
    assert np.all(c.parasitic_hz > 0)


def test_worker_keeps_the_mass_underflow_field():
    """A worker process reports errors by name; the service rebuilds them with their field (HTTP 422 with
    loc body.scene.materials.0.density)."""
    from flexopt.service.jobs.worker import _error, raise_error

    with pytest.raises(MassUnderflowError) as e:
        raise_error(_error(MassUnderflowError("materials[0].density", "mass underflow: x"))[1])
    assert e.value.field == "materials[0].density"
