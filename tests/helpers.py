"""Shared test helpers: scene dicts from templates, path edits, rigid motions and unit changes of scenes.

Everything here works on the JSON form of a scene (a plain dict, as ``Scene.model_dump(mode="json")``
gives), so a test can break or transform a scene and then pass it through ``scene_from_dict`` like a
user's file.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from flexopt.model import template

__all__ = [
    "HINGES",
    "SEED_LEAF_LIGHT_SET",
    "COARSE_MESH",
    "coarse",
    "DELETE",
    "scene_dict",
    "edit",
    "rotation_from_quaternion",
    "rigid_motion",
    "scale_units",
]


#: The three classic flexures and the optimiser's three hinge families: the templates the methods' tests compare on
#: (bench/_common.py's HINGES, which the bench scripts use without importing the tests).
HINGES = (
    "leaf-spring",
    "parallel-leaf-spring",
    "cross-spring-pivot",
    "cartwheel-hinge",
    "three-fold-cross-hinge",
    "double-cross-hinge",
)


#: The meshes of the templates' defaults before issue 26 item 4 made them finer (segments per leaf, wire or
#: sheet). Tests whose check does not depend on the mesh (a method against another on one mesh, symmetry,
#: convergence of the continuation, finite gradients, ...) pass them through :func:`coarse`: the finer
#: defaults cost up to 7x (the cartwheel's 40 segments) to 10x (the folded sheets' 24), and figures quoted in
#: those tests were measured on these meshes. Never where the mesh matters to the check.
COARSE_MESH = {
    "cross-spring-pivot": 8,
    "cartwheel-hinge": 8,
    "three-fold-cross-hinge": 8,
    "double-cross-hinge": 8,
    "topology-hinge": 8,
    "wire-guide-5": 1,
    "wire-guide-parallel": 1,
    "folded-sheet-guide-5": 1,
    "folded-sheet-guide-6": 1,
    "folded-sheet-guide-5a": 1,
}


def coarse(name: str) -> dict[str, int]:
    """``{"segments": n}``: template ``name``'s former default mesh (:data:`COARSE_MESH`), or {} if unchanged."""
    return {"segments": COARSE_MESH[name]} if name in COARSE_MESH else {}


class _Delete:
    """Marker for :func:`edit`: remove the field instead of setting it."""

    def __repr__(self) -> str:
        return "DELETE"


#: Use as a value in :func:`edit` to remove a field.
DELETE = _Delete()


def scene_dict(name: str = "leaf-spring", **params: Any) -> dict[str, Any]:
    """The JSON form (a fresh dict) of template ``name`` with ``params`` overridden."""
    return template(name, **params).model_dump(mode="json")


def _split(path: str) -> list[str | int]:
    return [int(p) if p.lstrip("-").isdigit() else p for p in path.split(".")]


def edit(data: Mapping[str, Any], changes: Mapping[str, Any]) -> dict[str, Any]:
    """A deep copy of ``data`` with each dotted ``path: value`` of ``changes`` applied, in order.

    Integer parts index lists (``"elements.0.section.width"``; ``-1`` is the last item); a path that ends
    in ``+`` appends ``value`` to that list (``"nodes.+"``); the value :data:`DELETE` removes the field.
    Values are deep-copied, so one table entry can be applied many times.
    """
    out = copy.deepcopy(dict(data))
    for path, value in changes.items():
        parts = _split(path)
        parent: Any = out
        for p in parts[:-1]:
            parent = parent[p]
        last = parts[-1]
        if last == "+":
            parent.append(copy.deepcopy(value))
        elif value is DELETE:
            del parent[last]
        else:
            parent[last] = copy.deepcopy(value)
    return out


def rotation_from_quaternion(q: Sequence[float]) -> np.ndarray:
    """The rotation matrix of the (not necessarily unit, non-zero) quaternion ``q = (w, x, y, z)``.

    Normalised quaternions from a distribution symmetric about the origin give rotations spread over SO(3).
    """
    w, x, y, z = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


_FULL_TRIPLES = ({"x", "y", "z"}, {"rx", "ry", "rz"})


