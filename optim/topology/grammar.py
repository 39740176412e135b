"""Hinge topologies from building blocks: the descriptor grammar, canonical forms and the enumeration.

Building blocks (a rotation about the z axis; the same machinery names a straight guide's flexures, see
:mod:`.screen`): ground, a moving body (the rotor) and intermediate bodies; leaf flexures between two
bodies, each placed by discrete choices (the plane it lies in about the axis, stacked along the axis or
crossing the other leaves of its stage in one plane, crossing at its midpoint or at a designed fraction of
its length, a rigid middle part) and sized by continuous parameters (length, thickness, width, the
angle between the ``+`` and ``-`` planes, the crossing fraction, the rigid fraction); stages in series
through intermediate bodies.

Descriptor
----------
``R:<stage>|<stage>|...`` from ground to the rotor. A stage is ``[x]<leaf>...[@]``: its leaves stacked
along the axis from +z to -z, or with ``x`` crossing in one plane and joined where they cross; ``@`` makes
the crossing fraction a design parameter (else 0.5). A leaf is its plane, ``+`` (direction
``(sin a/2, cos a/2, 0)``, ``a`` the design angle), ``-`` (``(-sin a/2, cos a/2, 0)``) or ``0``
(radial, ``(0, 1, 0)``), an optional width multiple ``2``-``9`` and an optional ``r`` (rigid middle).
Examples, the four hand-made families (:data:`FAMILIES`):

=========================  ==========================  ==================================================
``R:+-@``                  cross-spring-pivot          two stacked leaves, crossing fraction designed
``R:x+-``                  cartwheel-hinge             two leaves crossing in one plane, joined at the middle
``R:-+2-@``                three-fold-cross-hinge      a double-width leaf between two mirrored ones
``R:+-|-+``                double-cross-hinge          two pivots in series, the second mirrored and outside
=========================  ==========================  ==================================================

Dimensions (:func:`design_parameters`): one length, thickness, width and plane angle for every stage
(``"shared"``, today's spaces), each stage its own (``"stage"``: stage k >= 2's ``length_s<k>`` and so on),
or each stage its own and each leaf its own thickness (``"leaf"``: ``thickness_s<k>l<i>``). They are the
design space's choice, not the descriptor's: a descriptor names the same hinge under each, and keeps the
meaning it had. So is a tapered leaf (``taper`` k: k thickness zones along every stacked, unreinforced
leaf, ``thickness_z<j>`` and so on in place of each thickness; :func:`design_parameters`).

The scene of a descriptor is built by one builder, ``model.templates``' ``topology-hinge`` (which reads the
descriptor with :func:`model.templates.topology_layout`, so the grammar and the scene cannot disagree).

A straight guide (``T:<wire>,<wire>,...``, template ``wire-guide-topology``, read by
:func:`model.templates.guide_layout`) is a block guided along x by wire flexures, each placed by its
direction and a discrete place: ``z<i><j>`` vertical under the block at ``(0.8 a i, 0.75 b j, -c)``,
``y<i><k>`` lateral on the face y = -b at ``(0.8 a i, -b, 0.5 c k)`` (``i, j, k`` in ``-``, ``0``, ``+``);
seed 002's Figure 3a guide is ``T:z--,z-+,z+0,y-0,y+0``. Its symmetries: the mirror x -> -x (every ``i``
negated) and the order of the wires.

Symmetry
--------
Two descriptors name the same hinge (up to a mirror image, which has the same frequencies and stresses)
when one maps onto the other by the mirror x -> -x (``+`` <-> ``-``), by the mirror z -> -z (every stacking
order reversed; only when each later stage has an even number of layers, since an odd stage's middle layer
goes above the earlier ones), or by reordering the leaves of an in-plane crossing. :func:`canonical` is the
smallest descriptor string over these maps; the enumeration keeps one descriptor per class.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from ...model.templates import guide_layout, topology_layout

__all__ = [
    "Leaf",
    "Stage",
    "Topology",
    "parse",
    "canonical",
    "family_form",
    "family_of",
    "enumerate_topologies",
    "candidate_topologies",
    "FAMILIES",
    "design_parameters",
    "DIMENSIONS",
    "tapers",
    "zone_names",
    "crosses",
    "GuideTopology",
    "parse_guide",
    "canonical_guide",
    "enumerate_guides",
    "GUIDE_PLACES",
]


@dataclass(frozen=True, order=True)
class Leaf:
    """One leaf flexure: its plane (``+``, ``-``, ``0``), width multiple and rigid middle."""

    plane: str
    width: int = 1
    reinforced: bool = False

    def __str__(self) -> str:
        return self.plane + (str(self.width) if self.width != 1 else "") + ("r" if self.reinforced else "")


@dataclass(frozen=True)
class Stage:
    """Leaves between two bodies: stacked (top to bottom) or crossing in one plane (``inplane``)."""

    leaves: tuple[Leaf, ...]
    inplane: bool = False
    free_crossing: bool = False

    def __str__(self) -> str:
        return ("x" if self.inplane else "") + "".join(map(str, self.leaves)) + ("@" if self.free_crossing else "")

    @property
    def layers(self) -> int:
        """Layers along the axis: one per stacked leaf, one for an in-plane crossing."""
        return 1 if self.inplane else len(self.leaves)


@dataclass(frozen=True)
class Topology:
    """A hinge topology: stages in series from ground to the rotor (``str`` gives its descriptor)."""

    stages: tuple[Stage, ...]

    def __str__(self) -> str:
        return "R:" + "|".join(map(str, self.stages))

    @property
    def flexures(self) -> int:
        """Number of leaf flexures."""
        return sum(len(s.leaves) for s in self.stages)

    @property
    def intermediate_masters(self) -> list[str]:
        """Scene names of the parts between ground and rotor whose rotation about the axis a series
        arrangement intends: intermediate bodies and the joints of in-plane crossings."""
        out = [f"s{k + 1}_centre" for k, s in enumerate(self.stages) if s.inplane]
        n = len(self.stages)
        out += ["intermediate"] if n == 2 else [f"intermediate{k + 1}" for k in range(n - 1)]
        return out

    def to_dict(self) -> dict:
        """A JSON form: the descriptor, counts and stages."""
        return {
            "descriptor": str(self),
            "flexures": self.flexures,
            "stages": len(self.stages),
            "layout": [
                {"leaves": [str(lf) for lf in s.leaves], "inplane": s.inplane, "free_crossing": s.free_crossing}
                for s in self.stages
            ],
        }


def parse(descriptor: str) -> Topology:
    """The topology of a descriptor (``parse(str(t)) == t``).

    Raises
    ------
    SceneError
        A malformed descriptor, with the position and what is allowed there.
    """
    return Topology(
        tuple(
            Stage(tuple(Leaf(p, m, r) for p, m, r in st["leaves"]), st["inplane"], st["free_crossing"])
            for st in topology_layout(descriptor)
        )
    )


def _mirror_x(t: Topology) -> Topology:
    swap = {"+": "-", "-": "+", "0": "0"}
    return Topology(
        tuple(
            Stage(tuple(Leaf(swap[lf.plane], lf.width, lf.reinforced) for lf in s.leaves), s.inplane, s.free_crossing)
            for s in t.stages
        )
    )


def _mirror_z(t: Topology) -> Topology | None:
    if any(s.layers % 2 for s in t.stages[1:]):
        return None  # not representable: an odd later stage's middle layer would move below the earlier ones
    return Topology(tuple(s if s.inplane else Stage(s.leaves[::-1], s.inplane, s.free_crossing) for s in t.stages))


def _sorted_inplane(t: Topology) -> Topology:
    return Topology(tuple(Stage(tuple(sorted(s.leaves)), True, s.free_crossing) if s.inplane else s for s in t.stages))


def canonical(t: Topology | str) -> Topology:
    """The representative of ``t``'s symmetry class (see the module docstring): the smallest descriptor."""
    t = parse(t) if isinstance(t, str) else t
    images = [t, _mirror_x(t)]
    images += [m for m in (_mirror_z(im) for im in list(images)) if m is not None]
    return min((_sorted_inplane(im) for im in images), key=str)


