"""Checks on a scene and its results: pure functions returning :class:`~model.results.ResultWarning` lists,
and the provenance every result carries. Nothing here changes a number; it says when a number should not be
trusted as it stands.

Checks and their limits (each a module constant, so tests and the README quote the same figure):

* **stress** -- a member whose largest von Mises stress exceeds its material's allowable stress, one warning
  per contiguous stroke range (ends interpolated linearly between stroke points), ``value`` = peak
  utilisation (stress / allowable).
* **validity** (beam theory) -- the beam here is Euler-Bernoulli: no shear deformation, the section rigid in
  its plane. Shear adds ``12 E I / (kappa G A L^2) = (E / (kappa G)) (h / L)^2`` to the bending compliance
  of a clamped-guided member of depth ``h`` (Timoshenko beam theory; Timoshenko and Gere, *Mechanics of
  Materials*, and Hutchinson, J. Appl. Mech. 68 (2001) 87-92, for kappa = 5/6 of a rectangle), 3.2 % for
  steel at L/h = 10. Limit: ``L / h >= SLENDER_MIN`` (= 10, the customary slenderness limit of
  Euler-Bernoulli theory) for the compliant (thin) direction; a member wider than it is long (``L / w <
  PLATE_MAX`` = 1) is a plate: plate bending stiffness ``E t^3 / (12 (1 - nu^2))`` per width is up to
  ``1 / (1 - nu^2)`` higher and clamps restrain the anticlastic curvature (Timoshenko and Woinowsky-Krieger,
  *Theory of Plates and Shells*, 1959, sec. 1-2). ``h`` is ``sqrt(12 I / A)`` (the depth of a rectangle).
* **validity** (small strain) -- a member whose equivalent strain ``sigma_vM / E`` (its largest von Mises
  stress over its material's E: the strain of a uniaxial test at that stress) exceeds ``STRAIN_MAX`` (1 %),
  one warning per contiguous stroke range, ``value`` = peak strain. The beam's constitutive law is linear in
  its strain measures, which agree only to first order (Green-Lagrange ``eps + eps^2 / 2`` against the
  engineering ``eps``: ``eps / 2`` relative, 0.5 % at 1 % strain, the ``MESH_RTOL`` to which curves are
  meshed); and 1 % is about the yield strain of the strongest spring steels (sigma_y ~ 2 GPa at E ~ 200 GPa;
  beryllium copper and titanium alloys 0.6-1 %), so beyond it every metal has left its elastic range. The
  material's own elastic limit is not in the scene (only an allowable stress, a design limit that the
  **stress** check applies); a polymer stays elastic further, but the model's small-strain error is the
  same. A 0.1 m leaf pulled 0.2 m along its axis (300 %) used to pass silently.
* **notice** (stiff direction) -- shear in the stiff (width) direction adds more than ``SHEAR_NOTICE``
  (10 %) to that compliance: support stiffness across the width is overestimated, and parasitic modes that
  bend the member about its stiff axis read high by up to ``sqrt(1 + share) - 1``.
* **mesh** -- ``curve.mesh_error`` (the estimated relative discretisation error of ``parasitic_hz``) above
  ``MESH_RTOL`` (0.5 %).
* **units** -- an allowable stress above ``ALLOWABLE_OVER_E_MAX`` (0.1) E (an elastic strain of 10 %: spring
  steel allows about 1 %, engineering polymers a few %; elastomers, which do, are outside this linear model); a bar-wave speed ``sqrt(E / rho)`` outside ``WAVE_SPEED`` = 30 m/s (a 1 MPa elastomer) to 20 km/s
  (diamond, the stiffest solid: about 18 km/s); ``G / E`` outside ``G_OVER_E`` = 0.01 to 1 (isotropic
  solids have 1/3 to 1/2, fibre composites down to a few hundredths); a scene larger than ``EXTENT_MAX``
  (10 m: lengths in mm given as m); a rotation stroke in degrees whose magnitude is a radian value (at most
  pi, and within ``RADIAN_RTOL`` of a multiple of 5 degrees when read as radians: 0.785 = 45 degrees); a
  rotation stroke of more than a turn in radians; a translation stroke larger than the scene.
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
from dataclasses import asdict, is_dataclass, replace
from typing import Any

import numpy as np

from .results import FrequencyCurve, ResultWarning
from .scene import Beam, Material, RectangularSection, Scene, Stroke

__all__ = [
    "SLENDER_MIN",
    "PLATE_MAX",
    "SHEAR_NOTICE",
    "KAPPA",
    "MESH_RTOL",
    "ALLOWABLE_OVER_E_MAX",
    "WAVE_SPEED",
    "G_OVER_E",
    "EXTENT_MAX",
    "RADIAN_RTOL",
    "STRAIN_MAX",
    "STRICT_KINDS",
    "SI_UNITS",
    "stress_warnings",
    "strain_warnings",
    "slenderness_warnings",
    "mesh_warnings",
    "units_warnings",
    "scene_warnings",
    "curve_warnings",
    "scene_hash",
    "input_units",
    "provenance",
    "annotate_curve",
    "annotate_diagnosis",
]

SLENDER_MIN = 10.0  # L / h below this: outside Euler-Bernoulli theory (shear deformation)
PLATE_MAX = 1.0  # L / w below this: a plate, not a beam
SHEAR_NOTICE = 0.10  # share of shear compliance in the stiff direction that earns a notice
KAPPA = 5.0 / 6.0  # Timoshenko shear coefficient of a rectangle
MESH_RTOL = 0.005  # estimated relative mesh error of parasitic_hz that earns a mesh warning
ALLOWABLE_OVER_E_MAX = 0.1
WAVE_SPEED = (30.0, 2.0e4)  # m/s, plausible sqrt(E / rho) of solids
G_OVER_E = (0.01, 1.0)
EXTENT_MAX = 10.0  # m
RADIAN_RTOL = 0.005
STRAIN_MAX = 0.01  # equivalent strain sigma_vM / E beyond which the small-strain beam is out of its range
#: Warning kinds that make ``flexopt curve --strict`` exit 3: an implausible unit is as wrong an answer as an
#: overstressed member (a scene in mm without a units block gave 0.146 Hz and exit 0)
STRICT_KINDS = ("stress", "validity", "units")
SI_UNITS = "SI: lengths m, masses kg, forces N, stresses Pa, moments N m, frequencies Hz"


# ----------------------------------------------------------------------------------------------- stress
def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Index ranges [i, j] (inclusive) of consecutive True entries."""
    runs, start = [], None
    for i, m in enumerate(mask):
        if m and start is None:
            start = i
        if not m and start is not None:
            runs.append((start, i - 1))
            start = None
    if start is not None:
        runs.append((start, len(mask) - 1))
    return runs