def rigid_motion(data: Mapping[str, Any], R: np.ndarray, t: Sequence[float]) -> dict[str, Any]:
    """The scene moved rigidly: every point ``p -> R p + t``, every direction ``v -> R v``, inertia
    ``J -> R J R^T``.

    Moved: node positions, body centres of mass and inertia tensors, beam ``y_axis`` vectors, the stroke
    axis and the support directions. Section properties are in the local (member) frame and stay.
    Support ``dofs`` name *global* coordinates, so a support that fixes only some of the x, y, z (or rx,
    ry, rz) coordinates has no rotated equivalent: such a scene is refused with ``ValueError``.
    """
    R = np.asarray(R, dtype=float)
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-12) and np.linalg.det(R) > 0, "R must be a rotation"
    t = np.asarray(t, dtype=float)
    out = copy.deepcopy(dict(data))

    def point(p: Sequence[float]) -> list[float]:
        return [float(v) for v in R @ np.asarray(p, dtype=float) + t]

    def direction(v: Sequence[float]) -> list[float]:
        return [float(c) for c in R @ np.asarray(v, dtype=float)]

    for s in out.get("supports", []):
        dofs = set(s.get("dofs") or ("x", "y", "z", "rx", "ry", "rz"))
        if s.get("node") is not None and any(0 < len(dofs & tri) < 3 for tri in _FULL_TRIPLES):
            raise ValueError(f"support {s} fixes only some global coordinates; it has no rotated equivalent")
    for n in out["nodes"]:
        n["position"] = point(n["position"])
    for b in out.get("bodies", []):
        b["center_of_mass"] = point(b["center_of_mass"])
        J = R @ np.asarray(b.get("inertia", np.zeros((3, 3))), dtype=float) @ R.T
        b["inertia"] = (0.5 * (J + J.T)).tolist()  # the exact tensor is symmetric; drop rounding asymmetry
    for e in out["elements"]:
        if "y_axis" in e:
            e["y_axis"] = direction(e["y_axis"])
    out["stroke"]["axis"] = direction(out["stroke"]["axis"])
    sd = out.get("support_directions")
    if sd:
        for key in ("translations", "rotations"):
            sd[key] = [direction(v) for v in sd.get(key, [])]
    return out


def scale_units(data: Mapping[str, Any], length: float, mass: float) -> dict[str, Any]:
    """The same scene in other consistent units: length unit ``length`` metres, mass unit ``mass`` kg,
    time unit the second (so frequencies in Hz do not change).

    Force unit ``mass*length`` N, stress unit ``mass/length`` Pa. ``length=1e-3, mass=1e3`` gives the
    mm-N-tonne-s system: lengths x1e3, E, G and stresses x1e-6 (MPa), density x1e-12 (tonne/mm^3),
    masses x1e-3 (tonne), inertias x1e3 (tonne mm^2), translation strokes x1e3.
    """
    L, M = 1.0 / length, 1.0 / mass  # factor to multiply a value in m (kg) by, to get the new unit
    stress = M / L  # Pa = kg / (m s^2)
    out = copy.deepcopy(dict(data))
    for m in out["materials"]:
        for k in ("E", "G", "allowable_stress"):
            m[k] *= stress
        m["density"] *= M / L**3
    for n in out["nodes"]:
        n["position"] = [v * L for v in n["position"]]
    for b in out.get("bodies", []):
        b["mass"] = b.get("mass", 0.0) * M
        b["center_of_mass"] = [v * L for v in b["center_of_mass"]]
        b["inertia"] = [[v * M * L**2 for v in row] for row in b.get("inertia", [[0.0] * 3] * 3)]
    for e in out["elements"]:
        if e.get("kind", "beam") == "truss":
            e["area"] *= L**2
            continue
        sec = e["section"]
        if sec.get("kind", "rectangular") == "rectangular":
            sec["width"] *= L
            sec["thickness"] *= L
        else:
            sec["A"] *= L**2
            for k in ("Iy", "Iz", "J"):
                sec[k] *= L**4
            for k in ("cy", "cz"):
                if sec.get(k) is not None:
                    sec[k] *= L
            if sec.get("torsion_stress_factor") is not None:
                sec["torsion_stress_factor"] /= L**3
    st = out["stroke"]
    if st.get("kind", "rotation") == "translation":
        for k in ("start", "stop"):
            if st.get(k) is not None:
                st[k] *= L
    return out


#: SPACAR Light's element set of the seed leaf (eprops: steel, a 40 x 0.5 mm rectangle, 4 beams, every
#: deformation flexible): the leaf-spring template written as a SPACAR Light script would (tests/test_spacar*.py)
SEED_LEAF_LIGHT_SET: dict[str, Any] = {
    "elems": [1],
    "emod": 210e9,
    "smod": 79e9,
    "dens": 7800,
    "cshape": "rect",
    "dim": [0.04, 0.0005],
    "orien": [0, 1, 0],
    "nbeams": 4,
    "flex": [1, 2, 3, 4, 5, 6],
}
