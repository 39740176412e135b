"""Parametric scenes with named parameters and sensible defaults.

``leaf-spring`` follows seed 000 section 3 (L 0.1 m, width 0.04 m, thickness 0.5 mm, steel E 210 GPa,
G 79 GPa, 7800 kg/m^3, ten elements, end rotation about the weak bending axis, +-45 degrees).
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import casadi as ca

from .errors import SceneError
from .scene import Scene

if TYPE_CHECKING:
    from pydantic import ValidationError

__all__ = [
    "TEMPLATES",
    "DESIGN_SPACES",
    "PARAMETER_UNITS",
    "design_space",
    "parameter_unit",
    "start_value",
    "template",
    "template_parameters",
]

STEEL = dict(E=210e9, G=79e9, density=7800.0, allowable_stress=600e6)


def _steel(p: dict) -> dict:
    return {
        "name": "steel",
        "E": p["E"],
        "G": p["G"],
        "density": p["density"],
        "allowable_stress": p["allowable_stress"],
    }


def _leaf_spring(p: dict) -> dict:
    """A single leaf along x, width along y, thickness along z, clamped at x = 0; the free end is driven
    in rotation about y (the weak bending axis). Parasitic = out of the x-z driving plane."""
    L = p["length"]
    return {
        "name": "leaf-spring",
        "materials": [_steel(p)],
        "nodes": [{"name": "root", "position": [0, 0, 0]}, {"name": "tip", "position": [L, 0, 0]}],
        "elements": [
            {
                "kind": "beam",
                "name": "leaf",
                "nodes": ["root", "tip"],
                "material": "steel",
                "section": {
                    "kind": "rectangular",
                    "width": p["width"],
                    "thickness": p["thickness"],
                    "warping": p["warping"],
                },
                "y_axis": [0, 1, 0],
                "segments": int(p["segments"]),
            }
        ],
        "supports": [{"node": "root"}],
        "stroke": {
            "kind": "rotation",
            "node": "tip",
            "axis": [0, 1, 0],
            "start": -p["stroke"],
            "stop": p["stroke"],
            "points": int(p["points"]),
        },
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
        "kind": "beam",
        "name": name,
        "nodes": [a, b],
        "material": "steel",
        "section": {"kind": "rectangular", "width": p["width"], "thickness": p["thickness"], "warping": p["warping"]},
        "y_axis": [0, 1, 0],
        "segments": int(p["segments"]),
    }
    return {
        "name": "parallel-leaf-spring",
        "materials": [_steel(p)],
        "nodes": [
            {"name": "root1", "position": [0, -d / 2, 0]},
            {"name": "tip1", "position": [L, -d / 2, 0]},
            {"name": "root2", "position": [0, d / 2, 0]},
            {"name": "tip2", "position": [L, d / 2, 0]},
        ],
        "bodies": [
            {"name": "stage", "mass": m, "center_of_mass": [L, 0, 0], "inertia": inertia, "nodes": ["tip1", "tip2"]}
        ],
        "elements": [leaf("leaf1", "root1", "tip1"), leaf("leaf2", "root2", "tip2")],
        "supports": [{"node": "root1"}, {"node": "root2"}],
        "stroke": {
            "kind": "translation",
            "body": "stage",
            "axis": [0, 0, 1],
            "start": -p["stroke"],
            "stop": p["stroke"],
            "points": int(p["points"]),
            "unit": "m",
        },
        "modes": int(p["modes"]),
    }


def _cross_spring_pivot(p: dict) -> dict:
    """Two leaves crossing (crossing angle ``angle`` in degrees, symmetric about the y axis) between ground
    (y < 0) and a moving body (y > 0); the pivot axis is z through the crossing point, which lies at the
    fraction ``crossing`` of each leaf's length from its ground end (0.5: the classic pivot crossing at the
    midpoints; Jensen and Howell's generalised cross-axis pivot varies it). The leaves are offset along z
    by +-(width/2 + gap/2) so they do not intersect. Stroke = body rotation about z. Traceable (casadi
    maths on continuous parameters, see model/design.py)."""
    L, w, lam = p["length"], p["width"], p["crossing"]
    half = p["angle"] * ca.pi / 360.0
    c = w / 2.0 + p["gap"] / 2.0
    ux, uy = ca.sin(half), ca.cos(half)  # leaf A direction (from ground end to body end)
    a0 = [-ux * L * lam, -uy * L * lam, c]
    a1 = [ux * L * (1 - lam), uy * L * (1 - lam), c]
    b0 = [ux * L * lam, -uy * L * lam, -c]
    b1 = [-ux * L * (1 - lam), uy * L * (1 - lam), -c]
    m, hb = p["body_mass"], uy * L * (1 - lam) + p["body_offset"]
    r = p["body_radius"]
    inertia = [[m * r * r / 2, 0, 0], [0, m * r * r / 2, 0], [0, 0, m * r * r / 2]]
    leaf = lambda name, a, b: {  # noqa: E731
        "kind": "beam",
        "name": name,
        "nodes": [a, b],
        "material": "steel",
        "section": {"kind": "rectangular", "width": w, "thickness": p["thickness"], "warping": p["warping"]},
        "y_axis": [0, 0, 1],
        "segments": int(p["segments"]),
    }
    return {
        "name": "cross-spring-pivot",
        "materials": [_steel(p)],
        "nodes": [
            {"name": "a0", "position": a0},
            {"name": "a1", "position": a1},
            {"name": "b0", "position": b0},
            {"name": "b1", "position": b1},
        ],
        "bodies": [
            {"name": "rotor", "mass": m, "center_of_mass": [0, hb, 0], "inertia": inertia, "nodes": ["a1", "b1"]}
        ],
        "elements": [leaf("leafA", "a0", "a1"), leaf("leafB", "b0", "b1")],
        "supports": [{"node": "a0"}, {"node": "b0"}],
        "stroke": {
            "kind": "rotation",
            "body": "rotor",
            "axis": [0, 0, 1],
            "start": -p["stroke"],
            "stop": p["stroke"],
            "points": int(p["points"]),
        },
        "modes": int(p["modes"]),
    }


_COMMON = dict(STEEL, warping="free", points=91, modes=6)

TEMPLATES: dict[str, tuple[Callable[[dict], dict], dict[str, Any]]] = {
    "leaf-spring": (_leaf_spring, dict(_COMMON, length=0.1, width=0.04, thickness=0.5e-3, segments=10, stroke=45.0)),
    "parallel-leaf-spring": (
        _parallel_leaf_spring,
        dict(
            _COMMON,
            length=0.1,
            width=0.04,
            thickness=0.5e-3,
            spacing=0.06,
            segments=10,
            body_mass=0.1,
            body_depth=0.01,
            stroke=0.01,
        ),
    ),
    "cross-spring-pivot": (
        _cross_spring_pivot,
        dict(
            _COMMON,
            length=0.05,
            width=0.02,
            thickness=0.3e-3,
            angle=90.0,
            crossing=0.5,
            gap=0.002,
            segments=12,
            body_mass=0.1,
            body_radius=0.02,
            body_offset=0.01,
            stroke=45.0,
        ),
    ),
}


#: SI unit of each template parameter (``""``: a plain number; absent: a count or a word). A parameter given
#: as a string with a unit (``"0.3 mm"``, ``--set thickness=0.3mm``) is converted to this unit with pint.
PARAMETER_UNITS: dict[str, str] = {
    **dict.fromkeys(("E", "G", "allowable_stress"), "Pa"),
    "density": "kg/m^3",
    **dict.fromkeys(
        (
            "length",
            "width",
            "thickness",
            "spacing",
            "gap",
            "body_depth",
            "body_radius",
            "body_offset",
            "half_width",
            "height",
            "wire_length",
            "wire_diameter",
            "sheet_length",
            "sheet_width",
            "sheet_thickness",
            "body_length",
            "body_width",
            "body_height",
        ),
        "m",
    ),
    **dict.fromkeys(("body_mass", "mid_mass"), "kg"),
    "area": "m^2",
    "angle": "deg",
    "crossing": "",
}
#: Templates whose ``stroke`` parameter is a translation [m]; in the others it is a rotation [deg].
_TRANSLATION_TEMPLATES = frozenset(
    {
        "parallel-leaf-spring",
        "wire-guide-5",
        "wire-guide-parallel",
        "wire-guide-topology",
        "folded-sheet-guide-5",
        "folded-sheet-guide-6",
        "folded-sheet-guide-5a",
    }
)


def parameter_unit(name: str, parameter: str) -> str | None:
    """The SI unit of ``parameter`` of template ``name`` (None for counts and words)."""
    if parameter == "stroke":
        return "m" if name in _TRANSLATION_TEMPLATES else "deg"
    return PARAMETER_UNITS.get(parameter)


def template_parameters(name: str) -> dict[str, Any]:
    """The named parameters of a template with their defaults."""
    if name not in TEMPLATES:
        from .scene import did_you_mean

        raise SceneError(
            "template",
            f"unknown template '{name}'{did_you_mean(name, sorted(TEMPLATES))}; "
            f"choose one of {', '.join(sorted(TEMPLATES))}",
        )
    return dict(TEMPLATES[name][1])


def _read_parameter(name: str, key: str, default: Any, v: Any) -> Any:
    """One override as the type of its default; strings with a unit are converted to the parameter's SI unit."""
    where = f"template.{key}"
    if isinstance(default, str):
        return str(v)
    unit = parameter_unit(name, key)
    kind = "an integer" if isinstance(default, int) else "a number"
    if isinstance(v, str):
        try:
            num = float(v)
        except ValueError:
            if unit is None:
                raise SceneError(
                    where,
                    f"cannot read '{v}' as {type(default).__name__}: template parameter '{key}' is {kind} without unit",
                ) from None
            from .units import UnitsError, quantity_to

            try:
                num = quantity_to(v, unit)
            except UnitsError as exc:
                raise SceneError(
                    where,
                    f"cannot read '{v}' as float or as a quantity in {unit or 'no unit'} "
                    f"(template parameter '{key}'): {exc}",
                ) from None
        v = num
    if isinstance(v, bool) or not isinstance(v, numbers.Real):
        raise SceneError(where, f"template parameter '{key}' must be {kind}, got {v!r}")
    v = float(v) if not isinstance(v, int) else v
    if not math.isfinite(v):
        raise SceneError(where, f"template parameter '{key}' must be a finite number, got {v}")
    if isinstance(default, int):
        if v != int(v):
            raise SceneError(where, f"template parameter '{key}' must be an integer, got {v}")
        return int(v)
    return float(v)


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, bool) or isinstance(b, bool):
        return False
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        return a == b or (math.isnan(a) and math.isnan(b))
    return isinstance(a, str) and a == b


