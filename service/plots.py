"""Every flexopt figure, drawn from wire data (the JSON-ready dicts of results), never from model objects.

One module for the command line, the service and client code: it imports matplotlib, numpy and scipy only
(no CasADi, no FastAPI), uses matplotlib's object API (``Figure``, no pyplot state, so it is thread-safe in
the server) and accepts either the dicts of ``to_dict()`` / the HTTP API or objects with a ``to_dict`` or
``model_dump`` method.

- :func:`curve_figure`: frequencies against stroke (first parasitic highlighted, tracked modes labelled,
  units, the design's key values in the title, linear or log frequency axis) over a second panel of the
  stress utilisation (von Mises / allowable) with the limit marked; warnings and truncation in a text box.
- :func:`shapes_figure`: the deflected structure in 3D (leaves as plates of their real width, bodies as
  boxes) with a mode shape overlaid at a stated scale; :func:`animate_mode` writes it as an animated GIF.
- :func:`stroke_figure`: the deflected structure at a few stroke values side by side (e.g. -45, 0 and +45
  deg), each panel titled with its first parasitic frequency, on common axes.
- :func:`pareto_figure`: a Pareto front of worst-case parasitic frequency against drive stiffness
  (optim/pareto.py), its single-objective optima marked, with the NSGA-II check's points if it ran.
- :func:`diagnosis_figure`: the exact-constraint diagnosis: self-stress as member colours with a colour bar,
  each free motion drawn as the structure moved along it (translation and rotation) with its rotation axis.
"""

from __future__ import annotations

import io
import re
import textwrap
from collections.abc import Sequence
from typing import Any

import numpy as np
from matplotlib.figure import Figure

__all__ = [
    "curve_figure",
    "curve_png",
    "shapes_figure",
    "stroke_figure",
    "animate_mode",
    "diagnosis_figure",
    "figure_bytes",
    "save",
    "mode_scale",
    "design_summary",
    "pareto_figure",
]

PARASITIC_COLOR = "#c0392b"
MODE_COLOR = "#e67e22"
PLATE_COLOR = "#7f8c8d"
BODY_COLOR = "#34495e"
STAGE_COLORS = ("#2471a3", "#e67e22", "#27ae60", "#8e44ad", "#c0392b", "#7f8c8d")
GROUND_COLOR = "#000000"  # stroke_figure's ground marks
AXIS_COLORS = ("#c0392b", "#27ae60", "#2471a3")  # x, y, z of stroke_figure's triad


def _data(obj: Any) -> dict:
    """A result as its wire dict."""
    if isinstance(obj, dict):
        return obj
    if hasattr(obj, "to_dict"):
        return obj.to_dict()
    if hasattr(obj, "model_dump"):
        return obj.model_dump(mode="json")
    raise TypeError(f"expected a result dict or an object with to_dict()/model_dump(), got {type(obj).__name__}")


def _arr(values: Sequence[Any]) -> np.ndarray:
    return np.array([np.nan if v is None else v for v in values], dtype=float)


def figure_bytes(fig: Figure, fmt: str = "png", dpi: int = 110) -> bytes:
    """The figure encoded as ``fmt`` (png, svg, pdf)."""
    buf = io.BytesIO()
    fig.savefig(buf, format=fmt, dpi=dpi)
    return buf.getvalue()


def save(fig: Figure, path: str, dpi: int = 120) -> None:
    """Write the figure to ``path`` (format from the extension)."""
    fig.savefig(path, dpi=dpi)


def _mm(v: float) -> str:
    return f"{v * 1e3:.4g} mm"


def design_summary(scene: dict | None) -> str:
    """Key values of a scene for a title: member lengths and rectangular sections, body masses, stroke."""
    if not scene:
        return ""
    scene = _data(scene)
    pos = {n["name"]: np.array(n["position"], dtype=float) for n in scene.get("nodes", [])}
    seen: dict[str, list[str]] = {}
    for e in scene.get("elements", []):
        p, q = e["nodes"]
        L = float(np.linalg.norm(pos[q] - pos[p])) if p in pos and q in pos else float("nan")
        sec = e.get("section") or {}
        key = f"L {_mm(L)}"
        if sec.get("kind") == "rectangular":
            key += f", w {_mm(sec['width'])}, t {_mm(sec['thickness'])}"
        elif e.get("kind") == "truss":
            key += f", A {e['area'] * 1e6:.3g} mm^2"
        seen.setdefault(key, []).append(e["name"])
    parts = [f"{len(v)}x ({k})" if len(v) > 1 else f"{v[0]}: {k}" for k, v in seen.items()]
    masses = [b for b in scene.get("bodies", []) if b.get("mass")]
    if masses:
        parts.append(", ".join(f"{b['name']} {b['mass'] * 1e3:.3g} g" for b in masses[:3]))
    st = scene.get("stroke")
    if st:
        unit = st.get("unit") or ("deg" if st.get("kind", "rotation") == "rotation" else "m")
        if st.get("start") is not None and st.get("stop") is not None:
            parts.append(f"stroke {st['start']:.4g} to {st['stop']:.4g} {unit}")
    return "; ".join(parts)