def _crossing(s: np.ndarray, v: np.ndarray, i: int, j: int, level: float) -> float:
    """Stroke where ``v`` crosses ``level`` between points i and j (linear interpolation)."""
    if not (np.isfinite(v[i]) and np.isfinite(v[j])) or v[j] == v[i]:
        return float(s[j])
    return float(s[i] + (level - v[i]) / (v[j] - v[i]) * (s[j] - s[i]))


def stress_warnings(curve: FrequencyCurve) -> list[ResultWarning]:
    """One ``stress`` warning per member and contiguous stroke range where von Mises exceeds the allowable.

    Parameters
    ----------
    curve
        A frequency curve with ``max_von_mises`` and ``allowable_stress`` per member [Pa].

    Returns
    -------
    list of ResultWarning
        ``stress`` warnings: ``stroke_range`` with its inner ends interpolated linearly between the last
        point below and the first above the allowable, ``value`` the peak utilisation (stress / allowable)
        in the range. ``notice`` for members without stresses (NaN: a general section without fibre
        distances) and for methods that compute no stresses.
    """
    out: list[ResultWarning] = []
    if not curve.max_von_mises:
        if len(curve.stroke):
            out.append(
                ResultWarning(
                    "notice",
                    f"stresses not computed by method '{curve.method}': nothing was "
                    "checked against the allowable stress; run method 'exact' to check them",
                )
            )
        return out
    s = np.asarray(curve.stroke, dtype=float)
    unit = curve.stroke_unit
    for member, vm in curve.max_von_mises.items():
        vm = np.asarray(vm, dtype=float)
        allow = curve.allowable_stress.get(member)
        if allow is None or not len(vm):
            continue
        if np.isnan(vm).all():
            out.append(
                ResultWarning(
                    "notice",
                    f"{member}: stress not checked (its section has no fibre distances "
                    "cy, cz); give them to check the allowable stress",
                    element=member,
                )
            )
            continue
        over = np.nan_to_num(vm, nan=-np.inf) > allow
        for i, j in _runs(over):
            a = float(s[i]) if i == 0 else _crossing(s, vm, i - 1, i, allow)
            b = float(s[j]) if j == len(s) - 1 else _crossing(s, vm, j, j + 1, allow)
            peak = float(np.nanmax(vm[i : j + 1]))
            out.append(
                ResultWarning(
                    "stress",
                    f"{member}: von Mises stress reaches {peak / 1e6:.4g} MPa, {peak / allow:.3g} times its allowable "
                    f"{allow / 1e6:.4g} MPa, for stroke {a:.4g} to {b:.4g} {unit}; reduce the stroke or the "
                    "thickness, or use a material with a higher allowable stress",
                    element=member,
                    stroke_range=(a, b),
                    value=peak / allow,
                )
            )
    return out


