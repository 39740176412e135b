"""Symmetries that reverse the stroke (model/symmetry.py) and the exact curve's use of them.

The claim under test is physical: a design mapped onto itself by a reflection or half-turn that reverses
the drive has a frequency curve even in the stroke. The independent check is the exact curve solved on
both sides (``mirror=False``): where the detector finds a symmetry the two sides must agree to the Newton
tolerance, and where it finds none (the three-fold cross hinge, whose middle leaf runs the other way from
its outer ones) they must not.
"""

from __future__ import annotations

import numpy as np
import pytest
from flexopt.model import Analysis, scene_from_dict, template
from flexopt.model.symmetry import stroke_symmetry

from .helpers import coarse

SYMMETRIC = ["leaf-spring", "parallel-leaf-spring", "cross-spring-pivot", "cartwheel-hinge", "double-cross-hinge"]


@pytest.mark.parametrize("name", SYMMETRIC + ["three-fold-cross-hinge"])
def test_detected_symmetry_matches_the_two_sided_exact_curve(name: str) -> None:
    an = Analysis(template(name, points=31, **coarse(name)))  # mirrored against solved: any mesh
    both = an.frequency_curve(mirror=False, mesh_error=False)
    hz = both.modes_hz
    even = float(np.max(np.abs(hz / hz[::-1] - 1)))
    if name in SYMMETRIC:
        assert an.symmetry is not None
        # the two sides' equilibria agree to the Newton tolerance (increments below 1e-12 of the length
        # scale): measured 3e-14 (leaf) to 1e-10 (double cross) on the 91-point default grids
        assert even < 1e-8, even
        one = an.frequency_curve(mesh_error=False)  # the negative side mirrored
        assert np.array_equal(one.stroke, both.stroke)
        assert np.allclose(one.modes_hz, hz, rtol=1e-8, atol=0)
        assert np.array_equal(one.mode_labels, both.mode_labels)
        scale = np.abs(both.drive_reaction).max()
        assert np.allclose(one.drive_reaction, both.drive_reaction, rtol=0, atol=1e-8 * scale)
        for m, vm in both.max_von_mises.items():  # each member's stresses at -s: its image's at s
            assert np.allclose(one.max_von_mises[m], vm, rtol=1e-7, atol=1e-9 * vm.max()), m
        assert [w.message for w in one.warnings] == [w.message for w in both.warnings]
    else:
        assert an.symmetry is None
        assert even > 0.01, even  # the three-fold hinge's curve is far from even: no symmetry to find


def _pivot() -> dict:
    return template("cross-spring-pivot").model_dump(mode="json")


def _nudge_node(d: dict) -> dict:
    d["nodes"][1]["position"][0] += 1e-6 * 0.05  # 1e-6 of the leaf length: far above the 1e-9 tolerance
    return d


def _one_thicker(d: dict) -> dict:
    d["elements"][0]["section"]["thickness"] *= 1.001
    return d


def _com_off(d: dict) -> dict:
    d["bodies"][0]["center_of_mass"][0] += 1e-4
    return d


def _twisted_section(d: dict) -> dict:
    d["elements"][1]["y_axis"] = [0.0, 0.1, 1.0]  # leaf B's width direction tilted about its axis
    return d


def _partial_support(d: dict) -> dict:
    d["supports"][1]["dofs"] = ["x", "y", "z", "rx", "ry"]  # one clamp releases rz
    return d


def _tilted_axis(d: dict) -> dict:
    d["stroke"]["axis"] = [0.0, 0.05, 1.0]
    return d


@pytest.mark.parametrize(
    "change", [_nudge_node, _one_thicker, _com_off, _twisted_section, _partial_support, _tilted_axis]
)
def test_any_asymmetry_means_no_symmetry(change) -> None:  # noqa: ANN001
    assert stroke_symmetry(scene_from_dict(_pivot())) is not None
    assert stroke_symmetry(scene_from_dict(change(_pivot()))) is None


