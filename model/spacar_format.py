"""The line reader of SPACAR ``.dat`` files (:mod:`model.spacar`'s first step): each line into a
:class:`_Reader` by its keyword's handler, the errors collected per line. Below both :mod:`model.spacar`
(the scene) and :mod:`model.spacar_dcc` (SPACAR's D_cc), which read a file alike."""

from __future__ import annotations

from dataclasses import dataclass, field

from .errors import SceneError

__all__ = ["SpacarError"]

_MODE = {1: "eps1", 2: "eps2", 3: "eps3", 4: "eps4", 5: "eps5", 6: "eps6"}


class SpacarError(SceneError):
    """Lines of a ``.dat`` file that cannot be mapped: ``lines``, each "line N: KEYWORD: why"."""

    def __init__(self, lines: list[str]) -> None:
        super().__init__("spacar", "; ".join(lines))
        self.lines = list(lines)


class _Errors:
    def __init__(self) -> None:
        self.items: list[str] = []

    def add(self, line: int, keyword: str, why: str) -> None:
        self.items.append(f"line {line}: {keyword}: {why}")


def _numbers(tokens: list[str], line: int, keyword: str, errors: _Errors) -> list[float] | None:
    try:
        return [float(t) for t in tokens]
    except ValueError:
        errors.add(line, keyword, f"'{' '.join(tokens)}' is not a list of numbers; write plain numbers")
        return None