# ------------------------------------------------------------------------------------------- slenderness
def strain_warnings(curve: FrequencyCurve, scene: Scene) -> list[ResultWarning]:
    """One ``validity`` warning per member and contiguous stroke range where its equivalent strain
    ``sigma_vM / E`` exceeds :data:`STRAIN_MAX` (reasons in the module docstring).

    Parameters
    ----------
    curve
        A frequency curve with ``max_von_mises`` per member [Pa] (methods without stresses are not checked:
        :func:`stress_warnings` says so).
    scene
        Its scene (each member's material gives E).

    Returns
    -------
    list of ResultWarning
        ``validity`` warnings with ``stroke_range`` (inner ends interpolated linearly) and ``value`` = the peak
        strain in the range.
    """
    out: list[ResultWarning] = []
    if not curve.max_von_mises:
        return out
    E = {m.name: m.E for m in scene.materials}
    modulus = {e.name: E.get(e.material) for e in scene.elements}
    s = np.asarray(curve.stroke, dtype=float)
    unit = curve.stroke_unit
    for member, vm in curve.max_von_mises.items():
        Em = modulus.get(member)
        vm = np.asarray(vm, dtype=float)
        if Em is None or not len(vm) or len(vm) != len(s):
            continue
        eps = vm / Em
        over = np.nan_to_num(eps, nan=-np.inf) > STRAIN_MAX
        for i, j in _runs(over):
            a = float(s[i]) if i == 0 else _crossing(s, eps, i - 1, i, STRAIN_MAX)
            b = float(s[j]) if j == len(s) - 1 else _crossing(s, eps, j, j + 1, STRAIN_MAX)
            peak = float(np.nanmax(eps[i : j + 1]))
            out.append(
                ResultWarning(
                    "validity",
                    f"{member}: strain reaches {100 * peak:.3g} % (von Mises stress / E) for stroke {a:.4g} to {b:.4g} "
                    f"{unit}, beyond the {100 * STRAIN_MAX:g} % to which this small-strain beam holds (and beyond the "
                    "elastic range of metals): the frequencies there are outside the model; reduce the stroke or "
                    "lengthen the member",
                    element=member,
                    stroke_range=(a, b),
                    value=peak,
                )
            )
    return out


def _member_length(scene: Scene, nodes: tuple[str, str]) -> float:
    pos = {n.name: np.asarray(n.position, dtype=float) for n in scene.nodes}
    return float(np.linalg.norm(pos[nodes[1]] - pos[nodes[0]]))


