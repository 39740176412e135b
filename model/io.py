"""Reading scenes: JSON or dict in, a validated Scene out, every problem as one SceneError."""

from __future__ import annotations

import functools
import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from .errors import SceneError
from .scene import SUGGEST_BUDGET, Scene, closest

__all__ = ["scene_from_dict", "load_scene", "load_dat", "format_validation_error", "clean_errors"]


#: Tags of the scene's discriminated unions: pydantic puts the chosen tag into an error's location
#: (``elements[0].beam.segments``); the scene JSON has no such level, so it is dropped from messages.
_UNION_TAGS = frozenset({"beam", "truss", "rectangular", "general"})


@functools.cache
def _field_names() -> list[str]:
    """Every field name of the scene's models (for "did you mean" on a misspelt field)."""
    from . import scene as sc

    models = (
        sc.Material,
        sc.Node,
        sc.RectangularSection,
        sc.GeneralSection,
        sc.Beam,
        sc.Truss,
        sc.RigidBody,
        sc.Support,
        sc.Stroke,
        sc.SupportDirections,
        sc.Units,
        sc.Load,
        sc.LoadRamp,
        sc.LoadTable,
        sc.Joint,
        sc.Scene,
    )
    return sorted({f for m in models for f in m.model_fields})


def clean_errors(errors: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """pydantic error dicts as they should reach a user: union tags dropped from locations, and no echo.

    An unknown field gets the closest field name of the scene's models ("did you mean"). A tuple whose
    item fails validation is also reported by pydantic as "Tuple should have at least 1
    item after validation, not 0" when the field has a minimum length (the failed item counts as
    missing); that echo of a real error inside the same field is dropped.
    """
    out = []
    budget = SUGGEST_BUDGET  # one bound on the suggestions' work for all the errors (issue 29 item 3)
    for e in errors:
        loc = tuple(
            p
            for i, p in enumerate(e["loc"])
            if not (
                isinstance(p, str)
                and p in _UNION_TAGS
                and i > 0
                and (isinstance(e["loc"][i - 1], int) or e["loc"][i - 1] == "section")
            )
        )
        e = {**e, "loc": loc}
        if e["type"] == "extra_forbidden" and loc and isinstance(loc[-1], str):
            e["type"] = "value_error"  # the message is final: later formatters keep it
            close, spent = closest(loc[-1], _field_names(), budget)
            budget -= spent
            hint = f" (did you mean '{close}'?)" if close else ""
            e["msg"] = f"unknown field{hint}; remove it or check its spelling"
        out.append(e)
    locs = [e["loc"] for e in out]
    return [
        e
        for e in out
        if not (
            e["type"] == "too_short"
            and any(len(other) > len(e["loc"]) and other[: len(e["loc"])] == e["loc"] for other in locs)
        )
    ]


def format_validation_error(exc: ValidationError) -> str:
    """One line, one clause per problem: ``field.path: message``."""
    lines = []
    for err in clean_errors(exc.errors()):
        loc = ".".join(f"[{p}]" if isinstance(p, int) else str(p) for p in err["loc"]).replace(".[", "[")
        msg = err["msg"].removeprefix("Value error, ")
        if err["type"] == "extra_forbidden":
            msg = "unknown field; remove it or check its spelling"
        elif err["type"] == "missing":
            msg = "required field is missing; add it"
        # the scene's cross-reference check reports at the top level with the path in its message
        lines.append(f"{loc}: {msg}" if loc else msg)
    return "; ".join(lines)


def scene_from_dict(data: Any) -> Scene:
    """Validate a scene given as a dict. Raises SceneError naming each bad field."""
    if not isinstance(data, dict):
        raise SceneError("scene", "a scene is a JSON object with materials, nodes, elements, supports, stroke")
    try:
        return Scene.model_validate(data)
    except ValidationError as exc:
        raise SceneError("", format_validation_error(exc)) from None


def load_dat(path: str | Path, name: str | None = None) -> tuple[Scene, Any]:
    """Read a SPACAR ``.dat`` model (:func:`model.spacar.read_dat`), or SPACAR Light's four tables in a JSON or
    YAML file (``nodes``, ``elements``, ``nprops``, ``eprops``, optional ``opt``; :func:`model.spacar.spacar_light`),
    into a validated Scene and the import report (:class:`model.spacar.SpacarImport`: what was mapped, notes,
    the node numbering, SPACAR's DOF count)."""
    from .spacar import read_dat

    p = Path(path)
    try:
        text = p.read_text()
    except OSError as exc:
        raise SceneError("scene", f"cannot read SPACAR file '{p}': {exc.strerror}") from None
    if p.suffix.lower() == ".dat":
        imp = read_dat(text, name or p.stem)
    else:
        imp = _spacar_light(_tables(p, text), name or p.stem)
    return scene_from_dict(imp.scene), imp


def _tables(p: Path, text: str) -> Any:
    """The parsed JSON or YAML (``.yaml``/``.yml``, with PyYAML) of a tables file."""
    if p.suffix.lower() in (".yaml", ".yml"):
        try:
            import yaml
        except ImportError:
            raise SceneError(
                "scene", f"'{p}' is YAML, which needs PyYAML (pip install pyyaml); or write it as JSON"
            ) from None
        try:
            return yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise SceneError("scene", f"'{p}' is not valid YAML: {exc}") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise SceneError(
            "scene", f"'{p}' is not valid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})"
        ) from None


def _spacar_light(data: Any, name: str) -> Any:
    from .spacar import spacar_light

    if not isinstance(data, dict) or not {"nodes", "elements", "eprops"} <= set(data):
        raise SceneError(
            "scene", "a SPACAR Light tables file has 'nodes', 'elements', 'nprops' and 'eprops' (and optionally 'opt')"
        )
    bad = sorted(set(data) - {"nodes", "elements", "nprops", "eprops", "opt", "name"})
    if bad:
        raise SceneError(
            "scene", f"unknown SPACAR Light tables {bad}; the tables are nodes, elements, nprops, eprops, opt"
        )
    try:
        return spacar_light(
            data["nodes"],
            data["elements"],
            data.get("nprops") or [],
            data["eprops"],
            data.get("opt"),
            data.get("name", name),
        )
    except (TypeError, ValueError) as exc:
        if isinstance(exc, SceneError):
            raise
        raise SceneError(
            "scene",
            f"malformed SPACAR Light tables: {exc}; nodes is n x 3 numbers, elements "
            "n x 2 node numbers, nprops and eprops lists of objects",
        ) from None


def load_scene(path: str | Path) -> Scene:
    """Read and validate a scene JSON file, or a SPACAR ``.dat`` model (:mod:`model.spacar`)."""
    p = Path(path)
    try:
        text = p.read_text()
    except OSError as exc:
        raise SceneError("scene", f"cannot read scene file '{p}': {exc.strerror}") from None
    if p.suffix.lower() in (".dat", ".yaml", ".yml"):
        return load_dat(p)[0]
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise SceneError(
            "scene", f"'{p}' is not valid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})"
        ) from None
    if isinstance(data, dict) and "eprops" in data:  # SPACAR Light's tables (model.spacar.spacar_light)
        return scene_from_dict(_spacar_light(data, p.stem).scene)
    return scene_from_dict(data)
