"""Cost of a synchronous frequency curve against model size: the data behind ``service.api.guards.seconds_per_point``.

The leaf-spring template meshed with 10 to 320 segments, exact method, 5 stroke points, one process (kernels
compiled once, before the timed runs). Prints a markdown table: DOFs, measured seconds per point, and the
service's estimate. Not a test.

Usage::

    python bench/bench_request_cost.py
"""

from __future__ import annotations

import time

from flexopt.model import Analysis, template
from flexopt.model.structure import compile_scene
from flexopt.service.api.guards import seconds_per_point


def main() -> None:
    Analysis(template("leaf-spring", points=2)).frequency_curve()  # compile the kernels outside the timing
    print("| segments | DOFs | measured [s/point] | estimate [s/point] |\n|---:|---:|---:|---:|")
    for seg in (10, 40, 160, 320):
        scene = template("leaf-spring", segments=seg, points=5)
        n = compile_scene(scene).n_dof
        an = Analysis(scene)
        t = time.perf_counter()
        an.frequency_curve()
        per = (time.perf_counter() - t) / scene.stroke.points
        print(f"| {seg} | {n} | {per:.3f} | {seconds_per_point(n):.3f} |")


if __name__ == "__main__":
    main()
