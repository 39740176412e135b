"""Pictures of the topology search's winners beside the hand-made families (issue 30), for the docs page
Optimisation and topology search: each design at its optimum, drawn at -stroke, 0 and +stroke (the deflected
equilibria of the exact curve on the refined mesh the ranking used, leaves as plates of their real width, each
stage its own colour), each panel titled with its first parasitic frequency, the figure with the design's worst
case over the stroke; the clamped leaf ends (the scene's supports) are marked as ground and a 10 mm x, y, z
triad of the scene's axes stands at the origin (z the rotation axis).

The designs come from search results (``flexopt topology SPEC.json --json``'s answer, or
``run_topology_search``'s dict): the default search's top ``--top`` (3) and the four hand-made families
(``optim.topology.FAMILIES``) optimised under the identical problem (the default spec with their own shared
dimensions, as ``bench/bench_topology.py`` runs them). The families' search is run here when
``--families`` names no existing file (a few minutes; the answer is written there for the next run).

Run from the repository root::

    OPENBLAS_NUM_THREADS=1 python docs/draw_topology.py --result DEFAULT.json --families FAMILIES.json \
        [--out docs/pages/images] [--workers 2] [--store DIR]

Writes ``topology_rank<k>.png`` and ``topology_family_<name>.png`` (each below 150 kB) and prints one line per
picture with its figures (the worst case is the search's refined one, else its verified one).
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from flexopt.model.curve import Analysis  # noqa: E402
from flexopt.model.scene import Scene  # noqa: E402
from flexopt.model.shapes import shapes_along  # noqa: E402
from flexopt.optim.topology import FAMILIES, run_topology_search  # noqa: E402
from flexopt.optim.topology.spec import TopologySpec  # noqa: E402
from flexopt.service.plots import save, stroke_figure  # noqa: E402

LIMIT = 150_000  # bytes per picture (the docs' budget)
AXES = 0.01  # the length of the x, y, z triad [m]


def _figures(c: dict) -> tuple[float, float, str]:
    """Worst case, zero-stroke frequency and which verification they are from."""
    ref = c.get("refined") or {}
    if ref.get("worst_hz") is not None:
        segs = max(ref.get("segments_used") or [0])
        return ref["worst_hz"], ref["zero_stroke_hz"], f"refined, {segs} segments per leaf"
    return c["worst_case_hz"], c["zero_stroke_hz"], "on the search's mesh"


def draw(c: dict, stroke: float, label: str, path: Path) -> str:
    scene_dict = json.loads(json.dumps(c["scene"]))
    segs = max((c.get("refined") or {}).get("segments_used") or [0])
    for el in scene_dict["elements"] if segs else []:  # on the refined mesh, as the worst case in the title
        if el.get("kind") == "beam":
            el["segments"] = segs
    scene = Scene.model_validate(scene_dict)
    shapes = shapes_along(Analysis(scene), [-stroke, 0.0, stroke])
    worst, zero, where = _figures(c)
    title = (
        f"{label} {c['topology']}: worst case {worst:.2f} Hz over +-{stroke:g} deg ({where}), "
        f"{zero:.2f} Hz at 0 ({worst / zero:.0%} kept)"
    )
    nodes_of = {b["name"]: b["nodes"] for b in scene_dict.get("bodies", [])}
    ground = [  # the clamped leaf ends: a supported node, or every node of a supported body
        n for sp in scene_dict.get("supports", []) for n in ([sp["node"]] if sp.get("node") else nodes_of[sp["body"]])
    ]
    fig = stroke_figure(shapes, title, bodies=False, ground=ground, axes=AXES)
    for dpi in (80, 70, 60):  # the smallest reduction that keeps the picture within its budget
        save(fig, str(path), dpi=dpi)
        if path.stat().st_size < LIMIT:
            break
    else:
        raise SystemExit(f"{path}: {path.stat().st_size} bytes even at 60 dpi (budget {LIMIT})")
    return f"{path.name}: {title} [{path.stat().st_size // 1000} kB]"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--result", required=True, help="the default search's result JSON")
    ap.add_argument("--families", required=True, help="the families' result JSON (run here and written if absent)")
    ap.add_argument("--out", default="docs/pages/images")
    ap.add_argument("--top", type=int, default=3)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--store", default=None, help="case store for the families' search (a rerun reuses it)")
    a = ap.parse_args()
    res = json.loads(Path(a.result).read_text())
    res = res.get("default", res)
    fam_path = Path(a.families)
    if fam_path.exists():
        fams = json.loads(fam_path.read_text())
        fams = fams.get("families", fams)
    else:
        spec = TopologySpec.model_validate(res["spec"]).model_dump(mode="json")
        fams = run_topology_search(
            {**spec, "topologies": sorted(FAMILIES.values()), "dimensions": "shared"},
            workers=a.workers,
            store=a.store,
        )
        fam_path.write_text(json.dumps(fams))
    stroke = float(res["spec"]["stroke"])
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    by = {c["topology"]: c for c in res["candidates"]}
    for k, name in enumerate(res["ranking"][: a.top], start=1):
        print(draw(by[name], stroke, f"rank {k}:", out / f"topology_rank{k}.png"), flush=True)
    fby = {c["family"]: c for c in fams["candidates"] if c.get("family") and c["status"] == "optimised"}
    for name in FAMILIES:
        if name not in fby:
            print(f"{name}: not optimised in the families' result ({fams['counts']})")
            continue
        print(draw(fby[name], stroke, f"{name}", out / f"topology_family_{name}.png"), flush=True)


if __name__ == "__main__":
    main()