def _at(data: Any, loc: tuple) -> Any:
    for p in loc:
        try:
            data = data[p]
        except (KeyError, IndexError, TypeError):
            return None
    return data


def _parameter_error(
    name: str, params: dict[str, Any], overrides: dict[str, Any], data: dict, exc: ValidationError
) -> SceneError:
    """A scene error of a template's scene, told in terms of the template parameter that caused it.

    The offending scene value is traced back to the parameter holding the same value (overridden
    parameters first); when none matches (a derived value), the scene path is kept.
    """
    from .io import clean_errors, format_validation_error

    for err in clean_errors(exc.errors()):
        if err["type"] == "too_short":
            continue
        value = _at(data, err["loc"])
        order = [k for k in overrides if k in params] + [k for k in params if k not in overrides]
        hits = [k for k in order if _same(params[k], value)]
        if hits:
            key = hits[0]
            unit = parameter_unit(name, key)
            msg = err["msg"].removeprefix("Value error, ").replace("Input should be", "must be")
            shown = f"{params[key]!r}" + (f" {unit}" if unit else "")
            return SceneError(f"template.{key}", f"template parameter '{key}' = {shown}: {msg}; change '{key}'")
    given = ", ".join(
        f"{k} = {params[k]!r}" + (f" {parameter_unit(name, k)}" if parameter_unit(name, k) else "")
        for k in overrides
        if k in params
    )
    key = next(iter(overrides), None) if len(overrides) == 1 else None
    return SceneError(
        f"template.{key}" if key else "",
        f"template '{name}' with {given or 'its defaults'} gives an "
        f"invalid scene: {format_validation_error(exc)}; change " + (f"'{key}'" if key else "the parameters"),
    )


def template(name: str, **overrides: Any) -> Scene:
    """The scene of template ``name`` with parameters overridden by keyword.

    A value may be a string with a unit (``thickness="0.3 mm"``): it is converted to the parameter's SI
    unit (:data:`PARAMETER_UNITS`; a rotation stroke in deg). Plain numbers are in that unit already.

    Raises
    ------
    SceneError
        For an unknown template or parameter (with the closest name), or a value that gives an invalid
        scene (naming the template parameter, not the scene path, when the value is a parameter's).
    """
    params = template_parameters(name)
    for k, v in overrides.items():
        if k not in params:
            from .scene import did_you_mean

            raise SceneError(
                f"template.{k}",
                f"template '{name}' has no parameter '{k}'"
                f"{did_you_mean(k, sorted(params))}; its parameters are {sorted(params)}",
            )
        params[k] = _read_parameter(name, k, params[k], v)
    from pydantic import ValidationError

    from .scene import Scene

    data = TEMPLATES[name][0](params)
    try:
        return Scene.model_validate(data)
    except ValidationError as exc:
        raise _parameter_error(name, params, overrides, data, exc) from None


# ----------------------------------------------------------------------------------------------------------
# Scenes of seed 002 (Aarts, van Dijk and Jonker): exact-constraint examples. Appended; the templates above
# are unchanged.


