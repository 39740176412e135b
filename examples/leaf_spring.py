"""A worked example on the seed leaf spring: frequency curve, mode shapes, exact-constraint diagnosis and a
small optimisation, with the figures a designer looks at. Run: ``python examples/leaf_spring.py [OUTDIR]``.

Everything here is public API: ``flexopt.model`` (analysis), ``flexopt.optim`` (optimisation) and
``flexopt.service.plots`` (figures from the results' JSON-ready dicts).
"""

from __future__ import annotations

import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from flexopt.model import Analysis, diagnose, template
from flexopt.model.shapes import shapes_at
from flexopt.optim import optimise
from flexopt.service import plots


def main(outdir: str = "leaf_spring_out") -> dict:
    """Run the example, write its figures to ``outdir`` and return the key numbers."""
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    scene = template("leaf-spring", points=19)  # L 100 mm, w 40 mm, t 0.5 mm steel, +-45 deg end rotation
    scene_json = scene.model_dump(mode="json")

    # 1. natural frequencies over the stroke (exact: continuation + eigen analysis at every point)
    analysis = Analysis(scene)
    curve = analysis.frequency_curve()
    plots.save(plots.curve_figure(curve, scene_json), str(out / "curve.png"))
    worst = float(curve.parasitic_hz.min())
    print(
        f"first parasitic: {curve.parasitic_hz[len(curve.stroke) // 2]:.1f} Hz at stroke 0, "
        f"worst {worst:.1f} Hz over +-45 deg"
    )

    # 2. the mode shapes at stroke 0 and at the end of the stroke
    at0 = shapes_at(analysis, 0.0).to_dict()
    parasitic = [i for i, m in enumerate(at0["modes"]) if m["label"] == "parasitic"]
    first = min(parasitic, key=lambda i: at0["modes"][i]["hz"])
    plots.save(plots.shapes_figure(at0, first), str(out / "mode_stroke0.png"))
    plots.animate_mode(at0, first, str(out / "mode_stroke0.gif"), frames=12)
    at45 = shapes_at(analysis, 45.0).to_dict()
    plots.save(plots.shapes_figure(at45, first), str(out / "mode_stroke45.png"))
    for i, m in enumerate(at0["modes"]):
        print(f"  mode {i + 1}: {m['hz']:8.2f} Hz  {m['label']}")

    # 3. exact-constraint diagnosis (seed 002), kinematic idealisation: a sheet keeps elongation and in-plane
    #    bending rigid, so it constrains three of the tip's six coordinates; one element (segments=1) so that
    #    the diagnosis is about the tip, not the mesh's internal nodes
    one = template("leaf-spring", segments=1)
    diag = diagnose(one, kinematic=True)
    plots.save(plots.diagnosis_figure(one.model_dump(mode="json"), diag.to_dict()), str(out / "diagnosis.png"))
    print(f"diagnosis: {diag.classification}")

    # 4. a small optimisation: thickness and width that maximise the worst-case first parasitic frequency,
    #    stress within the allowable (safety factor 1.5) over +-20 deg
    problem = {
        "families": [{"template": "leaf-spring", "design": {"thickness": [3e-4, 8e-4], "width": [0.02, 0.05]}}],
        "stroke": 20.0,
        "samples": 5,
        "modes": 1,
        "starts": 1,
        "max_iterations": 6,
        "refine_rounds": 0,
        "verify_points": 31,
    }
    with ThreadPoolExecutor(1) as pool:
        result = optimise(problem, executor=pool)
    best = result["ranking"][0] if result["ranking"] else None
    if best is not None:
        print(
            f"optimised: worst first parasitic {best['worst_hz']:.1f} Hz with "
            + ", ".join(f"{k} {v * 1e3:.3g} mm" for k, v in best["design"].items())
        )
    return {"curve": curve, "shapes0": at0, "first_parasitic": first, "diagnosis": diag, "optimisation": result}


if __name__ == "__main__":
    main(*sys.argv[1:2])
