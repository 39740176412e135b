"""``flexopt diagnose``: exact-constraint diagnosis of a scene (D_cc, its SVD, Table 1 of seed 002).

Registered by service.cli through :func:`add_parser`; imports the model lazily.
"""

from __future__ import annotations

import argparse
import json
from typing import Any

__all__ = ["add_parser", "plot_diagnosis"]


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add the ``diagnose`` subcommand to an argparse subparsers object."""
    d = subparsers.add_parser("diagnose", help="exact-constraint diagnosis: D_cc rank, free motions, self-stresses")
    from .cli import add_scene_arguments

    add_scene_arguments(d)
    d.add_argument("--at-stroke", type=float, default=None, metavar="VALUE",
                   help="diagnose the equilibrium at this stroke value (stroke unit); default: the reference")
    d.add_argument("--kinematic", dest="kinematic", action="store_true", default=None,
                   help="kinematic idealisation (flexures keep only compliant deformations)")
    d.add_argument("--declared", dest="kinematic", action="store_false",
                   help="use the scene's declared rigid deformations, not the kinematic idealisation")
    d.add_argument("--json", action="store_true", help="print a JSON object")
    d.add_argument("--plot", metavar="FILE.png", help="draw the structure, free motions and self-stresses")
    d.set_defaults(func=_cmd_diagnose)
    return d


def _cmd_diagnose(args: argparse.Namespace) -> int:
    import sys

    from ..model.constraints import diagnose
    from .cli import scene_from_args

    scene = scene_from_args(args)
    diag = diagnose(scene, at_stroke=args.at_stroke, kinematic=args.kinematic)
    if args.json:
        print(json.dumps(diag.to_dict(), indent=2))
    else:
        print(diag.report())
    if args.plot:
        plot_diagnosis(scene, diag, args.plot)
        print(f"plot written to {args.plot}", file=sys.stderr)
    return 0


def plot_diagnosis(scene: Any, diag: Any, path: str) -> None:
    """Draw the structure (reference geometry), each kinematic mode as arrows at the moving masters and
    the first self-stress as element colours (red tension, blue compression), as Figure 2 of seed 002."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from ..model.structure import compile_scene

    s = compile_scene(scene)
    pos = {n.name: np.array(n.position, dtype=float) for n in scene.nodes}
    stress: dict[str, float] = {}
    if diag.static_modes:
        for el, comps in diag.static_modes[0].items():
            member = el.split("[")[0]
            val = max(comps.values(), key=abs)
            if abs(val) > abs(stress.get(member, 0.0)):
                stress[member] = val
    smax = max((abs(v) for v in stress.values()), default=1.0) or 1.0
    cmap = plt.get_cmap("coolwarm")
    fig = plt.figure(figsize=(7, 6))
    ax = fig.add_subplot(projection="3d")
    for e in scene.elements:
        p, q = pos[e.nodes[0]], pos[e.nodes[1]]
        if e.name in stress:
            color, lw = cmap(0.5 + 0.5 * stress[e.name] / smax), 3.0
        else:
            color, lw = "0.4", 1.5
        ax.plot(*zip(p, q), color=color, lw=lw)
    for b in scene.bodies:
        pts = np.array([pos[n] for n in b.nodes] + [b.center_of_mass])
        ax.scatter(*pts.T, color="k", s=8)
    sup = [pos[x.node] for x in scene.supports if x.node is not None and x.node in pos]
    if sup:
        ax.scatter(*np.array(sup).T, marker="^", color="C2", s=40, label="supports")
    Lc = diag.characteristic_length
    master_pos = dict(zip(s.master_names, s.master_pos))
    for i, mode in enumerate(diag.kinematic_modes[:4]):
        for name, vel in mode.items():
            v = np.array(vel["translation"])
            if np.linalg.norm(v) > 1e-9:
                ax.quiver(*master_pos[name], *(0.3 * Lc * v), color=f"C{i + 3}", lw=2,
                          label=f"kinematic mode {i + 1}")
    handles, labels = ax.get_legend_handles_labels()
    uniq = dict(zip(labels, handles))
    if uniq:
        ax.legend(uniq.values(), uniq.keys(), loc="upper left", fontsize=8)
    ax.set_title(f"{diag.scene}: {diag.classification}", fontsize=9)
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    ax.set_zlabel("z")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