def _warning_lines(d: dict, width: int = 110) -> list[str]:
    lines = []
    for w in d.get("warnings") or []:
        lines += textwrap.wrap(f"[{w['kind']}] {w['message']}", width)
    for f in d.get("failures") or []:
        lines += textwrap.wrap(f"[truncated] {f['message']}", width)
    return lines


# ------------------------------------------------------------------------------------------------- curve
def curve_figure(curve: Any, scene: Any = None, log: bool | None = None) -> Figure:
    """Frequency curve and stress utilisation against stroke.

    ``log``: logarithmic frequency axis; ``None`` chooses it when the tracked modes span more than a
    factor 8 (so the first parasitic is not squashed under kHz modes).
    """
    d = _data(curve)
    stroke = _arr(d["stroke"])
    unit = d["stroke_unit"]
    rows = [_arr(r) for r in d["modes_hz"]]
    modes = np.array(rows).reshape(len(stroke), len(rows[0]) if rows else 0)
    labels = d.get("mode_labels") or []
    par = _arr(d["parasitic_hz"])
    warn = _warning_lines(d)
    members = list(d.get("max_von_mises", {}))
    fig = Figure(figsize=(8, 6.2 + 0.16 * min(len(warn), 8)))
    bottom = 0.08 + 0.025 * min(len(warn), 8)
    gs = fig.add_gridspec(2, 1, height_ratios=[3, 1.25], hspace=0.08, left=0.1, right=0.8, top=0.88, bottom=bottom)
    ax = fig.add_subplot(gs[0])
    ax2 = fig.add_subplot(gs[1], sharex=ax)
    finite = modes[np.isfinite(modes) & (modes > 0)]
    if log is None:
        log = finite.size > 0 and finite.max() / finite.min() > 8
    i0 = int(np.argmin(np.abs(stroke))) if len(stroke) else 0
    for j in range(modes.shape[1]):
        lab = labels[i0][j] if len(labels) > i0 and j < len(labels[i0]) else ""
        ls = "-" if lab == "parasitic" else ("--" if lab == "intended" else ":")
        (line,) = ax.plot(
            stroke,
            modes[:, j],
            lw=1,
            ls=ls,
            color=f"C{j % 10}",
            alpha=0.8,
            label=f"mode {j + 1} ({lab})" if lab else f"mode {j + 1}",
        )
        ok = np.flatnonzero(np.isfinite(modes[:, j]))
        if len(ok):
            k = ok[-1]
            ax.annotate(
                f"{j + 1}",
                (stroke[k], modes[k, j]),
                xytext=(3, 0),
                textcoords="offset points",
                fontsize=7,
                color=line.get_color(),
                va="center",
            )
    ax.plot(stroke, par, color=PARASITIC_COLOR, lw=3, alpha=0.9, label="first parasitic", zorder=5)
    if np.isfinite(par).any():
        k = int(np.nanargmin(par))
        ax.plot(stroke[k], par[k], "o", color=PARASITIC_COLOR, zorder=6)
        ax.annotate(
            f"worst {par[k]:.4g} Hz at {stroke[k]:.3g} {unit}",
            (stroke[k], par[k]),
            xytext=(0, -14 if not log else -16),
            textcoords="offset points",
            ha="center",
            fontsize=8,
            color=PARASITIC_COLOR,
        )
    if log:
        ax.set_yscale("log")
    ax.set_ylabel("natural frequency [Hz]" + (" (log)" if log else ""))
    ax.grid(alpha=0.3, which="both")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    ax.tick_params(labelbottom=False)
    title = f"{d.get('scene', '')} ({d.get('method', '')}, {d.get('stroke_kind', '')} stroke)"
    summary = design_summary(scene)
    fig.suptitle(title + ("\n" + "\n".join(textwrap.wrap(summary, 95)) if summary else ""), fontsize=9.5)
    allow = d.get("allowable_stress", {})
    peak = 0.0
    for i, m in enumerate(members):
        util = _arr(d["max_von_mises"][m]) / allow.get(m, np.nan)
        if np.isfinite(util).any():
            peak = max(peak, float(np.nanmax(util)))
        ax2.plot(stroke, util, lw=1.5, color=f"C{i % 10}", label=m if len(members) <= 8 else None)
    ax2.axhline(1.0, color="red", ls="--", lw=1.2, label="allowable")
    ax2.set_ylim(0, max(1.1, 1.1 * peak))
    ax2.set_ylabel("von Mises /\nallowable [-]")
    ax2.set_xlabel(f"stroke [{unit}]")
    ax2.grid(alpha=0.3)
    ax2.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7, frameon=False)
    if warn:
        fig.text(
            0.02,
            0.01,
            "\n".join(warn[:8]) + ("\n..." if len(warn) > 8 else ""),
            fontsize=7,
            va="bottom",
            family="monospace",
            color="#8e2c1f",
            bbox=dict(boxstyle="round", fc="#fdecea", ec="#e0b4ae"),
        )
    return fig