def _truss12(p: dict) -> dict:
    """Figure 2 of seed 002: twelve rigid trusses. Supports at (+-a, +-a, 0); top nodes (a, 0, h),
    (0, a, h), (-a, 0, h), (0, -a, h) (a = ``half_width``, h = ``height``; the paper has a = h = 1), each
    joined to its two nearest supports and to its two neighbours (the top square). Every elongation rigid;
    no drive (``stroke: null``): a structure for the exact-constraint diagnosis only."""
    a, h = p["half_width"], p["height"]
    sup = {"s_pp": (a, a), "s_mp": (-a, a), "s_mm": (-a, -a), "s_pm": (a, -a)}
    top = {"t_px": (a, 0.0), "t_py": (0.0, a), "t_mx": (-a, 0.0), "t_my": (0.0, -a)}
    nodes = [{"name": k, "position": [x, y, 0.0]} for k, (x, y) in sup.items()]
    nodes += [{"name": k, "position": [x, y, h]} for k, (x, y) in top.items()]
    legs = [
        ("t_px", "s_pp"),
        ("t_px", "s_pm"),
        ("t_py", "s_pp"),
        ("t_py", "s_mp"),
        ("t_mx", "s_mp"),
        ("t_mx", "s_mm"),
        ("t_my", "s_mm"),
        ("t_my", "s_pm"),
    ]
    ring = [("t_px", "t_py"), ("t_py", "t_mx"), ("t_mx", "t_my"), ("t_my", "t_px")]
    elements = [
        {
            "kind": "truss",
            "name": f"{s}-{t}",
            "nodes": [s, t],
            "material": "steel",
            "area": p["area"],
            "rigid": ["elongation"],
        }
        for s, t in legs + ring
    ]
    return {
        "name": "truss12",
        "materials": [_steel(p)],
        "nodes": nodes,
        "elements": elements,
        "supports": [{"node": k} for k in sup],
        "stroke": None,
        "modes": int(p["modes"]),
    }


def _box_inertia(m: float, a: float, b: float, c: float) -> list[list[float]]:
    return [[m * (b * b + c * c) / 12, 0, 0], [0, m * (a * a + c * c) / 12, 0], [0, 0, m * (a * a + b * b) / 12]]


def _wire_guide(p: dict, parallel: bool) -> dict:
    """Figure 3a of seed 002 (geometry reconstructed): a block ``2a x 2b x 2c`` (x, y, z) centred at the
    origin guided along x by five wire flexures of length ``wire_length``. Three vertical wires (along z)
    under the block at (-0.8a, -0.75b), (-0.8a, +0.75b), (+0.8a, 0) fix z, rx, ry; two lateral wires (along
    y) on the face y = -b at x = -0.8a and x = +0.8a fix y and rz. With ``parallel`` the second lateral wire
    moves to x = -0.8a (above the first, at z = +0.5c): the two lateral wires are parallel and meet the
    same constraint line pattern, so one constraint is repeated (a self-stress) and the rotation about the
    vertical axis through x = -0.8a is free (a mechanism). Square wires of side ``wire_diameter``."""
    return _wire_block(
        p,
        ["z--", "z-+", "z+0", "y--", "y-+"] if parallel else ["z--", "z-+", "z+0", "y-0", "y+0"],
        "wire-guide-parallel" if parallel else "wire-guide-5",
    )


_STEP = {"-": -1.0, "0": 0.0, "+": 1.0}


def guide_layout(descriptor: str) -> list[str]:
    """Read a wire-guide descriptor ``T:<wire>,<wire>,...`` (the grammar of optim/topology/grammar.py).

    A wire is its direction and two places: ``z<i><j>`` a vertical wire under the block at
    ``(0.8 a i, 0.75 b j, -c)``, ``y<i><k>`` a lateral wire on the face y = -b at ``(0.8 a i, -b, 0.5 c k)``,
    each of ``i, j, k`` one of ``-``, ``0``, ``+`` (the block is ``2a x 2b x 2c``, guided along x; seed 002
    Figure 3a is ``T:z--,z-+,z+0,y-0,y+0``).

    Raises
    ------
    SceneError
        On a malformed descriptor or a wire given twice.
    """
    where = "template.topology"
    if not isinstance(descriptor, str) or not descriptor.startswith("T:"):
        raise SceneError(where, f"guide topology '{descriptor}' must start with 'T:', e.g. 'T:z--,z-+,z+0,y-0,y+0'")
    wires = descriptor[2:].split(",")
    for w in wires:
        if len(w) != 3 or w[0] not in "yz" or w[1] not in _STEP or w[2] not in _STEP:
            raise SceneError(
                where,
                f"guide topology '{descriptor}': wire '{w}' must be 'z' or 'y' and two of '-', '0', '+' (e.g. 'z-+')",
            )
    if len(set(wires)) != len(wires):
        raise SceneError(where, f"guide topology '{descriptor}' places a wire twice")
    return wires


def _wire_block(p: dict, wires: list[str], name: str) -> dict:
    """A block guided along x by wire flexures placed by :func:`guide_layout`'s tokens (square wires of side
    ``wire_diameter`` and length ``wire_length``, their ground ends supported; kinematic: a wire keeps its
    elongation rigid)."""
    a, b, c = p["body_length"] / 2, p["body_width"] / 2, p["body_height"] / 2
    Lw, d = p["wire_length"], p["wire_diameter"]
    nodes, elements, supports, carried = [], [], [], []
    for k, tok in enumerate(wires, start=1):
        i, j = _STEP[tok[1]], _STEP[tok[2]]
        at, direction = (
            ((0.8 * a * i, 0.75 * b * j, -c), (0, 0, 1))
            if tok[0] == "z"
            else ((0.8 * a * i, -b, 0.5 * c * j), (0, 1, 0))
        )
        wname = f"wire{k}"
        base = [at[q] - Lw * direction[q] for q in range(3)]
        nodes.extend([{"name": f"{wname}_body", "position": list(at)}, {"name": f"{wname}_ground", "position": base}])
        carried.append(f"{wname}_body")
        supports.append({"node": f"{wname}_ground"})
        elements.append(
            {
                "kind": "beam",
                "name": wname,
                "nodes": [f"{wname}_ground", f"{wname}_body"],
                "material": "steel",
                "section": {"kind": "rectangular", "width": d, "thickness": d},
                "y_axis": [1, 0, 0],
                "segments": int(p["segments"]),
                "rigid": [],
            }
        )
    m = p["body_mass"]
    return {
        "name": name,
        "materials": [_steel(p)],
        "nodes": nodes,
        "bodies": [
            {
                "name": "slider",
                "mass": m,
                "center_of_mass": [0, 0, 0],
                "inertia": _box_inertia(m, 2 * a, 2 * b, 2 * c),
                "nodes": carried,
            }
        ],
        "elements": elements,
        "supports": supports,
        "stroke": {
            "kind": "translation",
            "body": "slider",
            "axis": [1, 0, 0],
            "start": -p["stroke"],
            "stop": p["stroke"],
            "points": int(p["points"]),
            "unit": "m",
            "drive": "free",
        },
        "kinematic": True,
        "modes": int(p["modes"]),
    }