#: The hand-made families as descriptors (their scenes agree with the family templates to round-off:
#: tests/test_topology.py).
FAMILIES: dict[str, str] = {
    "cross-spring-pivot": "R:+-@",
    "cartwheel-hinge": "R:x+-",
    "three-fold-cross-hinge": "R:-+2-@",
    "double-cross-hinge": "R:+-|-+",
}
_FAMILY_OF = {str(canonical(d)): name for name, d in FAMILIES.items()}


def family_of(t: Topology | str) -> str | None:
    """The hand-made family a topology is (up to symmetry), or None."""
    return _FAMILY_OF.get(str(canonical(t)))


def family_form(descriptor: str) -> str | None:
    """The hand-made family a candidate is, in words, for the web page's and the command line's tables.

    The family's name when it is that family up to symmetry (:func:`family_of`); "<name> (crossing at the
    midpoint)" when it is the family's descriptor without its designed crossing '@' (the family at crossing
    fraction 0.5, e.g. ``R:+-`` of the cross-spring pivot ``R:+-@``); else None. Both forms are compared as the
    grammar's canonical descriptors, so a mirror image (``R:-+``) is recognised too."""
    name = family_of(descriptor)
    if name is not None:
        return name
    mine = str(canonical(descriptor))
    for name, d in FAMILIES.items():
        if "@" in d and str(canonical(d.replace("@", ""))) == mine:
            return f"{name} (crossing at the midpoint)"
    return None