@dataclass
class _Reader:
    """What :func:`read_dat` has read so far and made of it: the lines' contents per keyword, the line being read
    (``ln``, ``kw``, its numbers ``v`` and ``ints`` when all are integers), then the roles of the node numbers and
    the scene's parts as they are assembled (one method per step, in the order :func:`read_dat` calls them)."""

    err: _Errors = field(default_factory=_Errors)
    X: dict[int, tuple[list[float], int]] = field(default_factory=dict)
    beams: list[tuple] = field(default_factory=list)  # BEAM and BEAMW: (Ne, Xp, Rp, Xq, Rq, Oy, line)
    #: BEAMW elements: Ne -> (Wp, Wq, line), their warping nodes
    warp: dict[int, tuple[int, int, int]] = field(default_factory=dict)
    trusses: list[tuple] = field(default_factory=list)
    dyne: dict[int, set[int]] = field(default_factory=dict)
    estiff: dict[int, tuple[list[float], int]] = field(default_factory=dict)
    em: dict[int, tuple[list[float], int]] = field(default_factory=dict)
    fixes: list[tuple[int, list[int], int]] = field(default_factory=list)
    inputs: list[tuple[int, list[int], int]] = field(default_factory=list)
    delinp: list[tuple[int, int, float, int]] = field(default_factory=list)
    dynx: list[tuple[int, list[int], int]] = field(default_factory=list)
    rlse: dict[int, list[tuple[list[int], int]]] = field(default_factory=dict)
    hinges: list[tuple[int, int, int, list[float], int]] = field(default_factory=list)
    xf: dict[int, tuple[list[float], int]] = field(default_factory=dict)
    delxf: dict[int, tuple[list[float], int]] = field(default_factory=dict)
    xm: dict[int, tuple[list[float], int]] = field(default_factory=dict)
    crossdim: dict[int, tuple[float, float]] = field(default_factory=dict)
    beamprops: list[int] = field(default_factory=list)  # SPACAR Light: the beams the next CROSSDIM is of
    crosstype: str = ""
    gravity: list[float] | None = None
    steps: int | None = None
    mapped: dict[str, int] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    # the line being read
    ln: int = 0
    kw: str = ""
    v: list[float] = field(default_factory=list)
    ints: list[int] | None = None
    # assembled
    r_of: dict[int, int] = field(default_factory=dict)  # X -> its first R
    x_of: dict[int, int] = field(default_factory=dict)  # R -> X
    #: a second R at an X (R -> (X, element, line)): a HINGE must join it
    extra: dict[int, tuple[int, int, int]] = field(default_factory=dict)
    numbering: str = ""
    w_nodes: dict[int, list[int]] = field(default_factory=dict)  # W node -> the BEAMW elements using it
    w_fixed: dict[int, int] = field(default_factory=dict)  # W node -> its FIX line
    member_of: dict[int, str] = field(default_factory=dict)  # beam element -> the flexopt member it is part of
    chain_of: dict[str, list[str]] = field(default_factory=dict)  # merged member -> its beam elements in order
    joints: list[dict] = field(default_factory=list)
    hinged: set[int] = field(default_factory=set)
    elements: list[dict] = field(default_factory=list)
    materials: list[dict] = field(default_factory=list)
    rigid_links: list[tuple[int, int, int]] = field(default_factory=list)  # (Ne, Xp, Xq): no flexible deformation
    spacar_dof: int = 0
    #: released (RLSE) deformations of beams and trusses, "BEAM 4" -> [3, 5]
    released_report: dict[str, list[int]] = field(default_factory=dict)
    parent: dict[int, int] = field(default_factory=dict)  # union-find of the rigid bodies' X nodes
    bodies: list[dict] = field(default_factory=list)
    carrier: dict[int, str] = field(default_factory=dict)
    fixed: dict[int, set[str]] = field(default_factory=dict)
    fixed_extra: dict[str, set[str]] = field(default_factory=dict)  # rotation fixes of a hinged point's second R
    fix_line: dict[int, int] = field(default_factory=dict)
    stroke: dict | None = None
    supports: list[dict] = field(default_factory=list)
    loads: list[dict] = field(default_factory=list)

    def need(self, count: int, form: str, at_least: bool = False) -> bool:
        """Whether the line being read has ``count`` numbers after its keyword (``at_least``: that many or more);
        if not, the error naming the expected ``form``."""
        v = self.v
        ok = len(v) >= count if at_least else len(v) == count
        if not ok:
            self.err.add(
                self.ln,
                self.kw,
                f"expected '{form}' ({'at least ' if at_least else ''}{count} numbers after the keyword), got {len(v)}",
            )
        return ok

    def visual_line(self, ln: int, kw: str, tokens: list[str]) -> None:
        """A line inside the VISUALIZATION block: CROSSDIM is mapped (``CROSSDIM Ne w t``, or SPACAR Light's
        ``BEAMPROPS Ne...`` / ``CROSSTYPE RECT`` / ``CROSSDIM w t`` for the listed beams), the others only noted."""
        if kw in ("BEAMPROPS", "CROSSTYPE"):
            if kw == "BEAMPROPS":
                v = _numbers(tokens, ln, kw, self.err)
                self.beamprops = [int(x) for x in v or []]
                self.crosstype = "RECT"
            else:
                self.crosstype = tokens[0].upper() if tokens else ""
            self.mapped[kw] = self.mapped.get(kw, 0) + 1
        elif kw == "CROSSDIM":
            v = _numbers(tokens, ln, kw, self.err)
            if v is None:
                return
            if len(v) == 2 and self.crosstype != "RECT":
                self.notes.append(
                    f"line {ln}: CROSSDIM of a {self.crosstype or 'section'} cross-section: not mapped (a rectangle "
                    "only), so those beams' stresses are not available"
                )
                return
            if len(v) == 2:  # SPACAR Light: the dimensions of the BEAMPROPS list
                self.crossdim.update({ne: (v[0], v[1]) for ne in self.beamprops})
            elif len(v) == 3:
                self.crossdim[int(v[0])] = (v[1], v[2])
            else:
                self.err.add(ln, kw, f"expected 'CROSSDIM Ne w t' or (after BEAMPROPS) 'CROSSDIM w t', got {len(v)}")
                return
            self.mapped[kw] = self.mapped.get(kw, 0) + 1
        else:
            self.notes.append(f"line {ln}: {kw} (visualisation only; nothing in the model)")

    # --- names and roles of node numbers
    @staticmethod
    def nname(xn: int) -> str:
        return f"n{xn}"

    def rname(self, rn: int) -> str:
        """The flexopt node of R node ``rn``: its X node's, or a node of its own where a HINGE joins a second
        rotational node to the same point."""
        return f"n{self.x_of[rn]}r{rn}" if rn in self.extra else self.nname(self.x_of[rn])

    def released(self, ne: int) -> set[int]:
        """The deformations of element ``ne`` listed in RLSE (released: calculated, e(c))."""
        return {k for ks, _ in self.rlse.get(ne, []) for k in ks}

    def role(self, n: int) -> str:
        if n in self.X:
            return "X"
        if n in self.x_of:
            return "R"
        return "W" if n in self.w_nodes else "?"

    def bkw(self, ne: int) -> str:
        """The keyword of beam element ``ne``'s line: BEAMW (warping nodes) or BEAM."""
        return "BEAMW" if ne in self.warp else "BEAM"

    def find(self, a: int) -> int:
        parent = self.parent
        parent.setdefault(a, a)
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a


