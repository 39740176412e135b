"""Cross-section properties, each formula with its source.

Local axes: x along the beam, y along the section's ``y_axis`` (a rectangle's width), z = x cross y (a
rectangle's thickness). ``Iy`` resists deflection along z, ``Iz`` along y.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .scene import GeneralSection, RectangularSection

__all__ = ["SectionProperties", "section_properties", "rect_torsion_constant", "warping_factor"]


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
        Warping constant (thin rectangle: t^3 w^3 / 144; Vlasov), 0 when unknown.
    cy, cz
        Largest fibre distances along local y and z (None when unknown: no bending stress).
    tau_per_torque
        Largest shear stress per unit torque (None when unknown).
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


def rect_torsion_constant(width: float, thickness: float) -> float:
    """St Venant torsion constant of a solid rectangle (Roark's Formulas, 7th ed., Table 10.7 case 4).

    ``J = a b^3 [1/3 - 0.21 (b/a) (1 - b^4 / (12 a^4))]`` with ``a >= b`` the long and short sides; for a
    thin leaf this is ``w t^3/3 (1 - 0.63 t/w + ...)``. Accurate to about 4 % for a square and better for
    thinner rectangles.
    """
    a, b = max(width, thickness), min(width, thickness)
    return a * b**3 * (1.0 / 3.0 - 0.21 * (b / a) * (1.0 - b**4 / (12.0 * a**4)))


def warping_factor(E: float, G: float, props: SectionProperties, length: float, ends: str) -> float:
    """Multiplier on GJ for warping constrained at clamped ends (Vlasov torsion of a prismatic bar).

    With ``alpha = sqrt(GJ / (E Iw))`` the twist of a bar under end torque T gives an effective stiffness
    ``GJ_eff = GJ * f``: both ends clamped ``f = aL / (aL - 2 tanh(aL/2))`` (SPACAR Light's correction,
    see shared/PHYSICS.md), one end clamped (the other free to warp) ``f = aL / (aL - tanh(aL))``
    (Timoshenko and Gere, Theory of Elastic Stability, sec. 5.4, bar clamped against warping at one end).
    ``length`` is the length of the whole member, not of one segment.
    """
    if ends == "free" or props.Iw <= 0:
        return 1.0
    aL = math.sqrt(G * props.J / (E * props.Iw)) * length
    if ends == "both_ends":
        return aL / (aL - 2.0 * math.tanh(aL / 2.0))
    return aL / (aL - math.tanh(aL))


def section_properties(section: RectangularSection | GeneralSection) -> SectionProperties:
    """Section properties from a scene section (formulas in the docstrings of this module)."""
    if isinstance(section, RectangularSection):
        w, t = section.width, section.thickness
        A = w * t
        Iy = w * t**3 / 12.0  # about local y: fibres at distance z across the thickness
        Iz = t * w**3 / 12.0
        J = rect_torsion_constant(w, t)
        Iw = (t**3 * w**3) / 144.0  # Vlasov warping constant of a thin rectangle
        # Max shear stress of a rectangle in torsion: T b / J with b the short side for thin sections
        # (Roark Table 10.7 case 4, thin-wall limit); conservative for stubby rectangles.
        return SectionProperties(
            A=A, Iy=Iy, Iz=Iz, J=J, ct=(Iy + Iz) / A, Iw=Iw, cy=w / 2.0, cz=t / 2.0,
            tau_per_torque=min(w, t) / J, warping=section.warping,
        )
    s = section
    return SectionProperties(
        A=s.A, Iy=s.Iy, Iz=s.Iz, J=s.J, ct=(s.Iy + s.Iz) / s.A, Iw=0.0, cy=s.cy, cz=s.cz,
        tau_per_torque=s.torsion_stress_factor,
    )
