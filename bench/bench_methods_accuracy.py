"""Where each expansion about stroke 0 holds (fd1, fd2, manifold, reduced), as a markdown table.

For every template at its default stroke grid: the stroke range each method keeps at the tolerance (its own
estimate, :mod:`model.methods.accuracy`: exact check points), the range where its true error against the
exact curve meets the tolerance, the largest true error of the points kept, and how the estimate compares
with the true error at the kept points where the true error exceeds a hundredth of the tolerance (the smallest
ratio estimate / true: below 1 the estimate reads low there).

    python bench/bench_methods_accuracy.py [--tolerances 1e-2,1e-3] [--templates leaf-spring,...]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from _common import HINGES as TEMPLATES  # noqa: E402
from flexopt.model import Analysis, template  # noqa: E402
from flexopt.model.methods import frequency_curve  # noqa: E402
from flexopt.model.methods.accuracy import limit  # noqa: E402
from flexopt.model.methods.auto import expansion_curve  # noqa: E402

FAST = ("fd1", "fd2", "manifold", "reduced")


def held(stroke: np.ndarray, ok: np.ndarray) -> tuple[float, float]:
    """The stroke range (lowest, highest) reached from 0 through points where ``ok`` holds, per side."""
    out = []
    for sign in (-1.0, 1.0):
        idx = np.flatnonzero(np.sign(stroke) == sign)
        idx = idx[np.argsort(np.abs(stroke[idx]))]
        bad = np.flatnonzero(~ok[idx])
        n = bad[0] if len(bad) else len(idx)
        out.append(float(stroke[idx[n - 1]]) if n else 0.0)
    return out[0], out[1]


def rows(name: str, tolerances: list[float]) -> list[str]:
    an = Analysis(template(name))
    values = an.scene.stroke.values()
    exact = frequency_curve(an, "exact", stroke=values)
    unit = exact.stroke_unit
    scale = 1e3 if unit == "m" else 1.0
    u = "mm" if unit == "m" else unit
    out = []
    for m in FAST:
        curve, est = expansion_curve(an, m, values)
        f = curve.parasitic_hz
        true = np.where(np.isfinite(f) & (f > 0), np.abs(f / exact.parasitic_hz - 1), np.inf)
        for tol in tolerances:
            kept = limit(curve, est, tol)
            keep = np.isin(values, kept.stroke)
            lo, hi = held(values, est <= tol)
            tlo, thi = held(values, true <= tol)
            worst = float(true[keep].max())
            big = keep & (true > 0.01 * tol)
            ratio = float(np.min(est[big] / true[big])) if big.any() else float("nan")
            out.append(
                f"| {name} | {m} | {tol:g} | {lo * scale:.3g} .. {hi * scale:.3g} {u} | {tlo * scale:.3g} .. "
                f"{thi * scale:.3g} {u} | {worst:.2e} | {ratio:.2f} | {curve.solver['exact_checks']} |"
            )
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tolerances", default="1e-2,1e-3")
    ap.add_argument("--templates", default=",".join(TEMPLATES))
    a = ap.parse_args()
    tols = [float(x) for x in a.tolerances.split(",")]
    print(
        "| template | method | tolerance | kept (own estimate) | true error within tolerance | largest true error "
        "kept | min estimate / true | exact checks |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for name in a.templates.split(","):
        for r in rows(name, tols):
            print(r, flush=True)


if __name__ == "__main__":
    main()
