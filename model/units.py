"""Units at the scene boundary: a scene's optional ``units`` block and unit-bearing template parameters, both
converted to SI with pint (https://pint.readthedocs.io) when the scene is read. Nothing past this module sees
a unit: the model, every result and every wire form are SI (m, kg, s, N, Pa; stroke in deg, rad or m).

pint is imported on first use only (building its registry takes most of a second), so scenes without a
``units`` block and plain-number template parameters never load it.

The ``units`` block names the unit of each kind of quantity the scene's numbers are written in::

    "units": {"length": "mm", "mass": "tonne", "stress": "MPa"}

``length`` (node positions, section sizes, fibre distances, a translation stroke, centres of mass), ``mass``
(body masses; inertia is mass * length^2), ``force`` (used only to derive the default stress unit),
``stress`` (E, G, allowable stress; default force / length^2) and ``density`` (default mass / length^3).
Omitted kinds are SI. Conversions are exact up to rounding (a relative 1e-16 per factor).
"""

from __future__ import annotations

import copy
import math
import re
from functools import lru_cache
from typing import Any

__all__ = ["UNIT_KINDS", "UnitsError", "registry", "check_unit", "factors", "scene_to_si", "quantity_to"]

#: The kinds of quantity a ``units`` block may name, with their SI unit and pint dimensionality.
UNIT_KINDS: dict[str, tuple[str, str]] = {
    "length": ("m", "[length]"),
    "mass": ("kg", "[mass]"),
    "force": ("N", "[force]"),
    "stress": ("Pa", "[pressure]"),
    "density": ("kg/m^3", "[density]"),
}


#: What a unit expression may look like before pint sees it (pint evaluates expressions: a plain float and a
#: short product/quotient of unit names with small powers keep that cheap and harmless).
_UNIT_RE = re.compile(r"^[A-Za-z_\u00b5\u03bc\u00b0%][A-Za-z0-9_\u00b5\u03bc\u00b0%*/^.() -]{0,47}$")
_NUMBER_RE = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d{1,3})?)\s*(.*?)\s*$")


class UnitsError(ValueError):
    """A unit string pint cannot read, or one of the wrong dimension (the message names the fix)."""


@lru_cache(maxsize=1)
def registry() -> Any:
    """The one pint UnitRegistry (built on first use).

    pint parses its definition files at every build (about 1 s, in every fresh process that reads a unit: each
    ``flexopt --set thickness=0.3mm``); its own cache of the parsed definitions, keyed by their content, makes
    it 0.15 s. The cache sits beside the compiled kernels (``$FLEXOPT_CACHE_DIR`` or ``~/.cache/flexopt``,
    folder ``pint``); where it cannot be written the registry is built without it.
    """
    import os
    from pathlib import Path

    import pint

    env = os.environ.get("FLEXOPT_CACHE_DIR")
    folder = (Path(env) if env else Path.home() / ".cache" / "flexopt") / "pint"
    try:
        folder.mkdir(parents=True, exist_ok=True)
        return pint.UnitRegistry(cache_folder=folder)
    except OSError:  # a read-only home: the same registry, parsed
        return pint.UnitRegistry()


def check_unit(kind: str, unit: str) -> str:
    """``unit`` if pint reads it as a unit of ``kind`` (one of :data:`UNIT_KINDS`); else :class:`UnitsError`."""

    si, dim = UNIT_KINDS[kind]
    big_power = isinstance(unit, str) and re.search(r"(\*\*|\^)\s*-?\d{3}", unit)
    if not isinstance(unit, str) or not _UNIT_RE.match(unit.strip()) or big_power:
        raise UnitsError(f"'{unit}' is not a unit pint knows; give e.g. '{_example(kind)}'")
    try:
        u = registry().Unit(unit.strip())
    except Exception as exc:  # noqa: BLE001 - pint's parser raises many types (PintError, SyntaxError, ...)
        raise UnitsError(f"'{unit}' is not a unit pint knows ({exc}); give e.g. '{_example(kind)}'") from None
    if u.dimensionality != registry().Unit(si).dimensionality:
        raise UnitsError(f"'{unit}' is not a {kind} unit (it is {u.dimensionality}); give e.g. '{_example(kind)}'")
    return unit


def _example(kind: str) -> str:
    return {"length": "mm", "mass": "tonne", "force": "N", "stress": "MPa", "density": "kg/m^3"}[kind]


def factors(units: dict[str, str | None]) -> dict[str, float]:
    """SI factor of each kind (multiply a number written in the block's unit to get SI).

    ``stress`` defaults to force / length^2 and ``density`` to mass / length^3 (a consistent set such as
    mm, tonne, N gives MPa and tonne/mm^3).
    """
    reg = registry()
    given = {k: units.get(k) for k in UNIT_KINDS}
    f = {}
    for kind in ("length", "mass", "force"):
        u = given[kind]
        f[kind] = 1.0 if u is None else float(reg.Quantity(1.0, check_unit(kind, u)).to(UNIT_KINDS[kind][0]).magnitude)
    f["stress"] = (
        f["force"] / f["length"] ** 2
        if given["stress"] is None
        else float(reg.Quantity(1.0, check_unit("stress", given["stress"])).to("Pa").magnitude)
    )
    f["density"] = (
        f["mass"] / f["length"] ** 3
        if given["density"] is None
        else float(reg.Quantity(1.0, check_unit("density", given["density"])).to("kg/m^3").magnitude)
    )
    return f