def curve_png(curve: Any, scene: Any = None, log: bool | None = None, dpi: int = 100) -> bytes:
    """:func:`curve_figure` as PNG bytes."""
    return figure_bytes(curve_figure(curve, scene, log), "png", dpi)


# ------------------------------------------------------------------------------------------------ shapes
def _rotmat(rotvec: Sequence[float] | np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_rotvec(np.asarray(rotvec, dtype=float)).as_matrix()


def _extent(d: dict) -> float:
    p = np.array(list(d["nodes"].values()), dtype=float)
    return float(max(np.ptp(p, axis=0).max(), 1e-12))


def mode_scale(shapes: Any, mode: int, fraction: float = 0.12) -> float:
    """Amplitude drawing mode ``mode`` so its largest nodal displacement (including the plate edges'
    motion from nodal rotations) is ``fraction`` of the structure's extent."""
    d = _data(shapes)
    m = d["modes"][mode]
    half = max([(mb.get("width") or 0.0) / 2 for mb in d["members"].values()] + [0.0])
    u = np.array(list(m["translation"].values()), dtype=float)
    r = np.array(list(m["rotation"].values()), dtype=float)
    peak = max(
        float(np.linalg.norm(u, axis=1).max(initial=0)) + half * float(np.linalg.norm(r, axis=1).max(initial=0)), 1e-300
    )
    return fraction * _extent(d) / peak


def _moved(d: dict, mode: dict | None, a: float) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Node positions and a function of rotation per node: the deflected state plus ``a`` times the mode."""
    pos = {n: np.array(p, dtype=float) for n, p in d["nodes"].items()}
    rot = {n: _rotmat(v) for n, v in d["orientations"].items()}
    if mode is not None and a != 0.0:
        for n in pos:
            pos[n] = pos[n] + a * np.asarray(mode["translation"][n], dtype=float)
            rot[n] = _rotmat(a * np.asarray(mode["rotation"][n], dtype=float)) @ rot[n]
    return pos, rot


def _draw_structure(
    ax: Any,
    d: dict,
    pos: dict,
    rot: dict,
    *,
    color: str = PLATE_COLOR,
    alpha: float = 0.85,
    edge: str = "k",
    lw: float = 0.4,
    bodies: dict | None = None,
    facecolors: dict[str, Any] | None = None,
) -> list[np.ndarray]:
    """Plates (rectangular sections, real width), lines (other members) and body boxes; returns the points
    drawn (for the axis limits)."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    pts: list[np.ndarray] = []
    for name, mb in d["members"].items():
        chain = [n for n in mb["nodes"] if n in pos]
        P = np.array([pos[n] for n in chain])
        fc = (facecolors or {}).get(name, color)
        w = mb.get("width")
        if w and mb.get("y_axis") is not None and len(chain) > 1:
            y0 = np.asarray(mb["y_axis"], dtype=float)
            Y = np.array([rot[n] @ y0 for n in chain]) * (w / 2)
            quads = [[P[i] - Y[i], P[i + 1] - Y[i + 1], P[i + 1] + Y[i + 1], P[i] + Y[i]] for i in range(len(P) - 1)]
            ax.add_collection3d(Poly3DCollection(quads, facecolors=fc, edgecolors=edge, linewidths=lw, alpha=alpha))
            pts += [P - Y, P + Y]
        else:
            ax.plot(*P.T, color=fc, lw=2.0, alpha=alpha)
            pts.append(P)
    for b in (bodies if bodies is not None else d.get("bodies", {})).values():
        c, R = b["_centre"], b["_R"]
        size = np.asarray(b["size"], dtype=float)
        signs = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], dtype=float)
        V = c + (signs * size / 2) @ R.T
        faces = [[0, 1, 3, 2], [4, 5, 7, 6], [0, 1, 5, 4], [2, 3, 7, 6], [0, 2, 6, 4], [1, 3, 7, 5]]
        ax.add_collection3d(
            Poly3DCollection(
                [[V[i] for i in f] for f in faces],
                facecolors=BODY_COLOR,
                edgecolors="0.3",
                linewidths=lw,
                alpha=0.15 * alpha / 0.85,
            )
        )
        pts.append(V)
    return pts


