"""The pint registry's parsed-definitions cache (model.units.registry): a fresh process builds it from the cache
folder beside the kernels, and converts as the uncached registry does; an unwritable folder falls back."""

from __future__ import annotations

import os
import subprocess
import sys

_PROBE = (
    "from flexopt.model.units import registry; r = registry(); "
    "print(r('0.3 mm').to('m').magnitude, r('75 deg').to('rad').magnitude, r('7.8 g/cm^3').to('kg/m^3').magnitude)"
)


def _run(env: dict[str, str]) -> str:
    out = subprocess.run([sys.executable, "-c", _PROBE], env=env, capture_output=True, text=True, check=True)
    return out.stdout.strip()


def test_registry_cache_folder_and_same_conversions(tmp_path):
    """Two fresh processes with FLEXOPT_CACHE_DIR set: the first writes pint's cache under it, the second reads
    it; both convert exactly as an uncached pint registry (independent: pint itself, no cache)."""
    import math

    import pint

    env = {**os.environ, "FLEXOPT_CACHE_DIR": str(tmp_path)}
    first, second = _run(env), _run(env)
    assert any((tmp_path / "pint").iterdir())
    plain = pint.UnitRegistry()
    want = [
        plain("0.3 mm").to("m").magnitude,
        plain("75 deg").to("rad").magnitude,
        plain("7.8 g/cm^3").to("kg/m^3").magnitude,
    ]
    for got in (first, second):
        vals = [float(v) for v in got.split()]
        assert all(math.isclose(a, b, rel_tol=1e-15) for a, b in zip(vals, want, strict=True))


def test_unwritable_cache_falls_back(tmp_path):
    """A cache folder that cannot be made (its parent is a file: refused even to root) builds the registry
    without the cache: the same conversion, no error."""
    blocker = tmp_path / "file"
    blocker.write_text("")
    assert _run({**os.environ, "FLEXOPT_CACHE_DIR": str(blocker)}).split()[0] == "0.0003"
