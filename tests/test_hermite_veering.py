"""hermite and auto on butterfly-like four-leaf hinges: two cross-spring stages whose leaves are not at right
angles (the double cross hinge template with ``angle`` != 90 deg), where two or three parasitic modes veer
between the samples (issue 26 item 3).

Before the pair form on swaps, :data:`~flexopt.model.methods.hermite.VEER_MAC` and the shape check of the
probes (:func:`~flexopt.model.methods.hermite._follows`), hermite reported ``converged`` while missing its
tolerance on 2 of these 24 designs at 1e-2 (up to 2.1 times: 2.08 % with an estimate of 0.49 %) and 4 at 1e-3
(up to 7.4 times), and on 3 of the 4 six-segment designs below at 1e-2 (2.2 %, estimate 0.82 %): a veering
between two samples interpolated as a crossing, and probes at a midpoint the veering's peak error missed.
Reference: the exact curve (continuation + eigen at every point), an independent method. Coarse meshes (4 and
6 segments per leaf) keep the test short: the veering is a property of each mesh's own spectrum, which the
hermite curve of that mesh must follow."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from flexopt.model import Analysis, template
from flexopt.model.methods import frequency_curve

DESIGNS = [
    {"angle": a, "mid_mass": m, "width": w, "segments": 4}
    for a, m, w in itertools.product((60, 75, 105, 120), (0.005, 0.02, 0.08), (0.01, 0.03))
]
DESIGNS += [
    {"angle": a, "mid_mass": m, "width": 0.015, "segments": 6}
    for a, m in ((65, 0.01), (85, 0.01), (95, 0.01), (65, 0.04))
]


def _id(d: dict) -> str:
    return f"angle{d['angle']}-mid{d['mid_mass']}-w{d['width']}-seg{d['segments']}"


@pytest.mark.slow
@pytest.mark.parametrize("design", DESIGNS, ids=[_id(d) for d in DESIGNS])
def test_hermite_and_auto_meet_their_tolerance_through_veerings(design: dict) -> None:
    """At 1e-2 and 1e-3, hermite's curve is within the tolerance of the exact curve at every point and says it
    converged; auto at 1e-3 too (it runs hermite within a sample budget and fills what misses exactly)."""
    exact = frequency_curve(Analysis(template("double-cross-hinge", **design)), "exact")
    for tol in (1e-2, 1e-3):
        h = frequency_curve(Analysis(template("double-cross-hinge", **design)), "hermite", tol)
        assert h.method == "hermite" and h.solver["converged"]
        err = float(np.max(np.abs(h.parasitic_hz / exact.parasitic_hz - 1)))
        assert err <= tol, f"hermite at {tol:g}: {err:.3g} off, estimate {h.solver['estimated_error']:.3g}"
    a = frequency_curve(Analysis(template("double-cross-hinge", **design)), "auto", 1e-3)
    err = float(np.max(np.abs(a.parasitic_hz / exact.parasitic_hz - 1)))
    assert err <= 1e-3, f"auto ({a.solver.get('auto_method')}) at 1e-3: {err:.3g} off"