#: How a topology's dimensions are designed: one set for every stage (today's), one per stage, or one per
#: stage with every leaf its own thickness.
DIMENSIONS = ("shared", "stage", "leaf")


def _stage_names(k: int, stage: Stage, dimensions: str) -> list[str]:
    """The dimensions of stage ``k`` (0-based) that are its own: stage 1 names the template's base parameters
    (``length``, ``thickness``, ``width``, ``angle``), stage k >= 2 ``length_s<k>`` and so on, and with
    ``dimensions="leaf"`` each leaf's thickness is ``thickness_s<k>l<i>`` in place of its stage's."""
    tag = "" if k == 0 else f"_s{k + 1}"
    names = ["length" + tag]
    if dimensions == "leaf":
        names += [f"thickness_s{k + 1}l{i + 1}" for i in range(len(stage.leaves))]
    else:
        names.append("thickness" + tag)
    names.append("width" + tag)
    if any(lf.plane in "+-" for lf in stage.leaves):
        names.append("angle" + tag)
    return names


def tapers(stage: Stage, leaf: Leaf) -> bool:
    """Whether a leaf can be tapered (thickness zones along it, template ``topology-hinge``'s ``taper``): a
    stacked leaf without a rigid middle. A leaf crossing in one plane is joined where the (designed) crossing
    fraction puts it, and a reinforced leaf has its rigid middle: both keep one thickness."""
    return not stage.inplane and not leaf.reinforced


def zone_names(name: str, taper: int, symmetric: bool = True) -> list[str]:
    """The zone thicknesses that replace thickness parameter ``name`` in a tapered design space:
    ``<name>_z1`` ... ``<name>_z<m>``, m = ``taper`` or, ``symmetric``, ceil(taper / 2) (zones mirrored about
    the leaf's middle share one)."""
    m = (taper + 1) // 2 if symmetric else taper
    return [f"{name}_z{j}" for j in range(1, m + 1)] if taper > 1 else [name]


def _with_zones(t: Topology, dimensions: str, names: list[str], taper: int, symmetric: bool) -> list[str]:
    """``names`` with every thickness parameter replaced by its zone thicknesses where the leaves it sizes are
    tapered, kept as well where some of them are not (:func:`tapers`)."""
    use: dict[str, list[bool]] = {}
    for k, st in enumerate(t.stages):
        for i, lf in enumerate(st.leaves):
            if dimensions == "leaf":
                name = f"thickness_s{k + 1}l{i + 1}"
            else:
                name = "thickness" if k == 0 or dimensions == "shared" else f"thickness_s{k + 1}"
            use.setdefault(name, []).append(tapers(st, lf))
    out: list[str] = []
    for n in names:
        if n in use and any(use[n]):
            out += ([n] if not all(use[n]) else []) + zone_names(n, taper, symmetric)
        else:
            out.append(n)
    return out