def _body_poses(d: dict, mode: dict | None, a: float) -> dict:
    """Body boxes: centre and rotation at the deflected state, moved by ``a`` times the mode (the mode's
    motion of a body is read off its nodes: the rotation of any node, the translation of the box centre
    from a node by u + psi x r)."""
    out = {}
    for name, b in d.get("bodies", {}).items():
        R = _rotmat(b["orientation"])
        c = np.asarray(b["position"], dtype=float) + R @ np.asarray(b["center_offset"], dtype=float)
        if mode is not None and a != 0.0 and b["nodes"]:
            n0 = b["nodes"][0]
            psi = np.asarray(mode["rotation"][n0], dtype=float)
            u0 = np.asarray(mode["translation"][n0], dtype=float)
            r = c - np.asarray(d["nodes"][n0], dtype=float)
            c = c + a * (u0 + np.cross(psi, r))
            R = _rotmat(a * psi) @ R
        out[name] = {**b, "_centre": c, "_R": R}
    return out


def _equal_axes(ax: Any, pts: list[np.ndarray]) -> None:
    P = np.vstack(pts)
    lo, hi = P.min(axis=0), P.max(axis=0)
    span = max(float((hi - lo).max()), 1e-12)
    c = (lo + hi) / 2
    half = np.maximum((hi - lo) / 2, 0.04 * span) * 1.08
    ax.set_xlim(c[0] - half[0], c[0] + half[0])
    ax.set_ylim(c[1] - half[1], c[1] + half[1])
    ax.set_zlim(c[2] - half[2], c[2] + half[2])
    ax.set_box_aspect(half)


def _label_axes(ax: Any) -> None:
    from matplotlib.ticker import FuncFormatter

    fmt = FuncFormatter(lambda v, _: f"{v * 1e3:.0f}")
    for axis, _name in ((ax.xaxis, "x"), (ax.yaxis, "y"), (ax.zaxis, "z")):
        axis.set_major_formatter(fmt)
    ax.set_xlabel("x [mm]", fontsize=8)
    ax.set_ylabel("y [mm]", fontsize=8)
    ax.set_zlabel("z [mm]", fontsize=8)
    ax.tick_params(labelsize=7)


def _mode_title(d: dict, mode: int | None, a: float) -> str:
    t = f"{d.get('scene', '')} at stroke {d['stroke']:.4g} {d.get('stroke_unit', '')}"
    if mode is None:
        return t + ": deflected state"
    m = d["modes"][mode]
    shown = a * mode_scale(d, mode, 1.0) ** -1 * _extent(d)  # the largest drawn displacement, plate edges included
    return (
        t + f"\nmode {mode + 1}: {m['hz']:.4g} Hz ({m['label']}), mass-normalised shape drawn at scale {a:.3g}\n"
        f"(largest displacement shown {shown * 1e3:.3g} mm, plate edges included; grey = deflected state)"
    )


def _draw_frame(ax: Any, d: dict, mode: int | None, a: float, fixed_limits: list[np.ndarray] | None = None) -> list:
    pos, rot = _moved(d, None, 0.0)
    pts = _draw_structure(
        ax, d, pos, rot, alpha=0.25 if mode is not None else 0.85, edge="0.5", bodies=_body_poses(d, None, 0.0)
    )
    if mode is not None:
        m = d["modes"][mode]
        pos2, rot2 = _moved(d, m, a)
        pts += _draw_structure(ax, d, pos2, rot2, color=MODE_COLOR, alpha=0.85, bodies=_body_poses(d, m, a))
    _equal_axes(ax, fixed_limits or pts)
    _label_axes(ax)
    return pts


