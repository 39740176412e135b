"""How honest each curve's ``mesh_error`` is: the estimate against the true error from a converged mesh.

For each case (template, mesh, method) prints the curve's ``mesh_error``, whether the ``mesh`` warning fired,
and the true error: the largest relative difference of ``parasitic_hz`` from a converged mesh (``REF``
segments per member, O(h^2) error 1/16 or less of the cases' 8-segment one) over 13 stroke points spanning
the stroke (both ends included). Issue 26, item 3 (bullets 2-3) and item 4.

    OPENBLAS_NUM_THREADS=1 python bench/bench_mesh_estimate.py [case-name ...]
"""

from __future__ import annotations

import os
import sys
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from flexopt.model import Analysis, template  # noqa: E402
from flexopt.model.curve import curve_with_method  # noqa: E402

#: Converged reference mesh: segments per member (the cartwheel's template halves ``segments`` per half leaf).
REF = {"cartwheel-hinge": 128, "folded-sheet-guide-5": 32, "folded-sheet-guide-6": 32, "wire-guide-5": 32,
       "wire-guide-parallel": 32}
REF_DEFAULT = 64

#: (label, template, overrides or None for the template's default mesh, method)
CASES = [
    ("folded-sheet-guide-5 default", "folded-sheet-guide-5", {}, "exact"),
    ("wire-guide-5 default", "wire-guide-5", {}, "exact"),
    ("cartwheel 1 segment", "cartwheel-hinge", {"segments": 2}, "exact"),
    ("double cross 2 segments", "double-cross-hinge", {"segments": 2}, "exact"),
    ("cartwheel default, auto", "cartwheel-hinge", {}, "auto"),
    ("cartwheel default, hermite", "cartwheel-hinge", {}, "hermite"),
    ("cartwheel default", "cartwheel-hinge", {}, "exact"),
    ("cross-spring-pivot default", "cross-spring-pivot", {}, "exact"),
    ("three-fold default", "three-fold-cross-hinge", {}, "exact"),
    ("double cross default", "double-cross-hinge", {}, "exact"),
    ("leaf-spring default", "leaf-spring", {}, "exact"),
    ("parallel-leaf-spring default", "parallel-leaf-spring", {}, "exact"),
]

_REF_CACHE: dict[str, tuple[np.ndarray, np.ndarray]] = {}


def _grid(name: str) -> np.ndarray:
    v = np.asarray(template(name).stroke.values(), dtype=float)
    return np.linspace(v.min(), v.max(), 13)


def converged(name: str) -> tuple[np.ndarray, np.ndarray]:
    if name not in _REF_CACHE:
        c = Analysis(template(name, segments=REF.get(name, REF_DEFAULT))).frequency_curve(_grid(name), mesh_error=False)
        _REF_CACHE[name] = (c.stroke, c.parasitic_hz)
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
        print(f"{label:32s} {','.join(map(str, segs)):>8s} {method:>8s} {me:>10s} {str(warned):>7s} "
              f"{100 * true:7.3g} % {sec:6.1f}", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
