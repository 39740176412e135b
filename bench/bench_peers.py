"""Peer benchmark: the seed leaf's 91-point frequency curve in flexopt and in Exudyn, interleaved in one run.

The same work on both sides: a leaf spring (L 0.1, w 0.04, t 0.0005 m, steel) of N beam elements clamped at
one end, its free end rotated about the leaf's weak bending axis from 0 to +45 deg and from 0 to -45 deg in
1-deg steps (91 points), a static equilibrium and an eigen solve with the drive locked at every point.

- flexopt: ``Analysis(template("leaf-spring", segments=N)).frequency_curve()`` (warm: kernels loaded), as
  users call it (the leaf is mirror-symmetric: one side solved and mirrored, plus the mesh-error estimate),
  and with ``mirror=False, mesh_error=False``: both sides solved, no estimate, the same work as Exudyn's.
- Exudyn (BSD-3; ``pip install .[bench]``, never a runtime dependency of flexopt): N
  ``ObjectBeamGeometricallyExact`` elements (shear-flexible, section stiffness diag(EA, kGA, kGA, GJ, EI_y,
  EI_z), k = 5/6), ``NodeRigidBodyRxyz`` nodes, the root clamped by six coordinate constraints and the tip's
  *Tait-Bryan angle* about y prescribed by a coordinate constraint; ``SolveStatic`` (dense solver, relative
  tolerance 1e-8, absolute 1e-8: 1e-10 is not reached at 40 elements; continuing from the previous point)
  and ``ComputeODE2Eigenvalues`` (dense, constraints eliminated) at each point.

The drive locks differ: flexopt locks the incremental spin about the fixed drive axis (PHYSICS.md); Exudyn
locks a Tait-Bryan angle, i.e. another tangent direction at large stroke, which reads the leaf's torsion
frequency about 4.7 % higher at 45 deg. The table prints both frequencies at 0 and 45 deg so the difference
is visible; timings compare the same amount of work, not the same numbers.

Each repetition times flexopt then Exudyn (A B A B ...), so a drift of the machine's speed affects both;
the table gives medians, the ratio of the medians and the median of the per-pair ratios.

    python bench/bench_peers.py [--repeat 11] [--segments 10 40]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

L, W, T, E, G, RHO = 0.1, 0.04, 0.5e-3, 210e9, 79e9, 7800.0


class ExudynLeaf:
    """The leaf in Exudyn: build once, then :meth:`curve` solves the 91 points."""

    def __init__(self, segments: int) -> None:
        import exudyn as exu
        from exudyn.itemInterface import (
            CoordinateConstraint,
            MarkerNodeCoordinate,
            NodePointGround,
            NodeRigidBodyRxyz,
            ObjectBeamGeometricallyExact,
        )

        self.exu = exu
        A, Iy, Iz = W * T, W * T**3 / 12, T * W**3 / 12
        J = W * T**3 / 3 * (1 - 0.63 * T / W * (1 - T**4 / (12 * W**4)))  # the same series as flexopt's
        sc = exu.SystemContainer()
        mbs = sc.AddSystem()
        nodes = [
            mbs.AddNode(NodeRigidBodyRxyz(referenceCoordinates=[i * L / segments, 0, 0, 0, 0, 0]))
            for i in range(segments + 1)
        ]
        sec = exu.BeamSection()
        sec.stiffnessMatrix = np.diag([E * A, G * A * 5 / 6, G * A * 5 / 6, G * J, E * Iy, E * Iz])
        sec.massPerLength = RHO * A
        sec.inertia = RHO * np.diag([Iy + Iz, Iy, Iz])
        for i in range(segments):
            mbs.AddObject(
                ObjectBeamGeometricallyExact(nodeNumbers=[nodes[i], nodes[i + 1]], length=L / segments, sectionData=sec)
            )
        ground = mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=mbs.AddNode(NodePointGround()), coordinate=0))
        for c in range(6):
            m = mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=nodes[0], coordinate=c))
            mbs.AddObject(CoordinateConstraint(markerNumbers=[ground, m]))
        tip = mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=nodes[-1], coordinate=4))  # Tait-Bryan angle about y
        self.drive = mbs.AddObject(CoordinateConstraint(markerNumbers=[ground, tip], offset=0.0))
        mbs.Assemble()
        ss = exu.SimulationSettings()
        ss.staticSolver.newton.relativeTolerance = 1e-8  # 1e-10 is not reached at 40 elements
        ss.staticSolver.newton.absoluteTolerance = 1e-8
        ss.staticSolver.numberOfLoadSteps = 1
        ss.staticSolver.verboseMode = 0
        ss.solutionSettings.writeSolutionToFile = False  # Exudyn writes solution/ into the cwd by default
        ss.linearSolver.solverType = exu.LinearSolverType.EXUdense
        self.mbs, self.ss = mbs, ss
        self.state0 = mbs.systemData.GetSystemState(exu.ConfigurationType.Initial)

    def curve(self) -> dict[float, np.ndarray]:
        """Frequencies [Hz] (eight lowest, drive locked) at -45..45 deg in 1-deg steps, walking out from 0."""
        exu, mbs, ss = self.exu, self.mbs, self.ss
        out = {}
        for k, side in enumerate((np.arange(0, 46.0), -np.arange(1, 46.0))):
            mbs.systemData.SetSystemState(self.state0 if k == 0 else self.at0, exu.ConfigurationType.Initial)
            for deg in side:
                mbs.SetObjectParameter(self.drive, "offset", float(np.radians(deg)))
                if not mbs.SolveStatic(ss, updateInitialValues=True):
                    raise RuntimeError(f"Exudyn's static solver failed at {deg} deg")
                out[float(deg)] = np.asarray(mbs.ComputeODE2Eigenvalues(ss, convert2Frequencies=True)[0][:8])
                if deg == 0:
                    self.at0 = mbs.systemData.GetSystemState(exu.ConfigurationType.Current)
        return out


def main(argv: list[str] | None = None) -> int:
    """Run both interleaved and print one markdown table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=11, help="interleaved repetitions (medians reported)")
    ap.add_argument("--segments", type=int, nargs="+", default=[10, 40])
    args = ap.parse_args(argv)
    try:
        import exudyn
    except ImportError:
        print("Exudyn is not installed: pip install '.[bench]' (or pip install exudyn)", file=sys.stderr)
        return 2
    from flexopt.model import Analysis, template

    rows = []
    for n in args.segments:
        an = Analysis(template("leaf-spring", segments=n))
        ex = ExudynLeaf(n)
        fc, xc = an.frequency_curve(), ex.curve()  # warm-up (kernels, first factorisations)
        assert fc.status == "complete" and len(fc.stroke) == 91 and len(xc) == 91
        tf, ts, tx = [], [], []
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            an.frequency_curve()
            tf.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            an.frequency_curve(mirror=False, mesh_error=False)  # the same work as Exudyn's: both sides, no estimate
            ts.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            ex.curve()
            tx.append(time.perf_counter() - t0)
        i0, i45 = int(np.argmin(np.abs(fc.stroke))), int(np.argmin(np.abs(fc.stroke - 45)))
        rows.append(
            (
                n,
                statistics.median(tf),
                statistics.median(ts),
                statistics.median(tx),
                statistics.median([b / a for a, b in zip(tf, tx)]),
                statistics.median([b / a for a, b in zip(ts, tx)]),
                fc.parasitic_hz[i0],
                fc.parasitic_hz[i45],
                xc[0.0][1],
                xc[45.0][1],
            )
        )
    print(
        f"91-point leaf curve, {args.repeat} interleaved repetitions; Exudyn {exudyn.__version__}; "
        f"{os.cpu_count()} CPUs; Python {sys.version.split()[0]}; load {os.getloadavg()[0]:.2f}"
    )
    print(
        "| elements | flexopt median [ms] | flexopt, both sides, no mesh estimate [ms] | Exudyn median [ms] "
        "| Exudyn / flexopt (median of pairs) | Exudyn / flexopt both sides | torsion at 0 / 45 deg, flexopt [Hz] "
        "| torsion at 0 / 45 deg, Exudyn [Hz] |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for n, a, a2, b, r, r2, f0, f45, x0, x45 in rows:
        print(
            f"| {n} | {a * 1e3:.1f} | {a2 * 1e3:.1f} | {b * 1e3:.1f} | {r:.2f} | {r2:.2f} | {f0:.2f} / {f45:.2f} "
            f"| {x0:.2f} / {x45:.2f} |"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