def _straight_chains(scene: Scene) -> dict[str, tuple[float, list[str]]]:
    """Per beam, the length of the straight member it is a piece of, and the pieces: beams joined end to end
    at a node that holds exactly those two beams and nothing else (no other element, body or support) and
    that do not turn there (collinear to 1e-9) are one member, e.g. the thickness zones of a tapered leaf
    (template ``topology-hinge``'s ``taper``): its span, not a zone's, is what beam theory's limits are about."""
    pos = {n.name: np.asarray(n.position, dtype=float) for n in scene.nodes}
    beams = [e for e in scene.elements if isinstance(e, Beam)]
    held: dict[str, int] = {}
    for e in scene.elements:
        for n in e.nodes:
            held[n] = held.get(n, 0) + 1
    for body in scene.bodies or ():
        for n in body.nodes:
            held[n] = held.get(n, 0) + 1
    for sp in scene.supports or ():
        if sp.node is not None:
            held[sp.node] = held.get(sp.node, 0) + 1
    for j in scene.joints or ():
        for n in j.nodes:
            held[n] = held.get(n, 0) + 1
    for ld in scene.loads or ():
        if ld.node is not None:
            held[ld.node] = held.get(ld.node, 0) + 1
    at: dict[str, list[Beam]] = {}
    for e in beams:
        for n in e.nodes:
            at.setdefault(n, []).append(e)
    parent = {e.name: e.name for e in beams}

    def root(k: str) -> str:
        while parent[k] != k:
            k = parent[k]
        return k

    for n, es in at.items():
        if len(es) != 2 or held.get(n, 0) != 2:
            continue
        (a, b) = es
        u = pos[a.nodes[1]] - pos[a.nodes[0]]
        v = pos[b.nodes[1]] - pos[b.nodes[0]]
        nu, nv = float(np.linalg.norm(u)), float(np.linalg.norm(v))
        if nu > 0 and nv > 0 and abs(abs(float(u @ v)) / (nu * nv) - 1.0) <= 1e-9:
            parent[root(a.name)] = root(b.name)
    groups: dict[str, list[Beam]] = {}
    for e in beams:
        groups.setdefault(root(e.name), []).append(e)
    out: dict[str, tuple[float, list[str]]] = {}
    for es in groups.values():
        length = sum(_member_length(scene, e.nodes) for e in es)
        for e in es:
            out[e.name] = (length, [x.name for x in es])
    return out


def _section_depths(sec: Any) -> tuple[float, float, float, float]:
    """(h_thin, h_wide, A, I_thin): depths sqrt(12 I / A) in the compliant and the stiff direction."""
    if isinstance(sec, RectangularSection):
        w, t = sec.width, sec.thickness
        A, Iy, Iz = w * t, w * t**3 / 12.0, t * w**3 / 12.0
    else:
        A, Iy, Iz = sec.A, sec.Iy, sec.Iz
    lo, hi = min(Iy, Iz), max(Iy, Iz)
    return math.sqrt(12 * lo / A), math.sqrt(12 * hi / A), A, lo


def slenderness_warnings(scene: Scene) -> list[ResultWarning]:
    """Beam members outside Euler-Bernoulli theory (``validity``) or with large stiff-direction shear (``notice``).

    Parameters
    ----------
    scene
        A validated scene (SI).

    Returns
    -------
    list of ResultWarning
        Per beam member: ``validity`` when ``L / h < SLENDER_MIN`` (``h = sqrt(12 I_min / A)``; the shear
        share ``(E / (kappa G)) (h / L)^2`` of a clamped-guided member, Timoshenko beam theory, in the
        message) or ``L / w < PLATE_MAX`` (a plate; Timoshenko and Woinowsky-Krieger 1959), else a ``notice``
        when the share across the width exceeds ``SHEAR_NOTICE``; neither shear warning for a general section
        that carries shear flexibilities (its bending is Timoshenko's). ``value``: the ratio or the share.
        ``L`` is the length of the straight member the beam is a piece of (:func:`_straight_chains`: a tapered
        leaf's zones are one member), the beam's own for a beam that is a member by itself.
    """
    out: list[ResultWarning] = []
    mats = {m.name: m for m in scene.materials}
    chains = _straight_chains(scene)
    for e in scene.elements:
        if not isinstance(e, Beam) or e.material not in mats:
            continue
        L, pieces = chains[e.name]
        name = e.name if len(pieces) == 1 else f"{e.name} (one of the {len(pieces)} pieces of a straight member)"
        mat = mats[e.material]
        h, w, _, _ = _section_depths(e.section)
        ratio = mat.E / (KAPPA * mat.G)
        # a general section with SPACAR's shear flexibilities has Timoshenko bending (model.elements): the
        # shear warnings below do not apply to it
        sheared = not isinstance(e.section, RectangularSection) and (e.section.shear_y > 0 or e.section.shear_z > 0)
        if L / h < SLENDER_MIN and not sheared:
            share = ratio * (h / L) ** 2
            out.append(
                ResultWarning(
                    "validity",
                    f"{name}: L/t = {L / h:.3g} (t = {1e3 * h:.3g} mm, its thinner section depth) is below "
                    f"{SLENDER_MIN:g}, outside the beam theory used here (Euler-Bernoulli): shear would add "
                    f"{100 * share:.3g} % to its bending compliance (Timoshenko); "
                    "make the member longer or thinner, or check it with a solid or shell model",
                    element=e.name,
                    value=L / h,
                )
            )
        if L / w < PLATE_MAX:
            nu = mat.E / (2 * mat.G) - 1.0
            factor = 1.0 / (1.0 - nu**2) if -1.0 < nu < 1.0 else float("nan")
            out.append(
                ResultWarning(
                    "validity",
                    f"{name}: L/w = {L / w:.3g} (w = {1e3 * w:.3g} mm, its wider section depth) is below "
                    f"{PLATE_MAX:g}: wider than long, a plate rather than a beam "
                    f"(bending stiffness up to {factor:.3g} times the beam's, clamps restrain anticlastic "
                    "curvature); make it narrower or check it with a plate or shell model",
                    element=e.name,
                    value=L / w,
                )
            )
        elif ratio * (w / L) ** 2 > SHEAR_NOTICE and not sheared:
            share = ratio * (w / L) ** 2
            out.append(
                ResultWarning(
                    "notice",
                    f"{name}: L/w = {L / w:.3g} (w = {1e3 * w:.3g} mm): shear, which this beam neglects, would add "
                    f"{100 * share:.3g} % to "
                    f"its compliance across the width (Timoshenko, clamped-guided): support stiffness across the "
                    f"width is overestimated and modes bending it about its stiff axis read up to "
                    f"{100 * (math.sqrt(1 + share) - 1):.3g} % high",
                    element=e.name,
                    value=share,
                )
            )
    return out


