"""``flexopt modes``: the deflected structure and the mode shapes at a stroke value (plots, GIF, VTK export).

Registered by service.cli.main through :func:`add_parser`; imports the model lazily.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

__all__ = ["add_parser", "write_vtk"]


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add the ``modes`` subcommand to an argparse subparsers object."""
    from .scene_args import add_scene_arguments

    d = subparsers.add_parser("modes", help="deflected structure and mode shapes at a stroke value")
    add_scene_arguments(d)
    d.add_argument(
        "--at-stroke", type=float, default=0.0, metavar="S", help="stroke value in the scene's stroke unit (default 0)"
    )
    d.add_argument("--json", action="store_true", help="print the shapes as a JSON object")
    d.add_argument(
        "--mode",
        type=int,
        default=None,
        metavar="K",
        help="mode drawn by --plot/--animate (1-based; default: the first parasitic mode)",
    )
    d.add_argument("--plot", metavar="FILE.png", help="draw the deflected structure with the mode overlaid")
    d.add_argument("--animate", metavar="FILE.gif", help="write the mode oscillating about the deflected state")
    d.add_argument(
        "--vtk",
        metavar="DIR",
        help="write the deflected structure at every stroke point of the scene's "
        "grid, mode shapes as point data (VTU files and a ParaView .pvd series)",
    )
    d.set_defaults(func=_cmd_modes)
    return d


def _scene(args: argparse.Namespace) -> Any:
    from .scene_args import scene_from_args

    if args.scene is None and args.template is None:
        raise ValueError("give a scene file or --template NAME (one of them)")
    return scene_from_args(args)


def _table(d: dict) -> str:
    import numpy as np

    unit = "N m" if d["stroke_kind"] == "rotation" else "N"
    reaction = "not computed" if d["drive_reaction"] is None else f"{d['drive_reaction']:.4g} {unit}"
    lines = [
        f"scene '{d['scene']}' at stroke {d['stroke']:.6g} {d['stroke_unit']} (drive reaction {reaction}); "
        "modes by frequency, numbered as --mode takes them",
        f"{'mode':>4} {'Hz':>11} {'label':>10}  dominant motion (share of the squared nodal rotations/translations)",
    ]
    pts = np.array(list(d["nodes"].values()))
    size = float(np.ptp(pts, axis=0).max())
    by_frequency = sorted(range(len(d["modes"])), key=lambda i: (d["modes"][i]["hz"] is None, d["modes"][i]["hz"]))
    for i in by_frequency:
        m = d["modes"][i]
        rot = np.array(list(m["rotation"].values()))
        tra = np.array(list(m["translation"].values()))
        r2, t2 = (rot**2).sum(axis=0), (tra**2).sum(axis=0)
        k, j = int(np.argmax(r2)), int(np.argmax(t2))
        parts = []
        if np.abs(rot).max() > 0:
            parts.append(f"rotation about {'xyz'[k]} {r2[k] / r2.sum():.0%}")
        # translations below 1e-6 of what the rotations move across the structure are round-off
        if np.abs(tra).max() > 1e-6 * size * np.abs(rot).max():
            parts.append(f"translation along {'xyz'[j]} {t2[j] / t2.sum():.0%}")
        else:
            parts.append("nodes do not translate")
        hz = "-" if m["hz"] is None else f"{m['hz']:.4f}"
        lines.append(f"{i + 1:>4} {hz:>11} {m['label']:>10}  " + ", ".join(parts))
    for name, s in d["stress"].items():
        if s["von_mises"] is not None:
            lines.append(f"stress {name}: {s['von_mises'] / 1e6:.4g} MPa = {s['utilisation']:.3g} of the allowable")
    for w in d["warnings"]:
        lines.append(f"warning [{w['kind']}]: {w['message']}")
    return "\n".join(lines)


def _default_mode(d: dict, mode: int | None) -> int:
    if mode is not None:
        if not 1 <= mode <= len(d["modes"]):
            raise ValueError(f"--mode {mode} is out of range; give 1 to {len(d['modes'])}")
        return mode - 1
    par = [i for i, m in enumerate(d["modes"]) if m["label"] == "parasitic"]
    if not par:
        return 0
    return min(par, key=lambda i: d["modes"][i]["hz"])


