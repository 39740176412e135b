"""How honest each curve's ``mesh_error`` is: the estimate against the true error from a converged mesh.

For each case (template, mesh, method) prints the curve's ``mesh_error``, whether the ``mesh`` warning fired,
and the true error: the largest relative difference of ``parasitic_hz`` from the converged value (``REF``:
Richardson's extrapolation of two fine meshes) over 13 stroke points spanning the stroke (both ends
included). Issue 26, item 3 (bullets 2-3) and item 4.

    OPENBLAS_NUM_THREADS=1 python bench/bench_mesh_estimate.py [case-name ...]
    OPENBLAS_NUM_THREADS=1 python bench/bench_mesh_estimate.py --cost [template ...]

``--cost``: what the exact mesh's estimate adds to a fast method's curve (``auto`` at 1 %, the templates'
default meshes and 91 points): the method alone (``model.methods.frequency_curve``) against the curve with
its estimate (``model.curve.curve_with_method``), interleaved, medians of 5 runs on one warm analysis each.
"""

from __future__ import annotations

import os
import sys
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from _common import DEFAULT_TEMPLATES, interleave  # noqa: E402
from flexopt.model import Analysis, template  # noqa: E402
from flexopt.model.curve import curve_with_method  # noqa: E402

#: Converged reference: Richardson's extrapolation (order 2) of two fine meshes (segments per member; the
#: cartwheel's template puts segments // 2 on each half leaf), whose own error is O(h^2) of theirs.
REF = {
    "cartwheel-hinge": (48, 96),
    "folded-sheet-guide-5": (16, 32),
    "folded-sheet-guide-6": (16, 32),
    "wire-guide-5": (16, 32),
    "wire-guide-parallel": (16, 32),
}
REF_DEFAULT = (32, 64)

#: (label, template, overrides (empty: the template's default mesh), method). The first six: issue 26 item 3's
#: cases at the meshes it names (the former defaults); then every template's default mesh (item 4).
CASES = (
    [
        ("folded-sheet-guide-5 1 segment", "folded-sheet-guide-5", {"segments": 1}, "exact"),
        ("wire-guide-5 1 segment", "wire-guide-5", {"segments": 1}, "exact"),
        ("cartwheel 1 segment", "cartwheel-hinge", {"segments": 2}, "exact"),
        ("double cross 2 segments", "double-cross-hinge", {"segments": 2}, "exact"),
        ("cartwheel 4 per half leaf, auto", "cartwheel-hinge", {"segments": 8}, "auto"),
        ("cartwheel 4 per half leaf, hermite", "cartwheel-hinge", {"segments": 8}, "hermite"),
        ("cartwheel 4 per half leaf", "cartwheel-hinge", {"segments": 8}, "exact"),
    ]
    + [(f"{name} default", name, {}, "exact") for name in DEFAULT_TEMPLATES]
    + [("cartwheel default, auto", "cartwheel-hinge", {}, "auto")]
)


_REF_CACHE: dict[str, tuple[np.ndarray, np.ndarray]] = {}


def _grid(name: str) -> np.ndarray:
    v = np.asarray(template(name).stroke.values(), dtype=float)
    return np.linspace(v.min(), v.max(), 13)


def converged(name: str) -> tuple[np.ndarray, np.ndarray]:
    if name not in _REF_CACHE:
        n1, n2 = REF.get(name, REF_DEFAULT)
        c1, c2 = (Analysis(template(name, segments=n)).frequency_curve(_grid(name), mesh_error=False) for n in (n1, n2))
        _REF_CACHE[name] = (c2.stroke, c2.parasitic_hz + (c2.parasitic_hz - c1.parasitic_hz) / ((n2 / n1) ** 2 - 1))
    return _REF_CACHE[name]


def main(names: list[str]) -> None:
    print(f"{'case':32s} {'segments':>8s} {'method':>8s} {'mesh_error':>10s} {'warning':>7s} {'true':>8s} {'s':>6s}")
    for label, name, over, method in CASES:
        if names and not any(n in label for n in names):
            continue
        sc = template(name, **over)
        t0 = time.perf_counter()
        an = Analysis(sc)
        c = an.frequency_curve() if method == "exact" else curve_with_method(an, method, 0.01)
        sec = time.perf_counter() - t0
        ref_s, ref_f = converged(name)
        idx = [int(np.argmin(np.abs(c.stroke - s))) for s in ref_s]
        ok = np.abs(c.stroke[idx] - ref_s) <= 1e-9 * max(1.0, float(np.abs(ref_s).max()))
        true = float(np.max(np.abs(c.parasitic_hz[idx][ok] / ref_f[ok] - 1.0)))
        segs = sorted({e.segments for e in an.scene.elements if hasattr(e, "segments")})
        warned = any(w.kind == "mesh" for w in c.warnings)
        me = "None" if c.mesh_error is None else f"{100 * c.mesh_error:.3g} %"
        print(
            f"{label:32s} {','.join(map(str, segs)):>8s} {method:>8s} {me:>10s} {str(warned):>7s} "
            f"{100 * true:7.3g} % {sec:6.1f}",
            flush=True,
        )


def cost(names: list[str]) -> None:
    from flexopt.model.methods import frequency_curve as by_method

    names = names or ["cross-spring-pivot", "cartwheel-hinge", "three-fold-cross-hinge", "double-cross-hinge"]
    print(f"load: {os.getloadavg()}")
    print(f"{'template':26s} {'auto alone':>11s} {'with estimate':>14s} {'ratio':>6s}")
    for name in names:
        a, b = Analysis(template(name)), Analysis(template(name))
        by_method(a, "auto", 0.01), curve_with_method(b, "auto", 0.01)  # warm: kernels, second mesh
        t, _ = interleave(
            5, {"alone": lambda a=a: by_method(a, "auto", 0.01), "with": lambda b=b: curve_with_method(b, "auto", 0.01)}
        )
        ma, mb = float(np.median(t["alone"])), float(np.median(t["with"]))
        print(f"{name:26s} {ma:10.2f}s {mb:13.2f}s {mb / ma:6.2f}", flush=True)


if __name__ == "__main__":
    if sys.argv[1:2] == ["--cost"]:
        cost(sys.argv[2:])
    else:
        main(sys.argv[1:])