def shapes_figure(
    shapes: Any, mode: int | None = None, scale: float | None = None, view: tuple[float, float] = (22.0, -60.0)
) -> Figure:
    """The deflected structure in 3D with mode ``mode`` (index into ``shapes['modes']``) overlaid.

    ``scale``: amplitude of the drawn mode (default :func:`mode_scale`); the title states it.
    """
    d = _data(shapes)
    a = 0.0 if mode is None else (scale if scale is not None else mode_scale(d, mode))
    fig = Figure(figsize=(7.5, 6))
    ax = fig.add_subplot(projection="3d")
    ax.view_init(*view)
    _draw_frame(ax, d, mode, a)
    fig.suptitle(_mode_title(d, mode, a), fontsize=9)
    warn = _warning_lines(d, 100)
    if warn:
        fig.text(
            0.02,
            0.01,
            "\n".join(warn[:4]),
            fontsize=7,
            color="#8e2c1f",
            bbox=dict(boxstyle="round", fc="#fdecea", ec="#e0b4ae"),
        )
    fig.subplots_adjust(left=0.0, right=1.0, bottom=0.04, top=0.9)
    return fig


def _first_parasitic(d: dict) -> float | None:
    hz = [m["hz"] for m in d.get("modes", []) if m.get("label") == "parasitic"]
    return min(hz) if hz else None


def stroke_figure(
    shapes: Sequence[Any],
    title: str = "",
    view: tuple[float, float] = (28.0, -62.0),
    size: tuple[float, float] = (8.4, 3.0),
    bodies: bool = True,
    ground: Sequence[str] = (),
    axes: float | None = None,
) -> Figure:
    """The deflected structure at each of ``shapes`` (``model.shapes.shapes_along``'s answers, one per stroke
    value) side by side on common axes, leaves as plates of their real width, bodies as boxes; each panel
    titled with its stroke and, when its modes were computed, its first parasitic frequency; ``bodies=False``
    leaves the body boxes out (they hide the leaves of a compact hinge). ``ground``: the clamped nodes (the
    scene's supports), each marked with a black square (:data:`GROUND_COLOR`); ``axes``: the length [m] of an
    x, y, z triad (the scene's axes; z the axis a hinge turns about) drawn at the origin over the structure, its
    length said in the key line."""
    ds = [_data(s) for s in shapes]
    fig = Figure(figsize=size)
    n = len(ds)
    # a topology hinge's leaves are named s<stage>l<leaf>[a|b] (the halves of an in-plane crossing): one colour
    # per stage, so the stages read apart
    stage = {m: g.group(1) for m in (ds[0]["members"] if ds else {}) if (g := re.fullmatch(r"(s\d+)l\d+[ab]?", m))}
    colour = {st: STAGE_COLORS[i % len(STAGE_COLORS)] for i, st in enumerate(sorted(set(stage.values())))}
    faces = {m: colour[st] for m, st in stage.items()}
    drawn: list[tuple[Any, list[np.ndarray]]] = []
    for i, d in enumerate(ds):
        ax = fig.add_subplot(1, n, i + 1, projection="3d")
        ax.view_init(*view)
        pos, rot = _moved(d, None, 0.0)
        boxes = _body_poses(d, None, 0.0) if bodies else {}
        pts = _draw_structure(ax, d, pos, rot, edge="0.35", lw=0.3, bodies=boxes, facecolors=faces)
        fixed = np.array([pos[n] for n in ground if n in pos]).reshape(-1, 3)
        if len(fixed):
            ax.scatter(*fixed.T, marker="s", s=22, c=GROUND_COLOR, depthshade=False, zorder=10)
        drawn.append((ax, pts))
        hz = _first_parasitic(d)
        ax.set_title(
            f"{d['stroke']:+.0f} {d.get('stroke_unit', '')}" + (f": first parasitic {hz:.4g} Hz" if hz else ""),
            fontsize=8,
            pad=0,
        )
    every = [p for _, pts in drawn for p in pts]
    if axes:
        every.append(1.3 * axes * np.eye(3))
    for i, (ax, _) in enumerate(drawn):
        _equal_axes(ax, every)
        ax.set_box_aspect(ax.get_box_aspect(), zoom=1.35)
        ax.set_axis_off()
        if axes:  # on a transparent twin with the same view and limits, drawn over the leaves that would hide it
            top = fig.add_subplot(1, n, i + 1, projection="3d")
            top.view_init(*view)
            top.set_xlim(ax.get_xlim())
            top.set_ylim(ax.get_ylim())
            top.set_zlim(ax.get_zlim())
            top.set_box_aspect(ax.get_box_aspect(), zoom=1.35)
            top.set_axis_off()
            top.patch.set_alpha(0.0)
            for k, (name, c) in enumerate(zip("xyz", AXIS_COLORS)):
                tip = np.eye(3)[k] * axes
                top.plot(*np.array([np.zeros(3), tip]).T, color=c, lw=1.3)
                top.text(*(1.3 * tip), name, color=c, fontsize=7, ha="center", va="center")
    if title:
        fig.suptitle(title, fontsize=9)
    key = (["black squares: ground (clamped)"] if ground else []) + (
        [f"x, y, z: the scene's axes, {axes * 1e3:.3g} mm long (z: the rotation axis)"] if axes else []
    )
    if key:
        fig.text(0.01, 0.01, "; ".join(key), fontsize=7, color="0.25")
    fig.subplots_adjust(left=0.0, right=1.0, bottom=0.0, top=0.84 if title else 0.95, wspace=0.0)
    return fig