def write_vtk(shapes: list[dict], directory: str) -> list[str]:
    """One VTU file per stroke point (meshio): the deflected structure as lines (members) and quads (plates of
    rectangular members), point data ``mode_K_translation`` / ``mode_K_rotation`` (per unit modal
    coordinate) and ``mode_K_hz`` (constant); plus ``series.pvd`` indexing the files by stroke for ParaView.
    Returns the paths written."""
    import os

    import meshio
    import numpy as np
    from scipy.spatial.transform import Rotation

    os.makedirs(directory, exist_ok=True)
    paths = []
    entries = []
    for k, d in enumerate(shapes):
        names = list(d["nodes"])
        index = {n: i for i, n in enumerate(names)}
        P = np.array([d["nodes"][n] for n in names], dtype=float)
        R = Rotation.from_rotvec(np.array([d["orientations"][n] for n in names], dtype=float)).as_matrix()
        lines, quads = [], []
        extra: list[np.ndarray] = []  # plate edge points, appended after the nodes
        edge_of: list[int] = []  # node index each extra point belongs to
        for mb in d["members"].values():
            chain = [index[n] for n in mb["nodes"]]
            lines += [[a, b] for a, b in zip(chain[:-1], chain[1:])]
            if mb.get("width") and mb.get("y_axis") is not None:
                y0 = np.asarray(mb["y_axis"], dtype=float) * mb["width"] / 2
                base = len(P) + len(extra)
                for i in chain:
                    extra += [P[i] - R[i] @ y0, P[i] + R[i] @ y0]
                    edge_of += [i, i]
                quads += [
                    [base + 2 * j, base + 2 * j + 2, base + 2 * j + 3, base + 2 * j + 1] for j in range(len(chain) - 1)
                ]
        pts = np.vstack([P, *extra]) if extra else P
        owner = np.concatenate([np.arange(len(P)), np.array(edge_of, dtype=int)])
        point_data = {}
        for j, m in enumerate(d["modes"]):
            u = np.array([m["translation"][n] for n in names], dtype=float)
            psi = np.array([m["rotation"][n] for n in names], dtype=float)
            arm = pts - P[owner]  # plate edge points move with their node: u + psi x r
            point_data[f"mode_{j + 1}_translation"] = u[owner] + np.cross(psi[owner], arm)
            point_data[f"mode_{j + 1}_rotation"] = psi[owner]
            # meshio's VTU writer drops field data: the frequency travels as a constant point array
            point_data[f"mode_{j + 1}_hz"] = np.full(len(pts), np.nan if m["hz"] is None else m["hz"])
        cells = [("line", np.array(lines, dtype=int).reshape(-1, 2))]
        if quads:
            cells.append(("quad", np.array(quads, dtype=int)))
        path = os.path.join(directory, f"stroke_{k:04d}.vtu")
        meshio.write(path, meshio.Mesh(pts, cells, point_data=point_data))
        paths.append(path)
        entries.append(f'    <DataSet timestep="{d["stroke"]:.10g}" file="{os.path.basename(path)}"/>')
    pvd = os.path.join(directory, "series.pvd")
    with open(pvd, "w") as fh:
        fh.write(
            '<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n  <Collection>\n'
            + "\n".join(entries)
            + "\n  </Collection>\n</VTKFile>\n"
        )
    return [*paths, pvd]


def _cmd_modes(args: argparse.Namespace) -> int:
    from ...model import Analysis
    from ...model.shapes import shapes_along, shapes_at
    from .. import plots

    scene = _scene(args)
    an = Analysis(scene)
    d = shapes_at(an, args.at_stroke).to_dict()
    print(json.dumps(d, indent=2) if args.json else _table(d))
    if args.plot or args.animate:
        k = _default_mode(d, args.mode)
        if args.plot:
            plots.save(plots.shapes_figure(d, k), args.plot)
            print(f"plot written to {args.plot}", file=sys.stderr)
        if args.animate:
            plots.animate_mode(d, k, args.animate)
            print(f"animation written to {args.animate}", file=sys.stderr)
    if args.vtk:
        series = [s.to_dict() for s in shapes_along(an, scene.stroke.values(), strict=False)]
        files = write_vtk(series, args.vtk)
        print(f"{len(files) - 1} VTU files and {files[-1]} written", file=sys.stderr)
    return 0