def design_parameters(t: Topology, dimensions: str = "shared", taper: int = 1, symmetric: bool = True) -> list[str]:
    """The continuous parameters a topology's shape depends on (its design space's names, template
    ``topology-hinge``'s parameters).

    ``dimensions``: ``"shared"`` (every stage the same length, thickness, width and plane angle: today's
    spaces), ``"stage"`` (stage k >= 2 its own ``length_s<k>``, ``thickness_s<k>``, ``width_s<k>``,
    ``angle_s<k>``) or ``"leaf"`` (as ``"stage"``, and every leaf its own thickness ``thickness_s<k>l<i>``).
    A one-stage topology has the same space under ``"shared"`` and ``"stage"``.

    ``taper`` k >= 2: every leaf that can be tapered (:func:`tapers`) is k zones of equal length, and each
    thickness parameter of such leaves is replaced by its zone thicknesses (:func:`zone_names`: ``thickness``
    by ``thickness_z1`` ... ; with ``symmetric``, ceil(k/2) of them, zones mirrored about the leaf's middle
    sharing one). ``taper`` 1 (the default) is the space above, unchanged.
    """
    if dimensions not in DIMENSIONS:
        raise ValueError(f"dimensions must be one of {DIMENSIONS}, got {dimensions!r}")
    if dimensions == "shared":
        names = ["length", "thickness", "width"]
        if any(lf.plane in "+-" for s in t.stages for lf in s.leaves):
            names.append("angle")
    else:
        names = [n for k, s in enumerate(t.stages) for n in _stage_names(k, s, dimensions)]
    if taper > 1:
        names = _with_zones(t, dimensions, names, taper, symmetric)
    if any(s.free_crossing for s in t.stages):
        names.append("crossing")
    if any(lf.reinforced for s in t.stages for lf in s.leaves):
        names.append("rigid_fraction")
    return names


def crosses(stage: Stage) -> bool:
    """Whether a stage's leaves cross one another (they lie in at least two planes). A stage whose leaves all
    lie in one plane crosses nothing: a designed crossing fraction ('@') only slides its leaves along their
    own line, away from the axis, and is pruned from the enumeration (``prune``)."""
    return len({lf.plane for lf in stage.leaves}) >= 2


def _stage_patterns(
    k: int, planes: str, inplane: bool, free_crossing: bool, reinforce: bool, prune: bool = False
) -> list[Stage]:
    """Every stage of ``k`` leaves: stacked sequences of planes (and, for an odd mirror-symmetric stack whose
    middle leaf differs from its neighbours, the variant with a double-width middle leaf: the three-fold
    principle of equal width per plane), in-plane crossings of ``k`` different planes; each with the
    crossing at the midpoint and, with ``free_crossing``, designed; with ``reinforce``, also every stacked
    stage with all its leaves reinforced."""
    out: list[Stage] = []
    for seq in itertools.product(planes, repeat=k):
        variants = [tuple(Leaf(p) for p in seq)]
        m = k // 2
        if k % 2 and k > 1 and seq == seq[::-1] and seq[m] != seq[m - 1]:
            variants.append(tuple(Leaf(p, 2 if i == m else 1) for i, p in enumerate(seq)))
        for leaves in variants:
            for rein in (False, True) if reinforce else (False,):
                lv = tuple(Leaf(lf.plane, lf.width, rein) for lf in leaves)
                designed = free_crossing and not (prune and len(set(seq)) < 2)
                out += [Stage(lv, False, fc) for fc in ((False, True) if designed else (False,))]
    if inplane and k >= 2:
        for combo in itertools.combinations(sorted(planes), k):
            leaves = tuple(Leaf(p) for p in combo)
            out += [Stage(leaves, True, fc) for fc in ((False, True) if free_crossing else (False,))]
    return out