def animate_mode(
    shapes: Any,
    mode: int,
    path: str,
    scale: float | None = None,
    frames: int = 20,
    fps: int = 12,
    view: tuple[float, float] = (22.0, -60.0),
    dpi: int = 80,
) -> None:
    """Write mode ``mode`` oscillating about the deflected state as an animated GIF (matplotlib animation,
    Pillow writer); the amplitude (``scale``, default :func:`mode_scale`) is stated in the title."""
    from matplotlib.animation import FuncAnimation, PillowWriter

    d = _data(shapes)
    a = scale if scale is not None else mode_scale(d, mode)
    fig = Figure(figsize=(6.4, 5.2))
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    ax = fig.add_subplot(projection="3d")
    fig.suptitle(_mode_title(d, mode, a), fontsize=8)
    fig.subplots_adjust(left=0.0, right=1.0, bottom=0.02, top=0.88)
    ax.view_init(*view)
    limits = _draw_frame(ax, d, mode, a) + _draw_frame(ax, d, mode, -a)

    def frame(k: int) -> list:
        ax.cla()
        ax.view_init(*view)
        _draw_frame(ax, d, mode, a * float(np.sin(2 * np.pi * k / frames)), fixed_limits=limits)
        return []

    FuncAnimation(fig, frame, frames=frames, blit=False).save(path, writer=PillowWriter(fps=fps), dpi=dpi)


# --------------------------------------------------------------------------------------------- diagnosis
def _scene_geometry(scene: dict) -> dict:
    """The reference configuration of a scene in the shapes wire form (nodes incl. segment-internal ones,
    zero orientations, member chains and widths, body boxes), for drawing a diagnosis."""
    pos = {n["name"]: np.array(n["position"], dtype=float) for n in scene["nodes"]}
    nodes = dict(pos)
    members = {}
    for e in scene["elements"]:
        p, q = e["nodes"]
        n = int(e.get("segments", 1))
        chain = [p]
        for i in range(1, n):
            nodes[f"{e['name']}#{i}"] = pos[p] + (pos[q] - pos[p]) * i / n
            chain.append(f"{e['name']}#{i}")
        chain.append(q)
        sec = e.get("section") or {}
        y = None
        if e.get("kind", "beam") == "beam" and e.get("y_axis") is not None:
            t = (pos[q] - pos[p]) / np.linalg.norm(pos[q] - pos[p])
            y = np.asarray(e["y_axis"], dtype=float)
            y = y - (y @ t) * t
            y = (y / np.linalg.norm(y)).tolist()
        members[e["name"]] = {
            "nodes": chain,
            "width": sec.get("width") if sec.get("kind") == "rectangular" else None,
            "y_axis": y,
        }
    P = np.array(list(nodes.values()))
    ext = float(max(np.ptp(P, axis=0).max(), 1e-12))
    bodies = {}
    for b in scene.get("bodies", []):
        com = np.asarray(b["center_of_mass"], dtype=float)
        pts = np.array([pos[n] for n in b.get("nodes", [])] + [com])
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        bodies[b["name"]] = {
            "nodes": list(b.get("nodes", [])),
            "size": np.maximum(hi - lo, 0.06 * ext).tolist(),
            "center_offset": ((lo + hi) / 2 - com).tolist(),
            "position": com.tolist(),
            "orientation": [0.0, 0.0, 0.0],
        }
    return {
        "nodes": {k: v.tolist() for k, v in nodes.items()},
        "orientations": {k: [0.0, 0.0, 0.0] for k in nodes},
        "members": members,
        "bodies": bodies,
    }