# --- one handler per keyword: the line being read is r.ln, r.kw, r.v, r.ints


def _read_x(r: _Reader) -> None:
    if r.need(4, "X n x y z"):
        r.X[int(r.v[0])] = (r.v[1:4], r.ln)


def _read_beam(r: _Reader) -> None:
    v = r.v
    if r.need(8, "BEAM Ne Xp Rp Xq Rq Oy_x Oy_y Oy_z"):
        r.beams.append((int(v[0]), int(v[1]), int(v[2]), int(v[3]), int(v[4]), v[5:8], r.ln))


def _read_beamw(r: _Reader) -> None:
    v = r.v
    if r.need(10, "BEAMW Ne Xp Rp Wp Xq Rq Wq Oy_x Oy_y Oy_z"):
        ne = int(v[0])
        r.beams.append((ne, int(v[1]), int(v[2]), int(v[4]), int(v[5]), v[7:10], r.ln))
        r.warp[ne] = (int(v[3]), int(v[6]), r.ln)


def _read_truss(r: _Reader) -> None:
    v = r.v
    if r.need(3, "TRUSS Ne Xp Xq"):
        r.trusses.append((int(v[0]), int(v[1]), int(v[2]), r.ln))


def _read_dyne(r: _Reader) -> None:
    ints = r.ints
    if r.need(2, "DYNE Ne k...", True) and ints is not None:
        bad = [k for k in ints[1:] if k not in _MODE]
        if bad:
            r.err.add(r.ln, r.kw, f"deformation numbers {bad} are not 1-6")
        else:
            r.dyne.setdefault(ints[0], set()).update(ints[1:])


def _read_rlse(r: _Reader) -> None:
    if r.need(2, "RLSE Ne k...", True) and r.ints is not None:
        bad = [k for k in r.ints[1:] if k not in _MODE]
        if bad:
            r.err.add(r.ln, r.kw, f"deformation numbers {bad} are not 1-6")
        else:
            r.rlse.setdefault(r.ints[0], []).append((r.ints[1:], r.ln))


def _read_estiff(r: _Reader) -> None:
    if r.need(2, "ESTIFF Ne EA [GJ EIy EIz [Sy Sz [EIw]]]", True):
        r.estiff[int(r.v[0])] = (r.v[1:], r.ln)


def _read_em(r: _Reader) -> None:
    if r.need(2, "EM Ne rhoA [rho(Iy+Iz) rhoIy rhoIz [rhoIyz [rhoIw]]]", True):
        r.em[int(r.v[0])] = (r.v[1:], r.ln)


def _read_fix(r: _Reader) -> None:
    if r.need(1, "FIX n [k...]", True) and r.ints is not None:
        r.fixes.append((r.ints[0], r.ints[1:], r.ln))


def _read_inputx(r: _Reader) -> None:
    if r.need(2, "INPUTX n k...", True) and r.ints is not None:
        r.inputs.append((r.ints[0], r.ints[1:], r.ln))


def _read_dynx(r: _Reader) -> None:
    if r.need(2, "DYNX n k...", True) and r.ints is not None:
        r.dynx.append((r.ints[0], r.ints[1:], r.ln))


def _read_delinpx(r: _Reader) -> None:
    v = r.v
    if r.need(3, "DELINPX n k value"):
        r.delinp.append((int(v[0]), int(v[1]), v[2], r.ln))