def _folded_sheet_guide(p: dict, count: int, variant: str = "") -> dict:
    """Figures 3b (five) and 5b (six) of seed 002, geometry reconstructed from the figures.

    The moving part is a solid cylinder (mass ``body_mass``, radius ``body_radius``, length ``body_length``)
    on the x axis, guided along x. Each folded sheet flexure is two sheets (``sheet_length`` x
    ``sheet_width`` x ``sheet_thickness``, one beam each) folded at 90 degrees along a fold line ``f``
    tangent to the cylinder (perpendicular to x and to the radius ``n`` at its attachment point P on the
    cylinder's surface): sheet B runs from P along ``(x + n)/sqrt 2`` to the fold F, sheet A from F along
    ``(x - n)/sqrt 2`` to the support S, which lies at the radius of P, ``sqrt 2 sheet_length`` further
    along x. The width of both sheets is along ``f``, so the flexure constrains only the translation
    along ``f`` at F (section 4.2) and its internal mode is a rotation about the fold.

    Five flexures (3b): three at x = -body_length/2 at angles 90, 210, 330 degrees about x (angle 0 = +y,
    90 = +z) and two at x = +body_length/4 at 30 and 150 degrees (three on one side, two on the other;
    exactly constrained). Six (5b): the same plus one at 270 degrees on the second side, three on each
    side; overconstrained with one self-stress of in-plane bending in every sheet, as the paper finds.
    (Two flexures at 90 and 270 degrees on the second side instead, whose fold lines are parallel, give
    the under- and overconstrained design of Figure 5a.) In the kinematic diagnosis every sheet keeps
    elongation and in-plane bending (bending_z) rigid, and one out-of-plane bending of each flexure is a
    generalised deformation (section 4.2): eps4 of sheet B, measured at the fold (eps3, at the body end,
    has the rate of sheet A's elongation and would make D_cc singular).
    """
    R, Lb, Ls = p["body_radius"], p["body_length"], p["sheet_length"]
    if variant == "a":  # Figure 5a: the second side's two flexures at 90 and 270 degrees, fold lines parallel
        places = [(-Lb / 2, 90.0), (-Lb / 2, 210.0), (-Lb / 2, 330.0), (Lb / 4, 90.0), (Lb / 4, 270.0)]
    elif count == 5:
        places = [(-Lb / 2, 90.0), (-Lb / 2, 210.0), (-Lb / 2, 330.0), (Lb / 4, 30.0), (Lb / 4, 150.0)]
    else:
        places = [(-Lb / 2, 90.0), (-Lb / 2, 210.0), (-Lb / 2, 330.0), (Lb / 4, 30.0), (Lb / 4, 150.0), (Lb / 4, 270.0)]
    s2 = math.sqrt(0.5)
    nodes, elements, supports, carried = [], [], [], []
    sec = {"kind": "rectangular", "width": p["sheet_width"], "thickness": p["sheet_thickness"]}
    for i, (x0, deg) in enumerate(places, start=1):
        th = math.radians(deg)
        n = (0.0, math.cos(th), math.sin(th))
        f = (0.0, -math.sin(th), math.cos(th))
        P = (x0, R * n[1], R * n[2])
        b = tuple(s2 * (u + v) for u, v in zip((1.0, 0.0, 0.0), n))
        a = tuple(s2 * (u - v) for u, v in zip((1.0, 0.0, 0.0), n))
        F = tuple(P[k] + Ls * b[k] for k in range(3))
        S = tuple(F[k] + Ls * a[k] for k in range(3))
        tag = f"flex{i}"
        nodes += [
            {"name": f"{tag}_body", "position": list(P)},
            {"name": f"{tag}_fold", "position": list(F)},
            {"name": f"{tag}_ground", "position": list(S)},
        ]
        carried.append(f"{tag}_body")
        supports.append({"node": f"{tag}_ground"})
        elements.append(
            {
                "kind": "beam",
                "name": f"{tag}B",
                "nodes": [f"{tag}_body", f"{tag}_fold"],
                "material": "steel",
                "section": sec,
                "y_axis": list(f),
                "segments": int(p["segments"]),
                "generalised": ["eps4"],
            }
        )
        elements.append(
            {
                "kind": "beam",
                "name": f"{tag}A",
                "nodes": [f"{tag}_fold", f"{tag}_ground"],
                "material": "steel",
                "section": sec,
                "y_axis": list(f),
                "segments": int(p["segments"]),
            }
        )
    m = p["body_mass"]
    Jx = m * R * R / 2
    Jt = m * (3 * R * R + Lb * Lb) / 12
    return {
        "name": f"folded-sheet-guide-{count}{variant}",
        "materials": [_steel(p)],
        "nodes": nodes,
        "bodies": [
            {
                "name": "cylinder",
                "mass": m,
                "center_of_mass": [0, 0, 0],
                "inertia": [[Jx, 0, 0], [0, Jt, 0], [0, 0, Jt]],
                "nodes": carried,
            }
        ],
        "elements": elements,
        "supports": supports,
        "stroke": {
            "kind": "translation",
            "body": "cylinder",
            "axis": [1, 0, 0],
            "start": -p["stroke"],
            "stop": p["stroke"],
            "points": int(p["points"]),
            "unit": "m",
            "drive": "free",
        },
        "kinematic": True,
        "modes": int(p["modes"]),
    }