# ------------------------------------------------------------------------------------------------- mesh
def mesh_warnings(curve: FrequencyCurve, rtol: float = MESH_RTOL) -> list[ResultWarning]:
    """A ``mesh`` warning when the curve's estimated discretisation error exceeds ``rtol`` (relative)."""
    err = curve.mesh_error
    if err is None or not np.isfinite(err) or abs(err) <= rtol:
        return []
    return [
        ResultWarning(
            "mesh",
            f"the first parasitic frequency is estimated to be {100 * abs(err):.2g} % from its converged-mesh "
            f"value (limit {100 * rtol:g} %); raise the members' segments",
            value=float(abs(err)),
        )
    ]


# ------------------------------------------------------------------------------------------------ units
def _radian_like(x: float) -> bool:
    deg = math.degrees(abs(x))
    k = round(deg / 5.0)
    return 0 < abs(x) <= math.pi * (1 + RADIAN_RTOL) and k >= 1 and abs(deg - 5.0 * k) <= RADIAN_RTOL * 5.0 * k


def units_warnings(scene: Scene) -> list[ResultWarning]:
    """Input whose units look wrong.

    Parameters
    ----------
    scene
        A validated scene (SI).

    Returns
    -------
    list of ResultWarning
        ``units`` warnings for each implausible material (allowable / E, sqrt(E / density), G / E), a scene
        larger than ``EXTENT_MAX`` and a stroke that reads as radians given in degrees (or the reverse) or a
        translation larger than the scene; limits and reasons in the module docstring.
    """
    out: list[ResultWarning] = []
    for m in scene.materials:
        out += _material_units(scene, m)
    pos = np.array([n.position for n in scene.nodes], dtype=float)
    extent = float(np.ptp(pos, axis=0).max())
    out += _extent_units(extent)
    if scene.stroke is not None:
        out += _stroke_units(scene.stroke, extent)
    return out