def _free_motion(scene: dict, geo: dict, motion: dict, Lc: float) -> dict:
    """A free motion of the diagnosis (master -> {translation [L_c per unit], rotation [rad per unit]}) as
    a mode in the shapes wire form: node translation u + psi x r, rotation psi (masters missing from the
    motion do not move)."""
    owner = {n: b["name"] for b in scene.get("bodies", []) for n in b.get("nodes", [])}
    com = {b["name"]: np.asarray(b["center_of_mass"], dtype=float) for b in scene.get("bodies", [])}
    tr, ro = {}, {}
    for n, p in geo["nodes"].items():
        m = owner.get(n, n)
        v = motion.get(m)
        if v is None:
            tr[n], ro[n] = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
            continue
        u = Lc * np.asarray(v.get("translation", [0, 0, 0]), dtype=float)
        psi = np.asarray(v.get("rotation", [0, 0, 0]), dtype=float)
        r = np.asarray(p, dtype=float) - com[m] if m in com else np.zeros(3)
        tr[n], ro[n] = (u + np.cross(psi, r)).tolist(), psi.tolist()
    return {"translation": tr, "rotation": ro}


def _motion_text(motion: dict) -> str:
    parts = []
    for m, v in motion.items():
        t = np.asarray(v.get("translation", [0, 0, 0]), dtype=float)
        r = np.asarray(v.get("rotation", [0, 0, 0]), dtype=float)
        bits = []
        if np.linalg.norm(t) > 1e-6:
            bits.append("translation " + ", ".join(f"{c}{x:+.2f}" for c, x in zip("xyz", t) if abs(x) > 1e-3))
        if np.linalg.norm(r) > 1e-6:
            bits.append("rotation " + ", ".join(f"r{c}{x:+.2f}" for c, x in zip("xyz", r) if abs(x) > 1e-3))
        if bits:
            parts.append(f"{m}: " + "; ".join(bits))
    return "; ".join(parts[:4]) + (" ..." if len(parts) > 4 else "")


def diagnosis_figure(scene: Any, diagnosis: Any, max_motions: int = 4) -> Figure:
    """The exact-constraint diagnosis drawn on the structure (reference geometry, or as given).

    Members are coloured by the first self-stress (generalised stress of the largest magnitude per member,
    normalised; colour bar, red tension, blue compression); each free motion (kinematic mode) is drawn as
    the structure moved along it, translations and rotations together (amplitude stated), with an arrow
    along the rotation axis of every master that rotates.
    """
    from matplotlib import colormaps
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize

    sc, dg = _data(scene), _data(diagnosis)
    geo = _scene_geometry(sc)
    Lc = float(dg.get("characteristic_length") or _extent(geo))
    stress: dict[str, float] = {}
    if dg.get("static_modes"):
        for el, comps in dg["static_modes"][0].items():
            member = el.split("[")[0].split("#")[0]
            val = max(comps.values(), key=abs) if isinstance(comps, dict) else float(comps)
            if abs(val) > abs(stress.get(member, 0.0)):
                stress[member] = val
    smax = max((abs(v) for v in stress.values()), default=1.0) or 1.0
    cmap = colormaps["coolwarm"]
    norm = Normalize(-1.0, 1.0)
    faces = {m: cmap(norm(v / smax)) for m, v in stress.items()}
    fig = Figure(figsize=(8, 6.5))
    ax = fig.add_subplot(projection="3d")
    ax.view_init(24, -58)
    ref_bodies = _body_poses(geo, None, 0.0)
    pos, rot = _moved(geo, None, 0.0)
    pts = _draw_structure(ax, geo, pos, rot, alpha=0.8, facecolors=faces, bodies=ref_bodies)
    legend = []
    ext = _extent(geo)
    for i, motion in enumerate((dg.get("kinematic_modes") or [])[:max_motions]):
        mode = _free_motion(sc, geo, motion, Lc)
        u = np.array(list(mode["translation"].values()))
        peak = float(np.linalg.norm(u, axis=1).max(initial=0)) or 1.0
        a = 0.25 * ext / peak
        color = f"C{(i + 1) % 10}"
        p2, r2 = _moved(geo, mode, a)
        pts += _draw_structure(ax, geo, p2, r2, color=color, alpha=0.35, edge=color, bodies=_body_poses(geo, mode, a))
        for m, v in motion.items():
            psi = np.asarray(v.get("rotation", [0, 0, 0]), dtype=float)
            if np.linalg.norm(psi) > 1e-6:
                at = ref_bodies[m]["_centre"] if m in ref_bodies else np.asarray(geo["nodes"].get(m, [0, 0, 0]))
                ax.quiver(*at, *(0.3 * ext * psi / np.linalg.norm(psi)), color=color, lw=2.5, arrow_length_ratio=0.25)
        legend.append(
            (color, f"free motion {i + 1} (amplitude {a:.3g}, ghost; arrow = rotation axis): " + _motion_text(motion))
        )
    for s in sc.get("supports", []):
        if s.get("node") in geo["nodes"]:
            ax.scatter(*np.asarray(geo["nodes"][s["node"]]), marker="^", color="C2", s=50)
    _equal_axes(ax, pts)
    _label_axes(ax)
    if stress:
        fig.colorbar(
            ScalarMappable(norm=norm, cmap=cmap),
            ax=ax,
            shrink=0.55,
            pad=0.08,
            label="first self-stress (normalised) [-]\nred tension, blue compression",
        )
    head = f"{dg.get('scene', '')}: {dg.get('classification', '')}"
    if dg.get("stroke") is not None:
        head += f" (at stroke {dg['stroke']:.4g})"
    fig.suptitle("\n".join(textwrap.wrap(head, 100)), fontsize=9)
    y = 0.01
    for color, text in reversed(legend):
        wrapped = textwrap.wrap(text, 120)
        fig.text(0.02, y, "\n".join(wrapped), fontsize=7, color=color, va="bottom")
        y += 0.022 * len(wrapped) + 0.005
    fig.text(
        0.02,
        0.9,
        "supports: green triangles; lengths in mm; free-motion translations in L_c = "
        f"{Lc * 1e3:.3g} mm per unit, rotations in rad per unit",
        fontsize=7,
        va="top",
    )
    fig.subplots_adjust(left=0.0, right=0.95, bottom=min(0.05 + y, 0.4), top=0.88)
    return fig


