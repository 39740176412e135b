"""Cross-section properties, each formula with its source.

Local axes: x along the beam, y along the section's ``y_axis`` (a rectangle's width), z = x cross y (a
rectangle's thickness). ``Iy`` resists deflection along z, ``Iz`` along y.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca

from .scene import GeneralSection, RectangularSection

__all__ = [
    "SectionProperties",
    "section_properties",
    "rectangular_properties",
    "rect_torsion_constant",
    "warping_factor",
    "beam_segment",
]


@dataclass(frozen=True)
class SectionProperties:
    """Properties of a section used by the beam element.

    Attributes
    ----------
    A, Iy, Iz, J
        Area, second moments and St Venant torsion constant.
    ct
        Torsion-elongation coupling constant of seed 002 eq. 2, ``(Iy + Iz)/A``: the polar radius of
        gyration squared (Wagner effect; Meijaard, Brouwer and Jonker 2010, Multibody Syst. Dyn. 23:77-97).
    Iw
        Warping constant (thin rectangle: t^3 w^3 / 144; Vlasov; a general section's ``Iw``), 0 when unknown.
    warping
        Where warping is constrained: "free", "one_end", "both_ends" (:func:`warping_factor`).
    cy, cz
        Largest fibre distances along local y and z (None when unknown: no bending stress).
    tau_per_torque
        Largest shear stress per unit torque (None when unknown).
    Sy, Sz
        Shear flexibilities ``E Iy / (k G A)``, ``E Iz / (k G A)`` [m^2] (SPACAR's ESTIFF numbers; 0: no shear
        deformation). A segment of length ``l0`` gets ``phi = 12 S / l0^2`` (:func:`beam_segment`).
    """

    A: float
    Iy: float
    Iz: float
    J: float
    ct: float
    Iw: float
    cy: float | None
    cz: float | None
    tau_per_torque: float | None
    warping: str = "free"
    Sy: float = 0.0
    Sz: float = 0.0


def rect_torsion_constant(width: float, thickness: float) -> float:
    """St Venant torsion constant of a solid rectangle (Roark's Formulas, 7th ed., Table 10.7 case 4).

    ``J = a b^3 [1/3 - 0.21 (b/a) (1 - b^4 / (12 a^4))]`` with ``a >= b`` the long and short sides; for a
    thin leaf this is ``w t^3/3 (1 - 0.63 t/w + ...)``. Accurate to about 4 % for a square and better for
    thinner rectangles.
    """
    a, b = ca.fmax(width, thickness), ca.fmin(width, thickness)
    return a * b**3 * (1.0 / 3.0 - 0.21 * (b / a) * (1.0 - b**4 / (12.0 * a**4)))


def warping_factor(E: float, G: float, props: SectionProperties, length: float, ends: str) -> float:
    """Multiplier on GJ for warping constrained at clamped ends (Vlasov torsion of a prismatic bar).

    With ``alpha = sqrt(GJ / (E Iw))`` the twist of a bar under end torque T gives an effective stiffness
    ``GJ_eff = GJ * f``: both ends clamped ``f = aL / (aL - 2 tanh(aL/2))`` (SPACAR Light's correction,
    see shared/PHYSICS.md), one end clamped (the other free to warp) ``f = aL / (aL - tanh(aL))``
    (Timoshenko and Gere, Theory of Elastic Stability, sec. 5.4, bar clamped against warping at one end).
    ``length`` is the length of the whole member, not of one segment.
    """
    if ends == "free" or (isinstance(props.Iw, float) and props.Iw <= 0):
        return 1.0
    aL = ca.sqrt(G * props.J / (E * props.Iw)) * length
    if ends == "both_ends":
        return aL / (aL - 2.0 * ca.tanh(aL / 2.0))
    return aL / (aL - ca.tanh(aL))


def rectangular_properties(w, t, warping: str = "free") -> SectionProperties:
    """Properties of a solid ``w`` x ``t`` rectangle (width along local y, thickness along z).

    Written with casadi's scalar functions, which return plain floats for floats, so the same formulas
    serve the numeric model and the design-sensitivity kernels (CasADi symbols for ``w`` and ``t``).
    """
    A = w * t
    Iy = w * t**3 / 12.0  # about local y: fibres at distance z across the thickness
    Iz = t * w**3 / 12.0
    J = rect_torsion_constant(w, t)
    Iw = (t**3 * w**3) / 144.0  # Vlasov warping constant of a thin rectangle
    # Max shear stress of a rectangle in torsion: T b / J with b the short side for thin sections
    # (Roark Table 10.7 case 4, thin-wall limit); conservative for stubby rectangles.
    return SectionProperties(
        A=A,
        Iy=Iy,
        Iz=Iz,
        J=J,
        ct=(Iy + Iz) / A,
        Iw=Iw,
        cy=w / 2.0,
        cz=t / 2.0,
        tau_per_torque=ca.fmin(w, t) / J,
        warping=warping,
    )


def section_properties(section: RectangularSection | GeneralSection) -> SectionProperties:
    """Section properties from a scene section (formulas in the docstrings of this module)."""
    if isinstance(section, RectangularSection):
        return rectangular_properties(section.width, section.thickness, section.warping)
    s = section
    return SectionProperties(
        A=s.A,
        Iy=s.Iy,
        Iz=s.Iz,
        J=s.J,
        ct=(s.Iy + s.Iz) / s.A,
        Iw=s.Iw,
        cy=s.cy,
        cz=s.cz,
        tau_per_torque=s.torsion_stress_factor,
        warping=s.warping,
        Sy=s.shear_y,
        Sz=s.shear_z,
    )


def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def beam_segment(p, q, y_axis, props: SectionProperties, E, G, density, n) -> dict:
    """Constants of one of the ``n`` equal segments of a beam member from ``p`` to ``q``.

    ``l0 = |q - p| / n``; the local frame ``E0 = [ex ey ez]`` with ``ex`` along the member, ``ey`` the
    section's ``y_axis`` made perpendicular to ``ex`` and ``ez = ex x ey``; the stiffness constants of
    :mod:`model.elements` (``k1 = EA/l0``, ``k2 = GJ_eff/l0^3`` with the warping factor of the whole member,
    ``ky = EIy/l0^3``, ``kz = EIz/l0^3``, ``ct``, and ``phi_y = 12 Sy / l0^2``, ``phi_z = 12 Sz / l0^2`` for
    shear deformation); mass ``rho A l0`` and the rotary inertia lumped at each
    end, ``rho l0/2 E0 diag(Iy + Iz, Iy, Iz) E0^T``. Only arithmetic and ``sqrt``: the numeric model
    (``compile_scene``) and the design-sensitivity kernel (CasADi symbols) share this one formula.
    Vectors are sequences of three scalars; ``E0`` and ``rot`` are returned as 3 x 3 nested lists.
    """
    d = [q[i] - p[i] for i in range(3)]
    L = ca.sqrt(_dot(d, d))
    ex = [c / L for c in d]
    yx = _dot(y_axis, ex)
    v = [y_axis[i] - yx * ex[i] for i in range(3)]
    nv = ca.sqrt(_dot(v, v))
    ey = [c / nv for c in v]
    ez = _cross(ex, ey)
    E0 = [[ex[i], ey[i], ez[i]] for i in range(3)]
    l0 = L / n
    GJ = G * props.J * warping_factor(E, G, props, L, props.warping)
    Ix = props.Iy + props.Iz
    diag = (Ix, props.Iy, props.Iz)
    rot = [
        [density * l0 / 2.0 * sum(E0[i][k] * diag[k] * E0[j][k] for k in range(3)) for j in range(3)] for i in range(3)
    ]
    return dict(
        L=L,
        l0=l0,
        E0=E0,
        k1=E * props.A / l0,
        k2=GJ / l0**3,
        ky=E * props.Iy / l0**3,
        kz=E * props.Iz / l0**3,
        ct=props.ct,
        phi_y=12.0 * props.Sy / l0**2,
        phi_z=12.0 * props.Sz / l0**2,
        mass=density * props.A * l0,
        rot=rot,
    )