def test_uneven_grid_and_failures_are_mirrored_like_the_two_sided_solve() -> None:
    # a grid with points on one side only: -30 and +5 deg have no partner
    an = Analysis(template("cross-spring-pivot"))
    grid = np.array([-30.0, -10.0, 0.0, 5.0, 10.0, 20.0])
    a, b = an.frequency_curve(grid, mirror=False, mesh_error=False), an.frequency_curve(grid, mesh_error=False)
    assert np.array_equal(a.stroke, b.stroke)
    # the same frequencies; their branch order at -30 deg may differ, because MAC tracking over steps this
    # coarse depends on the points walked through (0, -10, -30 against 0, 5, 10, 20, 30)
    assert np.allclose(np.sort(a.modes_hz, axis=1), np.sort(b.modes_hz, axis=1), rtol=1e-8, atol=0)
    assert np.allclose(a.parasitic_hz, b.parasitic_hz, rtol=1e-8, atol=0)
    # a stability loss on both sides (the leaf with width and thickness swapped, tests/test_causes.py)
    an = Analysis(template("leaf-spring", width=0.5e-3, thickness=0.04, segments=40, points=3, stroke=1.0))
    fa, fb = an.frequency_curve(mirror=False).failures, an.frequency_curve().failures
    assert len(fa) == len(fb) == 2
    for x, y in zip(sorted(fa, key=lambda f: f.stroke), sorted(fb, key=lambda f: f.stroke)):
        assert x.reason == y.reason
        assert abs(x.stroke - y.stroke) <= 1e-6 * abs(x.stroke)  # the loss is located to 1e-4 of itself
        assert x.message.split(" (")[0] == y.message.split(" (")[0]


@pytest.mark.parametrize("name", ["cross-spring-pivot", "parallel-leaf-spring"])
def test_hermite_samples_one_side_of_a_symmetric_design(name: str) -> None:
    from flexopt.model.methods.hermite import hermite_curve

    an = Analysis(template(name))
    internal = an.scene.stroke.to_internal(an.scene.stroke.values())
    one = hermite_curve(an, internal, 0.01)
    both = hermite_curve(an, internal, 0.01, mirror=False)
    # the two-sided run samples the negative side at the images of the positive side's samples: the same
    # interpolants up to the equilibria's Newton tolerance
    assert np.allclose(one.hz, both.hz, rtol=1e-7, atol=0)
    assert one.samples < both.samples and 2 * one.samples >= both.samples


def test_one_side_and_image_indices_match_their_plain_definitions() -> None:
    """The vectorised mirror bookkeeping (model.symmetry.one_side, image_indices) against the plain loops
    that define it (nearest solved stroke by a scan of all of them), on grids symmetric to rounding,
    one-sided, uneven, with repeated and near-repeated values."""
    from flexopt.model.symmetry import image_indices, mirror_tol, one_side

    def one_side_plain(internal):
        tol = mirror_tol(internal)
        pos = sorted(float(v) for v in internal if v >= 0)
        for v in sorted(float(-v) for v in internal if v < 0):
            if not pos or np.min(np.abs(np.array(pos) - v)) > tol:
                pos.append(v)
                pos.sort()
        return np.array(pos)

    def image_plain(solved, internal):
        tol = mirror_tol(internal)
        out = []
        for v in np.abs(np.asarray(internal, dtype=float)):
            i = int(np.argmin(np.abs(solved - v))) if len(solved) else -1
            out.append(i if i >= 0 and abs(solved[i] - v) <= tol else None)
        return out

    rng = np.random.default_rng(7)
    grids = [
        np.linspace(-0.785, 0.785, 91),
        np.linspace(-0.785, 0.785, 90),
        np.linspace(0, 0.5, 7),
        np.linspace(-0.3, 0.0, 5),
        np.array([-0.2, -0.2 * (1 + 3e-16), 0.1, 0.2]),
        np.zeros(1),
    ]
    grids += [np.round(rng.uniform(-1, 1, rng.integers(1, 40)), rng.integers(1, 4)) for _ in range(50)]
    for g in grids:
        pos = one_side(g)
        np.testing.assert_array_equal(pos, one_side_plain(g))
        assert image_indices(pos, g) == image_plain(pos, g)
        assert image_indices(pos[:-1], g) == image_plain(pos[:-1], g)  # some points not solved