# Default meshes (issue 26 item 4): every template's default curve is within 0.5 % of the converged one over
# its default stroke and its mesh estimate stays below the mesh warning (tests/test_mesh.py, measured with
# python bench/bench_mesh_estimate.py): hinges 12 segments per leaf (8 read 0.6-0.8 % off at +-45 deg), the
# cartwheel 40 (20 per half leaf; 4 read 8.8 % off), wire guides 8 per wire (1 read 3.4 %; at 4 the estimate
# from 2 still reads 0.58 %), folded sheets 24 per sheet (1 read 56 %; 16 read 0.52 %).
_WIRE = dict(
    _COMMON,
    body_length=0.1,
    body_width=0.04,
    body_height=0.03,
    body_mass=0.3,
    wire_length=0.05,
    wire_diameter=1e-3,
    segments=8,
    stroke=0.002,
    points=11,
)
_FOLDED = dict(
    _COMMON,
    body_radius=0.02,
    body_length=0.1,
    body_mass=0.312,
    sheet_length=0.05,
    sheet_width=0.02,
    sheet_thickness=0.2e-3,
    segments=24,
    stroke=0.002,
    points=11,
)
TEMPLATES.update(
    {
        "truss12": (_truss12, dict(_COMMON, half_width=1.0, height=1.0, area=1e-4)),
        "wire-guide-5": (lambda p: _wire_guide(p, False), dict(_WIRE)),
        "wire-guide-parallel": (lambda p: _wire_guide(p, True), dict(_WIRE)),
        # a generated wire guide (optim/topology): wires placed by a descriptor, see guide_layout
        "wire-guide-topology": (
            lambda p: _wire_block(p, guide_layout(p["topology"]), f"guide {p['topology']}"),
            dict(_WIRE, topology="T:z--,z-+,z+0,y-0,y+0"),
        ),
        "folded-sheet-guide-5": (lambda p: _folded_sheet_guide(p, 5), dict(_FOLDED)),
        "folded-sheet-guide-6": (lambda p: _folded_sheet_guide(p, 6), dict(_FOLDED)),
        # Figure 5a: five flexures, the second side's two with parallel fold lines (90 and 270 degrees): the
        # paper's kinematic analysis finds it under- and overconstrained at once (one free motion, one
        # self-stress); tests/test_topology.py checks that the topology filter finds it so
        "folded-sheet-guide-5a": (lambda p: _folded_sheet_guide(p, 5, "a"), dict(_FOLDED)),
    }
)


# ----------------------------------------------------------------------------------------------------------
# Rotational hinge families searched by the optimiser (optim/). All traceable: casadi maths on continuous
# parameters, so model/design.py can differentiate their scenes. Leaves are steel beams with rectangular
# sections, width along the hinge axis z; stiff parts are rigid bodies; stroke = rotor rotation about z.


def _rotor(m: float, r: float, com: list, nodes: list[str], name: str = "rotor") -> dict:
    inertia = [[m * r * r / 2, 0, 0], [0, m * r * r / 2, 0], [0, 0, m * r * r / 2]]
    return {"name": name, "mass": m, "center_of_mass": com, "inertia": inertia, "nodes": nodes}


def _leaf(p: dict, name: str, a: str, b: str, width, segments: int, thickness=None) -> dict:
    t = p["thickness"] if thickness is None else thickness
    return {
        "kind": "beam",
        "name": name,
        "nodes": [a, b],
        "material": "steel",
        "section": {"kind": "rectangular", "width": width, "thickness": t, "warping": p["warping"]},
        "y_axis": [0, 0, 1],
        "segments": segments,
    }


def _hinge(p: dict, name: str, nodes: list, bodies: list, elements: list, supports: list[str]) -> dict:
    return {
        "name": name,
        "materials": [_steel(p)],
        "nodes": [{"name": k, "position": v} for k, v in nodes],
        "bodies": bodies,
        "elements": elements,
        "supports": [{"node": k} for k in supports],
        "stroke": {
            "kind": "rotation",
            "body": "rotor",
            "axis": [0, 0, 1],
            "start": -p["stroke"],
            "stop": p["stroke"],
            "points": int(p["points"]),
        },
        "modes": int(p["modes"]),
    }