def _read_force(r: _Reader) -> None:  # XF and DELXF
    if r.need(2, f"{r.kw} n f...", True):
        (r.xf if r.kw == "XF" else r.delxf)[int(r.v[0])] = (r.v[1:], r.ln)


def _read_xm(r: _Reader) -> None:
    if r.need(2, "XM n m  or  XM n Ixx Ixy Ixz Iyy Iyz Izz", True):
        r.xm[int(r.v[0])] = (r.v[1:], r.ln)


def _read_gravity(r: _Reader) -> None:
    if r.need(3, "GRAVITY gx gy gz"):
        r.gravity = r.v


def _read_iterstep(r: _Reader) -> None:
    if r.need(1, "ITERSTEP steps ...", True):
        v = r.v
        # SPACAR Light writes 'ITERSTEP 10 steps 5e-7 1 3 steps0' (spacarlight.m: its second number is
        # opt.loadsteps - 1, the first a constant 10); a shorter line gives the steps first
        r.steps = int(v[1]) if len(v) >= 6 and float(v[1]).is_integer() else int(v[0])
        if r.steps < 1:
            r.err.add(r.ln, r.kw, f"{r.steps} load steps; give at least 1")


def _read_hinge(r: _Reader) -> None:
    v = r.v
    if r.need(6, "HINGE Ne Rp Rq ax ay az"):
        r.hinges.append((int(v[0]), int(v[1]), int(v[2]), v[3:6], r.ln))


#: The mapped keywords outside the VISUALIZATION block (END, HALT and the block itself: :func:`_parse`).
_KEYWORDS = {
    "X": _read_x,
    "BEAM": _read_beam,
    "BEAMW": _read_beamw,
    "TRUSS": _read_truss,
    "DYNE": _read_dyne,
    "RLSE": _read_rlse,
    "ESTIFF": _read_estiff,
    "EM": _read_em,
    "FIX": _read_fix,
    "INPUTX": _read_inputx,
    "DYNX": _read_dynx,
    "DELINPX": _read_delinpx,
    "XF": _read_force,
    "DELXF": _read_force,
    "XM": _read_xm,
    "GRAVITY": _read_gravity,
    "ITERSTEP": _read_iterstep,
    "HINGE": _read_hinge,
}
#: Keywords known and refused, with why.
_REFUSED = {
    "ESIG": "initial stresses are not supported; remove the line (or model the preload as a load)",
}


def _parse(text: str) -> _Reader:
    """Every line of ``text`` into a :class:`_Reader` (its keyword's handler in ``_KEYWORDS``), errors collected."""
    r = _Reader()
    vis = False
    for ln, raw in enumerate(text.splitlines(), start=1):
        body = raw.split("#", 1)[0].strip()
        if not body:
            continue
        tok = body.replace(",", " ").split()
        kw = tok[0].upper()
        if kw == "HALT":  # SPACAR Light writes the stiffness, mass and loads after END/HALT: read on
            vis = False
            continue
        if kw == "END":
            vis = False
            continue
        if kw in ("VISUALIZATION", "VISUALISATION"):
            vis = True
            continue
        if vis:
            r.visual_line(ln, kw, tok[1:])
            continue
        v = _numbers(tok[1:], ln, kw, r.err)
        if v is None:
            continue
        r.ln, r.kw, r.v = ln, kw, v
        r.ints = [int(x) for x in v] if all(float(x).is_integer() for x in v) else None
        if kw in _REFUSED:
            r.err.add(ln, kw, _REFUSED[kw])
            continue
        handler = _KEYWORDS.get(kw)
        if handler is None:
            r.err.add(
                ln,
                kw,
                "unknown keyword (mapped: X BEAM BEAMW TRUSS HINGE DYNE RLSE ESTIFF EM FIX INPUTX "
                "DELINPX DYNX XF DELXF XM GRAVITY ITERSTEP END HALT VISUALIZATION/CROSSDIM)",
            )
            continue
        handler(r)
        r.mapped[kw] = r.mapped.get(kw, 0) + 1
    return r
