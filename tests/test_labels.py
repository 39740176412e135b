"""Mode labels with the drive free (issue 11, item 5): the drive mode is the one that moves the drive
coordinate itself (mass-weighted MAC with the equilibrium path's tangent), not the mode with the largest
kinetic-energy share in the spin of a rotor's centre of mass."""

from __future__ import annotations

import numpy as np
from flexopt.model import Analysis, scene_from_dict, template


def test_cross_spring_pivot_drive_free_keeps_the_drive_mode_over_45_degrees():
    d = template("cross-spring-pivot", points=19).model_dump(mode="json")
    d["stroke"]["drive"] = "free"
    c = Analysis(scene_from_dict(d)).frequency_curve()
    assert c.status == "complete" and len(c.stroke) == 19 and c.stroke[0] == -45 and c.stroke[-1] == 45
    for s, hz, lab, par in zip(c.stroke, c.modes_hz, c.mode_labels, c.parasitic_hz):
        drive = [h for h, lb in zip(hz, lab) if lb == "drive"]
        # the rotor's spin about the pivot: 9.9 Hz at 0 (2 E I / L against the rotor's inertia, see
        # tests/test_families.py) rising to 11 Hz at 45 deg; exactly one drive mode, in the 9.5-11.5 Hz band
        assert len(drive) == 1 and 9.5 < drive[0] < 11.5, (s, hz, lab)
        assert par > 11.5 and par == min(h for h, lb in zip(hz, lab) if lb == "parasitic"), (s, par, hz, lab)


def test_leaf_drive_free_labels_the_driving_plane_bending_as_drive():
    d = template("leaf-spring", points=5).model_dump(mode="json")
    d["stroke"]["drive"] = "free"
    c = Analysis(scene_from_dict(d)).frequency_curve()
    for hz, lab in zip(c.modes_hz, c.mode_labels):
        assert list(lab).count("drive") == 1
        assert hz[list(lab).index("drive")] == np.min(hz), "the tip-free leaf's drive mode is its first bending"