def _material_units(scene: Scene, m: Material) -> list[ResultWarning]:
    """``units`` warnings of material ``m`` of ``scene``: allowable / E, sqrt(E / density) and G / E."""
    out: list[ResultWarning] = []
    if m.allowable_stress > ALLOWABLE_OVER_E_MAX * m.E:
        out.append(
            ResultWarning(
                "units",
                f"material '{m.name}': allowable stress {m.allowable_stress:.4g} Pa is "
                f"{m.allowable_stress / m.E:.3g} times E = {m.E:.4g} Pa; E and the allowable stress look as if "
                "given in different units (E in MPa?); give both in Pa or add a units block",
                value=m.allowable_stress / m.E,
            )
        )
    c = math.sqrt(m.E / m.density)
    if not WAVE_SPEED[0] <= c <= WAVE_SPEED[1]:
        read = input_units(scene)
        how = (
            "E [Pa] and density [kg/m^3] look as if given in other units; fix them or add a units block"
            if read is None
            else f"the scene's E was read in {read['stress']} and its density in "
            f"{read['density']}; give them in those units or name theirs in the units block"
        )
        out.append(
            ResultWarning(
                "units",
                f"material '{m.name}': sqrt(E / density) = {c:.4g} m/s is outside the {WAVE_SPEED[0]:g} "
                f"to {WAVE_SPEED[1]:g} m/s of solids; {how}",
                value=c,
            )
        )
    if not G_OVER_E[0] <= m.G / m.E <= G_OVER_E[1]:
        out.append(
            ResultWarning(
                "units",
                f"material '{m.name}': G / E = {m.G / m.E:.3g} (isotropic solids: 1/3 to 1/2); E and G "
                "look as if given in different units",
                value=m.G / m.E,
            )
        )
    return out


def _extent_units(extent: float) -> list[ResultWarning]:
    """A ``units`` warning when the scene's extent [m] is larger than ``EXTENT_MAX`` (lengths in mm?)."""
    out: list[ResultWarning] = []
    if extent > EXTENT_MAX:
        out.append(
            ResultWarning(
                "units",
                f"the scene spans {extent:.4g} m; lengths look as if given in mm; give them in m or add "
                '"units": {"length": "mm"}',
                value=extent,
            )
        )
    return out


def _stroke_units(st: Stroke, extent: float) -> list[ResultWarning]:
    """A ``units`` warning when stroke ``st`` reads as radians given in degrees (or the reverse) or a translation
    is larger than the scene's extent [m]."""
    out: list[ResultWarning] = []
    ends = [x for x in (st.start, st.stop) if x is not None]
    if st.kind == "rotation" and st.resolved_unit == "deg":
        odd = [x for x in ends if _radian_like(x)]
        if odd:
            x = max(odd, key=abs)
            out.append(
                ResultWarning(
                    "units",
                    f"stroke {x:g} deg is {math.degrees(x):.4g} deg if meant in radians; if so, set "
                    "stroke.unit to 'rad' (or give the stroke in degrees)",
                    value=x,
                )
            )
    elif st.kind == "rotation" and any(abs(x) > 2 * math.pi for x in ends):
        x = max(ends, key=abs)
        out.append(
            ResultWarning(
                "units",
                f"stroke {x:g} rad is more than a turn; if meant in degrees, set stroke.unit to 'deg'",
                value=x,
            )
        )
    elif st.kind == "translation" and ends and max(abs(x) for x in ends) > extent:
        x = max(ends, key=abs)
        out.append(
            ResultWarning(
                "units",
                f"stroke {x:g} m is larger than the scene ({extent:.4g} m); give it in the scene's length "
                "unit (m, or the units block's)",
                value=x,
            )
        )
    return out


def scene_warnings(scene: Scene) -> list[ResultWarning]:
    """The checks that need only the scene: beam-theory validity and units."""
    return slenderness_warnings(scene) + units_warnings(scene)


def curve_warnings(curve: FrequencyCurve, scene: Scene) -> list[ResultWarning]:
    """Every check on a frequency curve: stress, mesh, validity and units."""
    return stress_warnings(curve) + strain_warnings(curve, scene) + mesh_warnings(curve) + scene_warnings(scene)


# ------------------------------------------------------------------------------------------- provenance
_HASHES: dict[int, tuple[Scene, str]] = {}  # id -> (scene, hash) of the last few scenes hashed


def scene_hash(scene: Scene) -> str:
    """sha256 (hex) of the scene's canonical JSON: ``json.dumps(scene.model_dump(mode="json"), sort_keys=True,
    separators=(",", ":"))`` (SI values; a ``units`` block is converted and left out, so a scene and its SI
    equivalent hash alike when the conversion is exact).

    Scenes are frozen, so the hash of the same object is remembered (the last 16 scenes, each kept alive by
    the entry, so an id is never reused while cached): every curve of an analysis used to serialise and hash
    its scene again (0.15 ms, a fiftieth of a hermite curve)."""
    hit = _HASHES.get(id(scene))
    if hit is not None and hit[0] is scene:
        return hit[1]
    text = json.dumps(scene.model_dump(mode="json"), sort_keys=True, separators=(",", ":"), allow_nan=False)
    digest = hashlib.sha256(text.encode()).hexdigest()
    if len(_HASHES) >= 16:
        _HASHES.pop(next(iter(_HASHES)))
    _HASHES[id(scene)] = (scene, digest)
    return digest


