"""Parametric scenes with named parameters and sensible defaults.

``leaf-spring`` follows seed 000 section 3 (L 0.1 m, width 0.04 m, thickness 0.5 mm, steel E 210 GPa,
G 79 GPa, 7800 kg/m^3, ten elements, end rotation about the weak bending axis, +-45 degrees).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from .errors import SceneError
from .scene import Scene

__all__ = ["TEMPLATES", "template", "template_parameters"]

STEEL = dict(E=210e9, G=79e9, density=7800.0, allowable_stress=600e6)


def _steel(p: dict) -> dict:
    return {"name": "steel", "E": p["E"], "G": p["G"], "density": p["density"],
            "allowable_stress": p["allowable_stress"]}


def _leaf_spring(p: dict) -> dict:
    """A single leaf along x, width along y, thickness along z, clamped at x = 0; the free end is driven
    in rotation about y (the weak bending axis). Parasitic = out of the x-z driving plane."""
    L = p["length"]
    return {
        "name": "leaf-spring",
        "materials": [_steel(p)],
        "nodes": [{"name": "root", "position": [0, 0, 0]}, {"name": "tip", "position": [L, 0, 0]}],
        "elements": [{
            "kind": "beam", "name": "leaf", "nodes": ["root", "tip"], "material": "steel",
            "section": {"kind": "rectangular", "width": p["width"], "thickness": p["thickness"],
                        "warping": p["warping"]},
            "y_axis": [0, 1, 0], "segments": int(p["segments"]),
        }],
        "supports": [{"node": "root"}],
        "stroke": {"kind": "rotation", "node": "tip", "axis": [0, 1, 0], "start": -p["stroke"],
                   "stop": p["stroke"], "points": int(p["points"])},
        "support_directions": {"translations": [[0, 1, 0]], "rotations": [[1, 0, 0], [0, 0, 1]]},
        "modes": int(p["modes"]),
    }


def _parallel_leaf_spring(p: dict) -> dict:
    """Two leaves along x (width along y, thickness along z), a distance ``spacing`` apart along y, clamped
    at x = 0 and joined at x = L by a rigid intermediate body; stroke = its translation along z."""
    L, d = p["length"], p["spacing"]
    m = p["body_mass"]
    # body: a block at the leaf ends; inertia of a slender bar of length d along y (plus a thin depth)
    Jy = m * (p["body_depth"] ** 2) / 12.0
    Jx = m * (d**2) / 12.0
    inertia = [[Jx, 0, 0], [0, Jy, 0], [0, 0, Jx + Jy]]
    leaf = lambda name, a, b: {  # noqa: E731
        "kind": "beam", "name": name, "nodes": [a, b], "material": "steel",
        "section": {"kind": "rectangular", "width": p["width"], "thickness": p["thickness"],
                    "warping": p["warping"]},
        "y_axis": [0, 1, 0], "segments": int(p["segments"]),
    }
    return {
        "name": "parallel-leaf-spring",
        "materials": [_steel(p)],
        "nodes": [
            {"name": "root1", "position": [0, -d / 2, 0]}, {"name": "tip1", "position": [L, -d / 2, 0]},
            {"name": "root2", "position": [0, d / 2, 0]}, {"name": "tip2", "position": [L, d / 2, 0]},
        ],
        "bodies": [{"name": "stage", "mass": m, "center_of_mass": [L, 0, 0], "inertia": inertia,
                    "nodes": ["tip1", "tip2"]}],
        "elements": [leaf("leaf1", "root1", "tip1"), leaf("leaf2", "root2", "tip2")],
        "supports": [{"node": "root1"}, {"node": "root2"}],
        "stroke": {"kind": "translation", "body": "stage", "axis": [0, 0, 1], "start": -p["stroke"],
                   "stop": p["stroke"], "points": int(p["points"]), "unit": "m"},
        "modes": int(p["modes"]),
    }


def _cross_spring_pivot(p: dict) -> dict:
    """Two leaves crossing at their midpoints (crossing angle ``angle`` in degrees, symmetric about the
    y axis) between ground (y < 0) and a moving body (y > 0); the pivot axis is z and the leaves are
    offset along z by +-(width/2 + gap/2) so they do not intersect. Stroke = body rotation about z."""
    L, w = p["length"], p["width"]
    half = math.radians(p["angle"]) / 2.0
    c = w / 2.0 + p["gap"] / 2.0
    ux, uy = math.sin(half), math.cos(half)  # leaf A direction (from ground end to body end)
    a0 = [-ux * L / 2, -uy * L / 2, c]
    a1 = [ux * L / 2, uy * L / 2, c]
    b0 = [ux * L / 2, -uy * L / 2, -c]
    b1 = [-ux * L / 2, uy * L / 2, -c]
    m, hb = p["body_mass"], uy * L / 2 + p["body_offset"]
    r = p["body_radius"]
    inertia = [[m * r * r / 2, 0, 0], [0, m * r * r / 2, 0], [0, 0, m * r * r / 2]]
    leaf = lambda name, a, b: {  # noqa: E731
        "kind": "beam", "name": name, "nodes": [a, b], "material": "steel",
        "section": {"kind": "rectangular", "width": w, "thickness": p["thickness"], "warping": p["warping"]},
        "y_axis": [0, 0, 1], "segments": int(p["segments"]),
    }
    return {
        "name": "cross-spring-pivot",
        "materials": [_steel(p)],
        "nodes": [{"name": "a0", "position": a0}, {"name": "a1", "position": a1},
                  {"name": "b0", "position": b0}, {"name": "b1", "position": b1}],
        "bodies": [{"name": "rotor", "mass": m, "center_of_mass": [0, hb, 0], "inertia": inertia,
                    "nodes": ["a1", "b1"]}],
        "elements": [leaf("leafA", "a0", "a1"), leaf("leafB", "b0", "b1")],
        "supports": [{"node": "a0"}, {"node": "b0"}],
        "stroke": {"kind": "rotation", "body": "rotor", "axis": [0, 0, 1], "start": -p["stroke"],
                   "stop": p["stroke"], "points": int(p["points"])},
        "modes": int(p["modes"]),
    }


_COMMON = dict(STEEL, warping="free", points=91, modes=6)

TEMPLATES: dict[str, tuple[Callable[[dict], dict], dict[str, Any]]] = {
    "leaf-spring": (_leaf_spring, dict(_COMMON, length=0.1, width=0.04, thickness=0.5e-3, segments=10,
                                       stroke=45.0)),
    "parallel-leaf-spring": (_parallel_leaf_spring, dict(_COMMON, length=0.1, width=0.04, thickness=0.5e-3,
                                                         spacing=0.06, segments=10, body_mass=0.1,
                                                         body_depth=0.01, stroke=0.01)),
    "cross-spring-pivot": (_cross_spring_pivot, dict(_COMMON, length=0.05, width=0.02, thickness=0.3e-3,
                                                     angle=90.0, gap=0.002, segments=8, body_mass=0.1,
                                                     body_radius=0.02, body_offset=0.01, stroke=45.0)),
}


def template_parameters(name: str) -> dict[str, Any]:
    """The named parameters of a template with their defaults."""
    if name not in TEMPLATES:
        raise SceneError("template", f"unknown template '{name}'; choose one of {sorted(TEMPLATES)}")
    return dict(TEMPLATES[name][1])


def template(name: str, **overrides: Any) -> Scene:
    """The scene of template ``name`` with parameters overridden by keyword.

    Raises
    ------
    SceneError
        For an unknown template or parameter, or a value that gives an invalid scene.
    """
    params = template_parameters(name)
    for k, v in overrides.items():
        if k not in params:
            raise SceneError(f"template.{k}", f"template '{name}' has no parameter '{k}'; "
                             f"its parameters are {sorted(params)}")
        default = params[k]
        try:
            params[k] = type(default)(v) if not isinstance(default, str) else str(v)
        except (TypeError, ValueError) as exc:
            raise SceneError(f"template.{k}", f"cannot read '{v}' as {type(default).__name__}") from exc
    from .io import scene_from_dict

    return scene_from_dict(TEMPLATES[name][0](params))
