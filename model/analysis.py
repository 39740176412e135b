"""frequency_curve(scene): equilibrium continuation plus an eigen solve at every stroke point.

This is the *exact* method: every point is a converged equilibrium (model.statics) and a full
generalised eigenproblem (model.modal). Continuation runs from the stress-free reference at stroke 0
outwards in each direction separately, so a mirror-symmetric design gives an even curve.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .assembly import System
from .checks import annotate_curve
from .elements import von_mises_spec
from .kernels import compiled
from .modal import Modes, modes_at, participation, track
from .results import Failure, FrequencyCurve
from .scene import Scene
from .statics import Equilibrium, NewtonOptions, WalkFailure, solve_point, walk
from .structure import Structure, compile_scene

__all__ = ["frequency_curve", "Analysis", "von_mises"]

DRIVE_CONVENTION = {
    "rotation": "stroke = twist angle about the fixed drive axis (swing-twist); the actuator exerts a moment "
    "about that axis only; locking the drive removes only the incremental spin about it "
    "(delta_omega . axis = 0), other rotations free",
    "translation": "stroke = displacement along the fixed drive axis; the actuator exerts a force along it "
    "only; locking the drive removes only that incremental translation",
}


def beam_sigma(structure: Structure, sys: System, eq: Equilibrium) -> np.ndarray:
    """Generalised stresses of every beam segment (nb, 6): ``S eps`` for flexible deformations, the
    multipliers for rigid ones."""
    s = structure
    sig = np.einsum("eij,ej->ei", s.beam_stiff, eq.ev.e_beam * s.beam_mask)
    k, el, mode = sys.con_beam
    sig[el, mode] = eq.state.lam[k]
    return sig


def beam_end_stresses(structure: Structure, sys: System, eq: Equilibrium) -> np.ndarray:
    """Von Mises bound at both ends of every beam segment (nb, 2) [Pa]."""
    z = np.hstack([beam_sigma(structure, sys, eq), structure.beam_stress])
    return compiled(von_mises_spec())(z)


def von_mises(structure: Structure, sys: System, eq: Equilibrium) -> np.ndarray:
    """Largest von Mises stress of every scene element (member) at ``eq`` [Pa].

    Generalised stresses ``sigma = S eps`` for flexible deformations and the multipliers for rigid ones;
    the bound per element end is :func:`model.elements.beam_von_mises` (one formula, also used for the
    optimiser's stress gradients). Members without fibre distances get NaN.
    """
    s = structure
    out = np.zeros(len(s.member_names))
    st = eq.state
    if s.n_beams:
        vm = beam_end_stresses(s, sys, eq).max(axis=1)
        np.maximum.at(out, s.beam_member, vm)
        out[np.unique(s.beam_member[np.isnan(vm)])] = np.nan
    if len(s.truss_nodes):
        S11 = s.truss_const[:, 1]
        sig = S11 * eq.ev.e_truss * s.truss_const[:, 2]
        k, el = sys.con_truss
        sig[el] = st.lam[k]
        np.maximum.at(out, s.truss_member, np.abs(sig) / s.truss_area)
    return out


@dataclass
class _Point:
    stroke: float
    hz: np.ndarray
    labels: list[str]
    parasitic: float
    reaction: float
    vm: np.ndarray
    iterations: int


class Analysis:
    """A compiled scene with its kernels, ready to compute curves (reuse it for repeated calls)."""

    def __init__(self, scene: Scene, options: NewtonOptions | None = None) -> None:
        self.scene = scene
        self.structure = compile_scene(scene)
        self.system = System(self.structure)
        self.options = options or NewtonOptions()

    def _labels(self, modes: Modes) -> tuple[list[str], float]:
        s = self.structure
        hz = modes.hz
        part = participation(self.system, modes)
        drive_free = s.scene.stroke.drive == "free"
        labels = ["parasitic"] * len(hz)
        if drive_free:
            dd = self.system.drive
            frac = modes.phi[dd] * (modes.M[dd] @ modes.phi)
            labels[int(np.argmax(np.abs(frac)))] = "drive"
        if part is not None:
            labels = [lab if lab == "drive" else ("parasitic" if p > 0.5 else "intended")
                      for lab, p in zip(labels, part)]
        par = [h for h, lab in zip(hz, labels) if lab == "parasitic"]
        return labels, (min(par) if par else float("nan"))

    def frequency_curve(
        self, stroke: np.ndarray | None = None, progress: Callable[[int, int], None] | None = None,
        visit: Callable[[Equilibrium, Modes, list[str]], None] | None = None,
    ) -> FrequencyCurve:
        """The exact frequency curve at ``stroke`` (stroke unit; default: the scene's stroke grid).

        ``visit(eq, modes, labels)``, if given, sees every converged point with its tracked modes and their
        labels (the design sensitivities of :mod:`model.design` are computed there).
        """
        t0 = time.perf_counter()
        s = self.structure
        spec = s.scene.stroke
        values = np.asarray(spec.values() if stroke is None else stroke, dtype=float)
        internal = spec.to_internal(values)
        n_rep = s.scene.modes
        k_track = n_rep + 2
        points: dict[float, _Point] = {}
        failures: list[Failure] = []
        total = len(values)
        iters = []

        # Branch order is the frequency order at stroke 0 on both sides: tracking starts from the modes of
        # the reference equilibrium, so a mirror-symmetric design gives the same branches left and right.
        eq0 = solve_point(self.system, self.system.reference_state(), 0.0, self.options, 0.0)
        modes0 = modes_at(self.system, eq0, k_track, s.scene.stroke.drive)
        for side in (internal[internal >= 0], internal[internal < 0][::-1]):
            if len(side) == 0:
                continue
            prev: list[Modes | None] = [modes0]
            prev_w2: list[float] = [float(modes0.omega2[0]) if len(modes0.omega2) else float("nan")]
            prev_s: list[float] = [0.0]

            def accept(eq: Equilibrium) -> WalkFailure | None:
                modes = modes_at(self.system, eq, k_track, s.scene.stroke.drive)
                lowest = float(modes.omega2[0]) if len(modes.omega2) else 1.0
                if lowest <= 0:
                    a, b = prev_w2[0], lowest
                    frac = a / (a - b) if np.isfinite(a) and a > b else 1.0
                    s_loss = prev_s[0] + frac * (eq.stroke - prev_s[0])
                    return WalkFailure(
                        "unstable", s_loss, prev_s[0],
                        "equilibrium becomes unstable (the tangent stiffness loses positive definiteness: "
                        "bifurcation or buckling, a parasitic frequency reaches 0)",
                    )
                if prev[0] is not None:
                    perm = track(prev[0], modes)
                    modes = Modes(modes.omega2[perm], modes.phi[:, perm], modes.M)
                labels, par = self._labels(modes)
                if visit is not None:
                    visit(eq, modes, labels)
                vm = von_mises(s, self.system, eq)
                points[eq.stroke] = _Point(eq.stroke, modes.hz[:n_rep].copy(), labels[:n_rep], par,
                                           eq.drive_reaction, vm, eq.iterations)
                iters.append(eq.iterations)
                prev[0], prev_w2[0], prev_s[0] = modes, lowest, eq.stroke
                if progress is not None:
                    progress(len(points), total)
                return None

            fail = walk(self.system, side, self.options, accept, start=eq0)
            if fail is not None:
                conv = spec.resolved_unit == "deg"
                f = (lambda v: float(np.degrees(v))) if conv else float
                failures.append(Failure(fail.reason, f(fail.stroke), f(fail.last_converged),
                                        f"{fail.message} (at stroke {f(fail.stroke):.4g} {spec.resolved_unit}; "
                                        f"last converged {f(fail.last_converged):.4g})"))

        keys = sorted(points)
        pts = [points[k] for k in keys]
        to_unit = np.degrees if spec.resolved_unit == "deg" else (lambda v: np.asarray(v, dtype=float))
        mats = {m.name: m for m in s.scene.materials}
        allow = {e.name: mats[e.material].allowable_stress for e in s.scene.elements}
        k = min((len(p.hz) for p in pts), default=0)
        curve = FrequencyCurve(
            scene=s.scene.name,
            method="exact",
            stroke=np.asarray(to_unit(np.array(keys)), dtype=float),
            stroke_unit=spec.resolved_unit,
            stroke_kind=spec.kind,
            modes_hz=np.array([p.hz[:k] for p in pts]).reshape(len(pts), k),
            mode_labels=np.array([p.labels[:k] for p in pts], dtype=object).reshape(len(pts), k),
            parasitic_hz=np.array([p.parasitic for p in pts]),
            drive_reaction=np.array([p.reaction for p in pts]),
            drive_reaction_unit="N m" if spec.kind == "rotation" else "N",
            max_von_mises={name: np.array([p.vm[i] for p in pts]) for i, name in enumerate(s.member_names)},
            allowable_stress=allow,
            status="complete" if not failures else "truncated",
            failures=tuple(failures),
            conventions={
                "drive": DRIVE_CONVENTION[spec.kind],
                "drive_in_eigen_analysis": spec.drive,
                "parasitic": "modes with more than half their kinetic energy in the declared support directions"
                if s.support_projector is not None else "every mode with the drive locked",
                "warping": ", ".join(f"{n}: {w}" for n, w in zip(s.member_names, s.warping)),
                "mass": "consistent translational mass (linear interpolation), rotary inertia lumped at nodes",
            },
            solver={"tol": self.options.tol, "seconds": time.perf_counter() - t0,
                    "mean_newton_iterations": float(np.mean(iters)) if iters else 0.0},
        )
        return annotate_curve(curve, self.scene, self.options)  # warnings and provenance (model.checks)


def frequency_curve(scene: Scene, stroke: np.ndarray | None = None,
                    progress: Callable[[int, int], None] | None = None) -> FrequencyCurve:
    """Exact stroke-dependent natural frequencies of ``scene`` (see :class:`Analysis`)."""
    return Analysis(scene).frequency_curve(stroke, progress)