def _cartwheel_hinge(p: dict) -> dict:
    """Cartwheel hinge (monolithic cross-spring pivot; Henein, Aymon, Bottinelli and Clavel, Proc. SPIE 3834, 1999,
    "Fatigue failure of thin wire-electrodischarge machined flexible hinges", and Naves 2017, sec. 2): two
    leaves of length ``length`` crossing at ``angle`` degrees in one plane (z = 0), rigidly joined at their
    common midpoint on the hinge axis; the four half-leaves run from the centre to two ground anchors
    (y < 0) and two rotor anchors (y > 0). Thickness in the plane, width along z."""
    L, half = p["length"], p["angle"] * ca.pi / 360.0
    ux, uy = ca.sin(half), ca.cos(half)
    n = max(int(p["segments"]) // 2, 1)
    nodes = [
        ("centre", [0.0, 0.0, 0.0]),
        ("a0", [-ux * L / 2, -uy * L / 2, 0.0]),
        ("a1", [ux * L / 2, uy * L / 2, 0.0]),
        ("b0", [ux * L / 2, -uy * L / 2, 0.0]),
        ("b1", [-ux * L / 2, uy * L / 2, 0.0]),
    ]
    w = p["width"]
    elements = [
        _leaf(p, "leafA0", "a0", "centre", w, n),
        _leaf(p, "leafA1", "centre", "a1", w, n),
        _leaf(p, "leafB0", "b0", "centre", w, n),
        _leaf(p, "leafB1", "centre", "b1", w, n),
    ]
    body = _rotor(p["body_mass"], p["body_radius"], [0, uy * L / 2 + p["body_offset"], 0], ["a1", "b1"])
    return _hinge(p, "cartwheel-hinge", nodes, [body], elements, ["a0", "b0"])


def _three_fold_cross_hinge(p: dict) -> dict:
    """Three-fold cross hinge (Naves, Brouwer and Aarts, "Building blocks for spatial flexure mechanisms"
    / Naves 2017, ch. 3): a cross-spring pivot made symmetric along its axis, a middle leaf of width
    ``2 width`` at z = 0 crossing two outer leaves of width ``width`` at z = +-(1.5 width + gap); the leaves
    cross at ``angle`` degrees and at the fraction ``crossing`` of their length from the ground end. The
    symmetry about z = 0 removes the twist coupling of the two-leaf pivot."""
    L, w, lam, g = p["length"], p["width"], p["crossing"], p["gap"]
    half = p["angle"] * ca.pi / 360.0
    ux, uy = ca.sin(half), ca.cos(half)
    zc = 1.5 * w + g
    n = int(p["segments"])
    nodes = [("a0", [-ux * L * lam, -uy * L * lam, 0.0]), ("a1", [ux * L * (1 - lam), uy * L * (1 - lam), 0.0])]
    for k, z in (("b", zc), ("c", -zc)):
        nodes += [(k + "0", [ux * L * lam, -uy * L * lam, z]), (k + "1", [-ux * L * (1 - lam), uy * L * (1 - lam), z])]
    elements = [
        _leaf(p, "middle", "a0", "a1", 2 * w, n),
        _leaf(p, "outer1", "b0", "b1", w, n),
        _leaf(p, "outer2", "c0", "c1", w, n),
    ]
    body = _rotor(p["body_mass"], p["body_radius"], [0, uy * L * (1 - lam) + p["body_offset"], 0], ["a1", "b1", "c1"])
    return _hinge(p, "three-fold-cross-hinge", nodes, [body], elements, ["a0", "b0", "c0"])


def _double_cross_hinge(p: dict) -> dict:
    """Two cross-spring pivots in series about one axis, joined by a rigid intermediate body (the principle
    of the butterfly hinge, Henein et al. 2003: each stage turns half the stroke, and the mirrored second
    stage cancels the first's centre shift). Stage 1 joins ground (y < 0) to the intermediate body
    (y > 0) with leaves at z = +-c (c = width/2 + gap/2); stage 2, mirrored, joins the intermediate body
    (y < 0) to the rotor (y > 0) with leaves at z = +-3c. The intermediate body's own rotation is a real,
    often the lowest, parasitic mode with the drive locked; its mass is ``mid_mass``."""
    L, w = p["length"], p["width"]
    half = p["angle"] * ca.pi / 360.0
    ux, uy = ca.sin(half), ca.cos(half)
    c = w / 2.0 + p["gap"] / 2.0
    n = int(p["segments"])
    nodes = [
        ("a0", [-ux * L / 2, -uy * L / 2, c]),
        ("a1", [ux * L / 2, uy * L / 2, c]),
        ("b0", [ux * L / 2, -uy * L / 2, -c]),
        ("b1", [-ux * L / 2, uy * L / 2, -c]),
        ("c0", [ux * L / 2, -uy * L / 2, 3 * c]),
        ("c1", [-ux * L / 2, uy * L / 2, 3 * c]),
        ("d0", [-ux * L / 2, -uy * L / 2, -3 * c]),
        ("d1", [ux * L / 2, uy * L / 2, -3 * c]),
    ]
    elements = [
        _leaf(p, "stage1A", "a0", "a1", w, n),
        _leaf(p, "stage1B", "b0", "b1", w, n),
        _leaf(p, "stage2A", "c0", "c1", w, n),
        _leaf(p, "stage2B", "d0", "d1", w, n),
    ]
    mid = _rotor(p["mid_mass"], p["body_radius"], [0.0, 0.0, 0.0], ["a1", "b1", "c0", "d0"], name="intermediate")
    body = _rotor(p["body_mass"], p["body_radius"], [0, uy * L / 2 + p["body_offset"], 0], ["c1", "d1"])
    return _hinge(p, "double-cross-hinge", nodes, [mid, body], elements, ["a0", "b0"])


_HINGE = dict(
    _COMMON,
    length=0.05,
    width=0.02,
    thickness=0.3e-3,
    angle=90.0,
    gap=0.002,
    segments=12,
    body_mass=0.1,
    body_radius=0.02,
    body_offset=0.01,
    stroke=45.0,
)
TEMPLATES.update(
    {
        "cartwheel-hinge": (_cartwheel_hinge, dict(_HINGE, segments=40)),  # 20 per half leaf
        "three-fold-cross-hinge": (_three_fold_cross_hinge, dict(_HINGE, width=0.01, crossing=0.5)),
        "double-cross-hinge": (_double_cross_hinge, dict(_HINGE, mid_mass=0.02)),
    }
)

#: Continuous design parameters of the optimiser's families with physical bounds [m, deg, -]: every design in
#: the box is a valid scene (leaves never meet, positive dimensions); thickness bounds are raised to the
#: problem's minimum manufacturable thickness by the optimiser.
DESIGN_SPACES: dict[str, dict[str, tuple[float, float]]] = {
    "cross-spring-pivot": {
        "length": (0.03, 0.07),
        "thickness": (1e-4, 4e-4),
        "width": (0.01, 0.04),
        "angle": (60.0, 120.0),
        "crossing": (0.15, 0.85),
    },
    "cartwheel-hinge": {
        "length": (0.04, 0.14),
        "thickness": (5e-5, 4e-4),
        "width": (0.01, 0.04),
        "angle": (60.0, 120.0),
    },
    "three-fold-cross-hinge": {
        "length": (0.03, 0.07),
        "thickness": (1e-4, 4e-4),
        "width": (0.005, 0.02),
        "angle": (60.0, 120.0),
        "crossing": (0.15, 0.85),
    },
    "double-cross-hinge": {
        "length": (0.03, 0.07),
        "thickness": (1e-4, 4e-4),
        "width": (0.01, 0.04),
        "angle": (60.0, 120.0),
    },
}


def design_space(name: str) -> dict[str, tuple[float, float]]:
    """The design parameters of an optimiser family with their bounds."""
    if name not in DESIGN_SPACES:
        raise SceneError("template", f"'{name}' is not an optimiser family; choose one of {sorted(DESIGN_SPACES)}")
    return dict(DESIGN_SPACES[name])


# ----------------------------------------------------------------------------------------------------------
# Generated hinge topologies (optim/topology): one builder for every descriptor the topology grammar writes.
# The descriptor is read here (model/ must not import optim/); optim/topology/grammar.py wraps this reader
# in its Topology type, so the scene and the grammar always agree.

#: Leaf plane angles about the hinge axis: "+" the leaf direction (sin a/2, cos a/2, 0) (a = ``angle``),
#: "-" its mirror (-sin a/2, cos a/2, 0), "0" radial (0, 1, 0); leaves run from the previous body (y < 0)
#: to the next (y > 0) and cross the axis at the fraction ``crossing`` of their length.
_PLANES = "+-0"


def topology_layout(descriptor: str) -> list[dict]:
    """Read a hinge topology descriptor into its stages (the grammar of optim/topology/grammar.py).

    ``R:<stage>|<stage>...``: stages in series from ground to the rotor (intermediate bodies between them).
    A stage is ``[x]<leaf><leaf>...[@]``: leaves stacked along the axis from +z to -z, or with ``x`` crossing
    in one plane and joined at their crossing point; ``@`` makes the crossing fraction a design parameter
    (otherwise the leaves cross at their midpoints). A leaf is a plane ``+``, ``-`` or ``0`` (see
    :data:`_PLANES`), an optional width multiple ``2``-``9`` and an optional ``r`` (middle part rigid).

    Returns
    -------
    list of dict
        Per stage ``{"inplane": bool, "free_crossing": bool, "leaves": [(plane, multiple, reinforced)]}``.

    Raises
    ------
    SceneError
        On a malformed descriptor, naming the position and what is allowed there.
    """
    where = "template.topology"
    if not isinstance(descriptor, str) or not descriptor.startswith("R:"):
        raise SceneError(
            where,
            f"topology '{descriptor}' must start with 'R:' (a rotation about the z axis), "
            "e.g. 'R:+-@' (the cross-spring pivot)",
        )
    stages = []
    for k, text in enumerate(descriptor[2:].split("|"), start=1):
        inplane = text.startswith("x")
        body = text[1:] if inplane else text
        free = body.endswith("@")
        body = body[:-1] if free else body
        leaves, i = [], 0
        while i < len(body):
            c = body[i]
            if c not in _PLANES:
                raise SceneError(
                    where,
                    f"topology '{descriptor}', stage {k}: '{c}' is not a leaf plane; a leaf "
                    "is '+', '-' or '0', then an optional width multiple 2-9 and an optional 'r'",
                )
            i += 1
            mult = 1
            if i < len(body) and body[i] in "23456789":
                mult, i = int(body[i]), i + 1
            rein = i < len(body) and body[i] == "r"
            i += rein
            leaves.append((c, mult, bool(rein)))
        if not leaves:
            raise SceneError(where, f"topology '{descriptor}': stage {k} has no leaves")
        if inplane and (len(leaves) < 2 or len({lf[0] for lf in leaves}) < len(leaves)):
            raise SceneError(
                where,
                f"topology '{descriptor}', stage {k}: leaves crossing in one plane ('x') need "
                "at least two leaves in different planes",
            )
        if inplane and any(lf[2] for lf in leaves):
            raise SceneError(
                where,
                f"topology '{descriptor}', stage {k}: a reinforced leaf ('r') cannot cross in "
                "one plane ('x'): its rigid middle would hold the joint",
            )
        stages.append({"inplane": inplane, "free_crossing": free, "leaves": leaves})
    return stages


def _layer_heights(stages: list[dict], w: Any, t_gap: Any) -> dict[tuple[int, int], Any]:
    """The z of every leaf's centre, keyed (stage, leaf): layers (a stacked leaf, or one in-plane crossing)
    stacked along z with ``t_gap`` between them and centred on z = 0, stage 1's in the middle and each later
    stage's first half above, second half below the earlier ones (see :func:`_topology_hinge`). ``w``: the
    width of every stage, or a list of each stage's width (a layer's height is its multiple times it)."""
    widths = list(w) if isinstance(w, (list, tuple)) else [w] * len(stages)
    # layers (top to bottom): (stage index, leaf indices, width multiple)
    order: list[tuple[int, list[int], int]] = []
    for k, st in enumerate(stages):
        own = (
            [(k, list(range(len(st["leaves"]))), max(lf[1] for lf in st["leaves"]))]
            if st["inplane"]
            else [(k, [i], lf[1]) for i, lf in enumerate(st["leaves"])]
        )
        up = (len(own) + 1) // 2
        order = own if k == 0 else own[:up] + order + own[up:]
    total = sum(m * widths[k] for k, _, m in order) + (len(order) - 1) * t_gap
    z_of: dict[tuple[int, int], Any] = {}
    top = total / 2.0
    for k, idx, m in order:
        for i in idx:
            z_of[(k, i)] = top - m * widths[k] / 2.0
        top = top - m * widths[k] - t_gap
    return z_of


def _topology_hinge(p: dict) -> dict:
    """A generated hinge topology (``topology``: see :func:`topology_layout`), built like the families.

    Every leaf has length ``length``, thickness ``thickness`` and width ``width`` times its multiple (width
    along the axis z); it crosses the axis at the fraction ``crossing`` of its length (0.5 unless a stage
    says ``@``). Layers (a stacked leaf, or one in-plane crossing) are stacked along z with ``gap`` between
    them and centred on z = 0: stage 1's layers in the middle, each later stage's first half above and
    second half below the earlier ones (so ``R:+-|-+`` is the double cross hinge). Ground holds stage 1's
    start nodes; intermediate body k (mass ``mid_mass``, at the origin) joins stage k's ends and stage
    k+1's starts; the rotor (``body_mass``, inertia ``body_mass body_radius^2 / 2`` about each axis) holds
    the last stage's ends, its centre ``body_offset`` beyond the farthest leaf end. An in-plane crossing
    joins its leaves at a node on the axis (each half ``segments // 2`` elements). A reinforced leaf
    (``r``) is rigid over the middle fraction ``rigid_fraction`` of its length: a rigid body of the leaf's
    width, ``rigid_thickness`` thick, steel. ``flexure_level`` 1 builds each leaf as one segment between its
    ends (the reinforcement and the in-plane halves condensed into the flexure, as the kinematic screen
    sees it: seed 002, section 4.2). Traceable (casadi maths on the continuous parameters).

    Per-stage and per-leaf dimensions (optional; every default 0 means "as stage 1", so a scene without them
    is the one described above): stage k >= 2 has its own ``length_s<k>``, ``thickness_s<k>``, ``width_s<k>``
    and ``angle_s<k>`` (stage 1 uses ``length``, ``thickness``, ``width``, ``angle``); leaf i of stage k its
    own thickness ``thickness_s<k>l<i>`` (default: its stage's). A layer's height along z is its width
    multiple times its stage's width.

    Tapered leaves (optional; ``taper`` k >= 2): every stacked leaf that is not reinforced is k zones of equal
    length along it, each its own beam element (``ceil(segments / k)`` segments, a rectangular section of the
    zone's thickness, its own stress), joined at nodes ``<leaf>_z<j>``; zone j's thickness is the most specific
    of ``thickness_s<k>l<i>_z<m>``, ``thickness_s<k>_z<m>`` (stage k >= 2), ``thickness_z<m>`` that is given
    (non-zero), else the leaf's own thickness, where m = j, or with ``taper_symmetric`` (the default) m =
    min(j, k + 1 - j): zones mirrored about the leaf's middle share one thickness. Leaves crossing in one
    plane (their joint is where the crossing fraction puts it) and reinforced leaves (a rigid middle) keep
    one thickness. ``taper`` 1 (the default) is the uniform leaf above."""
    stages = topology_layout(p["topology"])
    t_gap = p["gap"]

    def inherit(name: str, base: Any) -> Any:
        v = p.get(name, 0.0)
        return base if isinstance(v, (int, float)) and v == 0 else v  # 0: inherited (a symbol is designed)

    dims = []
    for k in range(len(stages)):
        half = (inherit(f"angle_s{k + 1}", p["angle"]) if k else p["angle"]) * ca.pi / 360.0
        sx, cy = ca.sin(half), ca.cos(half)
        dims.append(
            {
                "L": inherit(f"length_s{k + 1}", p["length"]) if k else p["length"],
                "w": inherit(f"width_s{k + 1}", p["width"]) if k else p["width"],
                "t": inherit(f"thickness_s{k + 1}", p["thickness"]) if k else p["thickness"],
                "cy": cy,
                "dirs": {"+": (sx, cy), "-": (-sx, cy), "0": (0.0, 1.0)},
            }
        )
    level = int(p["flexure_level"])
    n = 1 if level else int(p["segments"])
    zones = int(p["taper"])
    if not 1 <= zones <= _MAX_ZONES:
        raise SceneError("template.taper", f"taper {zones} must be 1 (a uniform leaf) to {_MAX_ZONES} zones per leaf")
    mirrored = bool(int(p["taper_symmetric"]))

    def zone_thickness(k: int, i: int, j: int, uniform: Any) -> Any:
        """Zone j (1-based, from the leaf's start) of leaf i of stage k (0-based): see the docstring."""
        m = min(j, zones + 1 - j) if mirrored else j
        names = [f"thickness_s{k + 1}l{i + 1}_z{m}"] + ([f"thickness_s{k + 1}_z{m}"] if k else []) + [f"thickness_z{m}"]
        for name in names:
            v = p.get(name, 0.0)
            if not (isinstance(v, (int, float)) and v == 0):
                return v
        return uniform

    n_half = max(n // 2, 1)
    z_of = _layer_heights(stages, [d["w"] for d in dims], t_gap)
    nodes: list[tuple[str, list]] = []
    elements: list[dict] = []
    bodies: list[dict] = []
    starts: list[list[str]] = []
    ends: list[list[str]] = []
    rho = p["rigid_fraction"]
    for k, st in enumerate(stages):
        lam = p["crossing"] if st["free_crossing"] else 0.5
        s0, s1 = [], []
        centre = f"s{k + 1}_centre"
        if st["inplane"]:
            nodes.append((centre, [0.0, 0.0, z_of[(k, 0)]]))
        L, w, dirs = dims[k]["L"], dims[k]["w"], dims[k]["dirs"]
        for i, (plane, mult, rein) in enumerate(st["leaves"]):
            ux, uy = dirs[plane]
            z = z_of[(k, i)]
            ti = inherit(f"thickness_s{k + 1}l{i + 1}", dims[k]["t"])
            tag = f"s{k + 1}l{i + 1}"
            a = [-ux * L * lam, -uy * L * lam, z]
            b = [ux * L * (1 - lam), uy * L * (1 - lam), z]
            nodes += [(f"{tag}_0", a), (f"{tag}_1", b)]
            s0.append(f"{tag}_0")
            s1.append(f"{tag}_1")
            wi = mult * w
            if st["inplane"] and not level:
                elements += [
                    _leaf(p, f"{tag}a", f"{tag}_0", centre, wi, n_half, ti),
                    _leaf(p, f"{tag}b", centre, f"{tag}_1", wi, n_half, ti),
                ]
            elif st["inplane"]:
                elements += [
                    _leaf(p, f"{tag}a", f"{tag}_0", centre, wi, 1, ti),
                    _leaf(p, f"{tag}b", centre, f"{tag}_1", wi, 1, ti),
                ]
            elif rein and not level:
                f0, f1 = (1 - rho) / 2.0, (1 + rho) / 2.0
                ra = [a[j] + (b[j] - a[j]) * f0 for j in range(3)]
                rb = [a[j] + (b[j] - a[j]) * f1 for j in range(3)]
                nodes += [(f"{tag}_ra", ra), (f"{tag}_rb", rb)]
                elements += [
                    _leaf(p, f"{tag}a", f"{tag}_0", f"{tag}_ra", wi, n_half, ti),
                    _leaf(p, f"{tag}b", f"{tag}_rb", f"{tag}_1", wi, n_half, ti),
                ]
                mr = p["density"] * wi * p["rigid_thickness"] * rho * L
                jr = mr * (rho * L) ** 2 / 12.0
                bodies.append(
                    {
                        "name": f"{tag}_rigid",
                        "mass": mr,
                        "center_of_mass": [(ra[j] + rb[j]) / 2 for j in range(3)],
                        "inertia": [[jr, 0, 0], [0, jr, 0], [0, 0, jr]],
                        "nodes": [f"{tag}_ra", f"{tag}_rb"],
                    }
                )
            elif zones > 1 and not level:
                nz = -(-n // zones)  # ceil: the leaf keeps at least its segments
                ends_z = [f"{tag}_0"] + [f"{tag}_z{j}" for j in range(1, zones)] + [f"{tag}_1"]
                nodes += [
                    (f"{tag}_z{j}", [a[c] + (b[c] - a[c]) * j / zones for c in range(3)]) for j in range(1, zones)
                ]
                elements += [
                    _leaf(p, f"{tag}z{j}", ends_z[j - 1], ends_z[j], wi, nz, zone_thickness(k, i, j, ti))
                    for j in range(1, zones + 1)
                ]
            else:
                elements.append(_leaf(p, tag, f"{tag}_0", f"{tag}_1", wi, n, ti))
        starts.append(s0)
        ends.append(s1)
    for k in range(len(stages) - 1):
        name = "intermediate" if len(stages) == 2 else f"intermediate{k + 1}"
        bodies.append(_rotor(p["mid_mass"], p["body_radius"], [0.0, 0.0, 0.0], ends[k] + starts[k + 1], name=name))
    last = stages[-1]
    lam = p["crossing"] if last["free_crossing"] else 0.5
    reach = (1.0 if any(lf[0] == "0" for lf in last["leaves"]) else dims[-1]["cy"]) * dims[-1]["L"] * (1 - lam)
    bodies.append(_rotor(p["body_mass"], p["body_radius"], [0, reach + p["body_offset"], 0], ends[-1]))
    out = _hinge(p, "topology-hinge", nodes, bodies, elements, starts[0])
    out["name"] = f"topology {p['topology']}"
    return out


#: Stages and leaves per stage that may have their own dimensions (the grammar's largest spaces: 3 stages, 6 leaves).
_OWN_STAGES, _OWN_LEAVES = 3, 6
_PER_STAGE = {
    f"{key}_s{k}": 0.0 for k in range(2, _OWN_STAGES + 1) for key in ("length", "thickness", "width", "angle")
}
_PER_LEAF = {f"thickness_s{k}l{i}": 0.0 for k in range(1, _OWN_STAGES + 1) for i in range(1, _OWN_LEAVES + 1)}
#: Most thickness zones of a tapered leaf, and every zone's thickness parameter (0: inherited, see _topology_hinge).
_MAX_ZONES = 5
_PER_ZONE = {
    f"{base}_z{j}": 0.0
    for base in ("thickness", *(f"thickness_s{k}" for k in range(2, _OWN_STAGES + 1)), *_PER_LEAF)
    for j in range(1, _MAX_ZONES + 1)
}


def start_value(name: str, key: str) -> float:
    """Where the optimiser's first start puts template parameter ``key`` of template ``name``: its default; a
    zone thickness of ``topology-hinge`` (default 0, "inherited") starts at the template's thickness, so the
    first start of a tapered leaf is the uniform leaf of the untapered first start."""
    defaults = TEMPLATES[name][1]
    if key in _PER_ZONE and defaults[key] == 0:
        return float(defaults["thickness"])
    return float(defaults[key])


TEMPLATES["topology-hinge"] = (
    _topology_hinge,
    dict(
        _HINGE,
        topology="R:+-@",
        crossing=0.5,
        mid_mass=0.02,
        rigid_fraction=1.0 / 3.0,
        rigid_thickness=2e-3,
        flexure_level=0,
        taper=1,
        taper_symmetric=1,
        **_PER_STAGE,
        **_PER_LEAF,
        **_PER_ZONE,
    ),
)
PARAMETER_UNITS.update(
    {
        "rigid_thickness": "m",
        "rigid_fraction": "",
        **{k: ("deg" if k.startswith("angle") else "m") for k in (*_PER_STAGE, *_PER_LEAF, *_PER_ZONE)},
    }
)