@functools.lru_cache(maxsize=1)
def _version() -> str:
    from .. import __version__  # looked up once per process (importlib.metadata reads the installed files)

    return str(__version__)


def input_units(scene: Scene) -> dict[str, str] | None:
    """The unit each kind of number of the scene file was read in, when it has a ``units`` block: the given
    ones, and the defaults the block implies named with their rule (``{"length": "mm", "mass": "g"}`` reads
    densities in g/mm^3, which a reader expecting kg/m^3 must see). None without a block (SI)."""
    u = scene.units
    if u is None:
        return None
    length, mass, force = u.length or "m", u.mass or "kg", u.force or "N"
    out = {"length": length, "mass": mass, "force": force if u.force else "N (default)"}
    out["stress"] = u.stress or f"{force}/{length}^2 (default: force / length^2)"
    out["density"] = u.density or f"{mass}/{length}^3 (default: mass / length^3)"
    return out


def provenance(scene: Scene, method: str, settings: dict[str, Any]) -> dict[str, Any]:
    """What produced a result: flexopt version, scene hash (:func:`scene_hash`), method, solver settings,
    and the units the scene file was written in (:func:`input_units`) when it had a units block."""
    out = {
        "flexopt_version": _version(),
        "scene_sha256": scene_hash(scene),
        "method": method,
        "settings": settings,
        "units": SI_UNITS,
    }
    read = input_units(scene)
    if read is not None:
        out["input_units"] = read
    return out


def _merge(old: tuple[ResultWarning, ...], new: list[ResultWarning]) -> tuple[ResultWarning, ...]:
    """``old`` then every ``new`` not already there (so annotating twice changes nothing)."""
    return tuple(old) + tuple(w for i, w in enumerate(new) if w not in old and w not in new[:i])


def annotate_curve(curve: FrequencyCurve, scene: Scene, options: Any = None) -> FrequencyCurve:
    """``curve`` with its checks' warnings, its provenance and the SI convention attached.

    Parameters
    ----------
    curve
        A frequency curve of ``scene`` by any method.
    scene
        The scene it was computed from.
    options
        The Newton settings (a dataclass, ``model.statics.NewtonOptions``) used; None keeps those already
        recorded.

    Returns
    -------
    FrequencyCurve
        A copy with ``warnings`` = the curve's own followed by :func:`curve_warnings` (no duplicates, so
        annotating twice changes nothing: call it again after filling ``mesh_error``), ``provenance`` =
        :func:`provenance` with the stroke grid, modes, segments and the method's settings, and
        ``conventions["units"]``.
    """
    st = scene.stroke
    settings: dict[str, Any] = {
        "newton": asdict(options)
        if is_dataclass(options) and not isinstance(options, type)
        else curve.provenance.get("settings", {}).get("newton", {}),
        "stroke_points": len(curve.stroke),
        "stroke_range": [float(np.min(curve.stroke)), float(np.max(curve.stroke))] if len(curve.stroke) else [],
        "stroke_unit": curve.stroke_unit,
        "drive": st.drive if st is not None else None,
        "modes": scene.modes,
        "segments": {e.name: e.segments for e in scene.elements},
        **{k: v for k, v in curve.solver.items() if k in ("tol", "auto_tolerance")},
    }
    prov = {
        **provenance(scene, curve.method, settings),
        **{k: v for k, v in curve.provenance.items() if k not in ("method", "settings")},
    }
    conv = {**curve.conventions, "units": f"{SI_UNITS}; stroke in {curve.stroke_unit}"}
    return replace(
        curve, warnings=_merge(curve.warnings, curve_warnings(curve, scene)), provenance=prov, conventions=conv
    )


def annotate_diagnosis(diag: Any, scene: Scene, settings: dict[str, Any]) -> Any:
    """An exact-constraint diagnosis with the scene's checks and its provenance attached (idempotent)."""
    method = "exact-constraint " + ("(kinematic idealisation)" if diag.kinematic else "(declared rigid deformations)")
    return replace(
        diag,
        warnings=_merge(tuple(diag.warnings), scene_warnings(scene)),
        provenance=provenance(scene, method, settings),
    )