def _scale(obj: dict, key: str, c: float) -> None:
    v = obj.get(key)
    if isinstance(v, bool) or v is None:
        return
    if isinstance(v, (int, float)):
        obj[key] = v * c
    elif isinstance(v, (list, tuple)):
        obj[key] = [_scaled(x, c) for x in v]


def _scaled(x: Any, c: float) -> Any:
    if isinstance(x, (list, tuple)):
        return [_scaled(y, c) for y in x]
    return x * c if isinstance(x, (int, float)) and not isinstance(x, bool) else x


def scene_to_si(data: dict[str, Any]) -> dict[str, Any]:
    """A copy of a scene dict whose numbers written in its ``units`` block are converted to SI.

    Converted: materials (E, G, allowable_stress: stress; density), node positions, bodies (mass,
    center_of_mass, inertia = mass length^2), beam sections (rectangle width and thickness; general A
    [length^2], Iy, Iz, J [length^4], Iw [length^6], cy, cz [length], torsion_stress_factor [1/length^3]), truss areas and
    the start and stop of a translation stroke, gravity (length / s^2) and loads (forces: force; moments: force length; points:
    length; a table's stroke values with a translation stroke: length). Angles, counts and directions are
    unit-free. Malformed parts are copied unchanged for the schema to report. The block itself is kept (the Scene excludes it from
    dumps, so a dumped scene is plain SI). Raises :class:`UnitsError` for a bad unit string.
    """
    units = data.get("units")
    if not isinstance(units, dict):
        return data
    f = factors(units)
    L, m, S, rho = f["length"], f["mass"], f["stress"], f["density"]
    out = copy.deepcopy(data)

    def each(key: str) -> list[dict]:
        items = out.get(key)
        return [x for x in items if isinstance(x, dict)] if isinstance(items, (list, tuple)) else []

    for mat in each("materials"):
        for k in ("E", "G", "allowable_stress"):
            _scale(mat, k, S)
        _scale(mat, "density", rho)
    for node in each("nodes"):
        _scale(node, "position", L)
    for body in each("bodies"):
        _scale(body, "mass", m)
        _scale(body, "center_of_mass", L)
        _scale(body, "inertia", m * L * L)
    for el in each("elements"):
        if el.get("kind", "beam") == "truss":
            _scale(el, "area", L * L)
            continue
        sec = el.get("section")
        if not isinstance(sec, dict):
            continue
        if sec.get("kind", "rectangular") == "rectangular":
            _scale(sec, "width", L)
            _scale(sec, "thickness", L)
        else:
            _scale(sec, "A", L**2)
            for k in ("Iy", "Iz", "J"):
                _scale(sec, k, L**4)
            _scale(sec, "cy", L)
            _scale(sec, "cz", L)
            _scale(sec, "torsion_stress_factor", L**-3)
            _scale(sec, "Iw", L**6)
    st = out.get("stroke")
    translation = isinstance(st, dict) and st.get("kind") == "translation"
    if isinstance(st, dict) and translation:
        _scale(st, "start", L)
        _scale(st, "stop", L)
    if isinstance(out.get("gravity"), (list, tuple)):
        _scale(out, "gravity", L)  # length / s^2
    F = f["force"]
    for load in each("loads"):
        _scale(load, "force", F)
        _scale(load, "moment", F * L)
        _scale(load, "point", L)
        if isinstance(load.get("ramp"), dict):
            c = F * L if load.get("kind") == "moment" else F  # a ramp is a force unless kind says moment
            _scale(load["ramp"], "start", c)
            _scale(load["ramp"], "stop", c)
        if isinstance(load.get("table"), dict):
            _scale(load["table"], "force", F)
            _scale(load["table"], "moment", F * L)
            if translation:
                _scale(load["table"], "stroke", L)
    return out


def quantity_to(text: str, unit: str) -> float:
    """The number of ``unit`` in ``text`` (e.g. ``quantity_to("0.3mm", "m") == 0.0003``).

    A plain number is taken as already in ``unit``. Raises :class:`UnitsError` when ``text`` is not a
    quantity or has another dimension.
    """
    import pint

    reg = registry()
    m = _NUMBER_RE.match(text) if isinstance(text, str) else None
    if m is None or (m.group(2) and not _UNIT_RE.match(m.group(2))):
        raise UnitsError(f"cannot read '{text}' as a quantity; write a number with a unit, e.g. '0.3 mm'")
    number, unit_text = float(m.group(1)), m.group(2)
    if not unit_text:
        return number
    try:
        q = reg.Quantity(number, reg.Unit(unit_text))
    except Exception as exc:  # noqa: BLE001 - pint's parser raises many types (PintError, SyntaxError, ...)
        raise UnitsError(
            f"cannot read '{text}' as a quantity ({exc}); write a number with a unit, e.g. '0.3 mm'"
        ) from None
    try:
        v = float(q.to(unit).magnitude)
    except OverflowError:
        raise UnitsError(f"'{text}' overflows when converted to {unit}") from None
    except pint.errors.DimensionalityError:
        want = "a plain number" if unit in ("", "dimensionless") else f"a quantity convertible to {unit}"
        raise UnitsError(f"'{text}' has dimension {q.dimensionality}; give {want}") from None
    if not math.isfinite(v):
        raise UnitsError(f"'{text}' is not finite")
    return v
