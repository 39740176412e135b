"""Invariances the physics guarantees: rigid motion of the whole scene, a change of consistent units,
mirror symmetry of the stroke. None of these numbers comes from this code: each test compares the model
with itself under a transformation that must not change the answer."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla
from flexopt.model import Analysis, scene_from_dict
from flexopt.model.statics import walk
from hypothesis import given, settings
from hypothesis import strategies as st

from .helpers import rigid_motion, rotation_from_quaternion, scale_units, scene_dict

# Stroke points used by the invariance checks: both signs, small and large.
STROKES = {
    "leaf-spring": [-40.0, 0.0, 25.0],
    "cross-spring-pivot": [-30.0, 0.0, 45.0],
    "parallel-leaf-spring": [-0.008, 0.0, 0.005],
}

# Newton converges to a scaled residual of 1e-9, so equilibria carry relative errors of about 1e-9 and the
# frequencies (stationary in the configuration error, to first order) somewhat less; round-off in the
# rotated (non axis-aligned) drive basis adds about 1e-12. 1e-7 is the bound with margin.
RIGID_RTOL = 1e-7


def _curve(data: dict, name: str):
    return Analysis(scene_from_dict(data)).frequency_curve(stroke=np.array(STROKES[name]))


def _largest_eigenvalues(an: Analysis, stroke: np.ndarray) -> np.ndarray:
    """lambda_max of the locked-drive pencil (K, M) at each stroke value (stroke unit)."""
    sys = an.system
    out = []
    for s in an.structure.scene.stroke.to_internal(stroke):
        eqs: list = []
        walk(sys, np.array([s]), an.options, eqs.append)
        K, M = eqs[0].ev.H[sys.ix_free], sys.mass(eqs[0].state)[sys.ix_free]
        n = len(K)
        out.append(sla.eigh(0.5 * (K + K.T), M, eigvals_only=True, subset_by_index=[n - 1, n - 1])[0])
    return np.array(out)


_REFERENCE: dict[str, object] = {}


def _reference(name: str):
    if name not in _REFERENCE:
        _REFERENCE[name] = _curve(scene_dict(name, segments=4), name)
    return _REFERENCE[name]


quaternions = st.tuples(*[st.floats(-1, 1, allow_nan=False) for _ in range(4)]).filter(
    lambda q: sum(v * v for v in q) > 0.05
)
translations = st.tuples(*[st.floats(-2.0, 2.0, allow_nan=False) for _ in range(3)])


@pytest.mark.slow
@pytest.mark.parametrize("name", ["leaf-spring", "cross-spring-pivot", "parallel-leaf-spring"])
@settings(max_examples=12)
@given(q=quaternions, t=translations)
def test_rigid_motion_leaves_frequencies_and_stresses_unchanged(name, q, t):
    """Move and rotate the whole scene (nodes, bodies, section axes, drive axis, support directions):
    frequencies, the drive reaction and the stresses are properties of the design, not of where it sits."""
    ref = _reference(name)
    moved = _curve(rigid_motion(scene_dict(name, segments=4), rotation_from_quaternion(q), t), name)
    assert moved.status == "complete"
    np.testing.assert_allclose(moved.modes_hz, ref.modes_hz, rtol=RIGID_RTOL)
    np.testing.assert_allclose(moved.parasitic_hz, ref.parasitic_hz, rtol=RIGID_RTOL)
    np.testing.assert_allclose(
        moved.drive_reaction, ref.drive_reaction, rtol=RIGID_RTOL, atol=RIGID_RTOL * np.abs(ref.drive_reaction).max()
    )
    for member, vm in ref.max_von_mises.items():
        np.testing.assert_allclose(moved.max_von_mises[member], vm, rtol=RIGID_RTOL, atol=RIGID_RTOL * vm.max())


@pytest.mark.parametrize("name", ["leaf-spring", "cross-spring-pivot", "parallel-leaf-spring"])
def test_millimetre_units_give_the_same_hertz(name):
    """The same scene in the mm-N-tonne-s system (lengths x1e3, moduli in MPa, density in t/mm^3): Hz do
    not depend on the length and mass units. Every criterion in the solver is relative (residual scaled by
    the Jacobi diagonal and the structure's length, eigenvalues to LAPACK's highest accuracy), so the two
    runs differ only by rounding. A backward-stable symmetric eigen solver perturbs eigenvalue i by at
    most about eps * lambda_max (Weyl's inequality on the mass-scaled pencil), a relative error in Hz of
    eps * lambda_max / (2 lambda_i); assembly rounding is of the same order. Bound: 10 times that. (An
    absolute tolerance anywhere in the solver, e.g. LAPACK's default ABSTOL, exceeds it by 100x.)"""
    base = scene_dict(name, segments=4)
    a = _curve(base, name)
    mm = scale_units(base, length=1e-3, mass=1e3)
    b = Analysis(scene_from_dict(mm)).frequency_curve(
        stroke=np.array(STROKES[name]) * (1e3 if base["stroke"]["kind"] == "translation" else 1.0)
    )
    lam_max = _largest_eigenvalues(Analysis(scene_from_dict(base)), a.stroke)
    rtol = 10 * np.finfo(float).eps * lam_max[:, None] / (2 * (2 * np.pi * a.modes_hz) ** 2)
    err = np.abs(b.modes_hz / a.modes_hz - 1)
    assert np.all(err <= rtol), f"error / rounding bound: {np.max(err / rtol):.3g}"
    np.testing.assert_allclose(b.parasitic_hz, a.parasitic_hz, rtol=rtol.max())
    # stresses come out in the new stress unit, MPa = 1e6 Pa
    for member, vm in a.max_von_mises.items():
        np.testing.assert_allclose(b.max_von_mises[member] * 1e6, vm, rtol=1e-9, atol=1e-9 * vm.max())


@pytest.mark.parametrize("name", ["leaf-spring", "cross-spring-pivot", "parallel-leaf-spring"])
def test_mirror_symmetric_designs_give_even_curves(name):
    """Each template is mirror-symmetric about its zero-stroke plane, so the frequency curve is even and
    the drive reaction odd in the stroke. Continuation runs from 0 outwards in each direction separately,
    so the two halves are independent solutions: they agree to solver tolerance (1e-7 relative)."""
    c = Analysis(scene_from_dict(scene_dict(name, segments=6, points=9))).frequency_curve()
    assert c.status == "complete"
    np.testing.assert_allclose(c.stroke, -c.stroke[::-1], atol=1e-12)
    np.testing.assert_allclose(c.parasitic_hz, c.parasitic_hz[::-1], rtol=1e-7)
    np.testing.assert_allclose(np.sort(c.modes_hz, axis=1), np.sort(c.modes_hz[::-1], axis=1), rtol=1e-7)
    np.testing.assert_allclose(
        c.drive_reaction, -c.drive_reaction[::-1], rtol=1e-7, atol=1e-7 * np.abs(c.drive_reaction).max()
    )