def enumerate_topologies(
    max_flexures: int,
    max_stages: int,
    planes: str = "+-",
    inplane: bool = True,
    free_crossing: bool = True,
    reinforce: bool = False,
    prune: bool = False,
) -> list[Topology]:
    """Every topology with at most ``max_flexures`` leaves in at most ``max_stages`` stages, one per symmetry
    class (canonical form), sorted by (flexures, stages, descriptor).

    Parameters
    ----------
    max_flexures, max_stages
        Bounds on the leaves in total and on the stages in series.
    planes
        The leaf planes to place (a subset of ``"+-0"``).
    inplane, free_crossing, reinforce
        Whether to generate in-plane crossings, designed crossing fractions and reinforced stages.
    prune
        Leave out the designed crossing ('@') of a stage whose leaves cross nothing (:func:`crosses`).
    """
    if not set(planes) <= set("+-0") or not planes:
        raise ValueError(f"planes must be a non-empty subset of '+-0', got {planes!r}")
    per_k = {
        k: _stage_patterns(k, planes, inplane, free_crossing, reinforce, prune) for k in range(1, max_flexures + 1)
    }
    tops = (
        Topology(tuple(stages))
        for s in range(1, max_stages + 1)
        for sizes in itertools.product(range(1, max_flexures + 1), repeat=s)
        if sum(sizes) <= max_flexures
        for stages in itertools.product(*(per_k[k] for k in sizes))
    )
    return sorted(_one_per_form(tops), key=lambda t: (t.flexures, len(t.stages), str(t)))


def _one_per_form(tops: Iterable[Topology | str]) -> list[Topology]:
    """The canonical forms of ``tops``, each once, in the order of its first member."""
    seen: dict[str, Topology] = {}
    for t in tops:
        c = canonical(t)
        seen.setdefault(str(c), c)
    return list(seen.values())


def candidate_topologies(
    topologies: Sequence[str] | None, max_flexures: int, max_stages: int, **options: Any
) -> list[Topology]:
    """A search's candidates: the given descriptors, one per canonical form in their first order, or else every
    topology ``enumerate_topologies(max_flexures, max_stages, **options)`` generates (the search ranks these;
    the job's cost estimate counts them)."""
    if topologies is not None:
        return _one_per_form(topologies)
    return enumerate_topologies(max_flexures, max_stages, **options)


# ---------------------------------------------------------------------------------------------- guides
#: Every place of a wire: nine vertical (z) and nine lateral (y).
GUIDE_PLACES: tuple[str, ...] = tuple(d + i + j for d in "zy" for i in "-0+" for j in "-0+")


@dataclass(frozen=True)
class GuideTopology:
    """A straight guide: wire flexures at discrete places (``str`` gives its descriptor)."""

    wires: tuple[str, ...]

    def __str__(self) -> str:
        return "T:" + ",".join(self.wires)

    @property
    def flexures(self) -> int:
        """Number of wire flexures."""
        return len(self.wires)

    def to_dict(self) -> dict:
        """A JSON form: the descriptor and the wires."""
        return {"descriptor": str(self), "flexures": self.flexures, "wires": list(self.wires)}


def parse_guide(descriptor: str) -> GuideTopology:
    """The guide of a descriptor (``parse_guide(str(g)) == g``); SceneError on a malformed one."""
    return GuideTopology(tuple(guide_layout(descriptor)))


def canonical_guide(g: GuideTopology | str) -> GuideTopology:
    """The representative of a guide's class under the mirror x -> -x and the order of the wires."""
    g = parse_guide(g) if isinstance(g, str) else g
    flip = {"-": "+", "+": "-", "0": "0"}
    images = [tuple(sorted(g.wires)), tuple(sorted(w[0] + flip[w[1]] + w[2] for w in g.wires))]
    return GuideTopology(min(images, key=lambda ws: "T:" + ",".join(ws)))


def enumerate_guides(wires: int) -> list[GuideTopology]:
    """Every guide of exactly ``wires`` wires at different places (:data:`GUIDE_PLACES`), one per class."""
    seen: dict[str, GuideTopology] = {}
    for combo in itertools.combinations(GUIDE_PLACES, wires):
        c = canonical_guide(GuideTopology(combo))
        seen.setdefault(str(c), c)
    return sorted(seen.values(), key=str)