def pareto_figure(result: Any) -> Figure:
    """The front of a ``flexopt-pareto-result`` (optim/pareto.py): verified worst-case first parasitic frequency
    against drive stiffness, a stiffer drive to the right; the two single-objective optima marked, each point
    labelled with its design, the NSGA-II check's verified points (if it ran) as grey crosses."""
    d = _data(result)
    fig = Figure(figsize=(6.4, 4.4))
    ax = fig.add_subplot(1, 1, 1)
    key = d.get("against", "drive_stiffness")  # the second objective: drive stiffness or stroke
    pts = sorted(d.get("points", []), key=lambda p: p[key])
    unit = d.get("drive_stiffness_unit", "") if key == "drive_stiffness" else d.get("stroke_unit", "")
    chk = d.get("check") or {}
    if chk.get("points"):
        ax.plot(
            [q["drive_stiffness"] for q in chk["points"]],
            [q["worst_hz"] for q in chk["points"]],
            "x",
            color="0.6",
            label=f"NSGA-II check ({chk.get('evaluations', 0)} curves): {'passed' if chk.get('passed') else 'FAILED'}",
        )
    if pts:
        ax.plot(
            [p[key] for p in pts],
            [p["worst_hz"] for p in pts],
            "o-",
            color=PARASITIC_COLOR,
            label="epsilon-constraint front (verified)",
        )
        for p in pts:
            text = ", ".join(f"{k}={v:.4g}" for k, v in (p.get("design") or {}).items())  # SI, as the spec
            ax.annotate(text, (p[key], p["worst_hz"]), fontsize=6, xytext=(4, -10), textcoords="offset points")
        for key, label in (("max_frequency", "max frequency"), ("min_drive_stiffness", "min drive stiffness")):
            e = d.get(key) or {}
            if e.get("status") == "optimal" and key == "drive_stiffness":
                ax.plot([e["drive_stiffness"]], [e["worst_hz"]], "s", mfc="none", mec="k", ms=10, label=label)
    ax.set_xlabel(
        f"drive stiffness (peak drive / stroke) [{unit}]"
        if key == "drive_stiffness"
        else f"stroke (half range) [{unit}]"
    )
    ax.set_ylabel("worst-case first parasitic frequency [Hz]")
    ax.set_title(f"{d.get('template', '')}: Pareto front", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower right")
    lines = [f"{w['kind']}: {w['message']}" for w in d.get("warnings", [])]
    if lines:
        ax.text(
            0.01,
            0.99,
            "\n".join(textwrap.shorten(x, 110) for x in lines[:4]),
            transform=ax.transAxes,
            fontsize=6,
            va="top",
            bbox={"fc": "#fff3cd", "ec": "#c9a227"},
        )
    fig.tight_layout()
    return fig
