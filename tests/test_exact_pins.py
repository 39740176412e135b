"""The exact path against its REGRESSION PINS (tests/data/exact_pins.json, made by tests/make_pins.py).

The pins are what the exact method produced before the exact path was optimised (issue 12): not
references, only a guard that the speed work changed no result. Tolerance 1e-9 relative: Newton converges
to a scaled increment of 1e-12, so frequencies repeat to about 1e-11; 1e-9 leaves room for a different
(but converged) continuation path and eigen route only; exceptions with their reason in make_pins.RTOL.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from flexopt.model import Analysis, template

from tests.make_pins import PATH, RTOL

PINS = json.loads(PATH.read_text())["cases"]


@pytest.mark.parametrize("pin", PINS, ids=[f"{p['template']}{p['overrides'] or ''}" for p in PINS])
def test_exact_curve_matches_regression_pin(pin: dict) -> None:
    rtol = RTOL.get((pin["template"], pin["overrides"].get("segments")), 1e-9)
    c = Analysis(template(pin["template"], **pin["overrides"])).frequency_curve(np.array(pin["stroke"]))
    assert c.status == pin["status"]
    np.testing.assert_allclose(c.stroke, pin["stroke"], rtol=1e-12)
    np.testing.assert_allclose(
        c.modes_hz, pin["modes_hz"], rtol=rtol, err_msg="regression pin (tests/make_pins.py) changed"
    )
    np.testing.assert_allclose(
        c.parasitic_hz, pin["parasitic_hz"], rtol=rtol, err_msg="regression pin (tests/make_pins.py) changed"
    )
