"""Reading scenes: JSON or dict in, a validated Scene out, every problem as one SceneError."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from .errors import SceneError
from .scene import Scene

__all__ = ["scene_from_dict", "load_scene", "format_validation_error"]


def format_validation_error(exc: ValidationError) -> str:
    """One line per problem: ``field.path: message``."""
    lines = []
    for err in exc.errors():
        loc = ".".join(f"[{p}]" if isinstance(p, int) else str(p) for p in err["loc"]).replace(".[", "[")
        msg = err["msg"].removeprefix("Value error, ")
        if err["type"] == "extra_forbidden":
            msg = "unknown field; remove it or check its spelling"
        elif err["type"] == "missing":
            msg = "required field is missing; add it"
        lines.append(f"{loc or 'scene'}: {msg}")
    return "; ".join(lines)


def scene_from_dict(data: Any) -> Scene:
    """Validate a scene given as a dict. Raises SceneError naming each bad field."""
    if not isinstance(data, dict):
        raise SceneError("scene", "a scene is a JSON object with materials, nodes, elements, supports, stroke")
    try:
        return Scene.model_validate(data)
    except ValidationError as exc:
        raise SceneError("", format_validation_error(exc)) from None


def load_scene(path: str | Path) -> Scene:
    """Read and validate a scene JSON file."""
    p = Path(path)
    try:
        text = p.read_text()
    except OSError as exc:
        raise SceneError("scene", f"cannot read scene file '{p}': {exc.strerror}") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise SceneError("scene", f"'{p}' is not valid JSON (line {exc.lineno}, column {exc.colno}: "
                         f"{exc.msg})") from None
    return scene_from_dict(data)
