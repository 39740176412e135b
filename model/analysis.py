"""frequency_curve(scene): equilibrium continuation plus an eigen solve at every stroke point.

This is the *exact* method: every point is a converged equilibrium (model.statics) and a full
generalised eigenproblem (model.modal). Continuation runs from the stress-free reference at stroke 0
outwards in each direction separately, so a mirror-symmetric design gives an even curve.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .assembly import System
from .causes import check_free_motions, check_mass, stiff_axis_drives
from .checks import annotate_curve
from .elements import von_mises_spec
from .errors import EquilibriumError, SceneError
from .kernels import compiled
from .modal import Modes, modes_at, participation, track
from .results import Failure, FrequencyCurve
from .scene import Scene, Stroke
from .statics import Equilibrium, NewtonOptions, StepFailure, WalkFailure, reference_equilibrium, walk
from .structure import Structure, compile_scene
from .symmetry import StrokeSymmetry, image_indices, one_side, stroke_symmetry
from .threads import limited

__all__ = ["MeshAnalysis", "von_mises", "beam_sigma", "beam_end_stresses", "DRIVE_CONVENTION", "MESH_CONVENTION"]

#: A loss of stability is bracketed by re-walking the failed interval in this many equal steps with the
#: stability check at each, and the failing step again, ... (MeshAnalysis._locate_loss) ...
LOSS_SUBSTEPS = 8
#: ... until the bracket is at most this fraction of the stroke at the loss (or of the first interval).
LOSS_RESOLUTION = 1e-3

#: What ``conventions["mesh"]`` says of a curve of one given mesh (model.curve states its estimate there).
MESH_CONVENTION = "one given mesh; no discretisation estimate (model.curve.Analysis estimates it)"

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
        with np.errstate(invalid="ignore"):  # NaN (no fibre distances) is set below, not compared
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
    flutter: complex | None = None  # the lowest complex omega^2 under non-conservative loads (model.modal)


class MeshAnalysis:
    """A compiled scene of one given mesh with its kernels, ready to compute exact curves (reuse it for
    repeated calls). The public curve pipeline, which resolves ``segments: "auto"`` and estimates the mesh's
    discretisation error, is :class:`model.curve.Analysis` (``flexopt.model.Analysis``)."""

    #: The stroke-0 expansion of the fast methods (modal derivatives, model.methods.taylor), built on first use.
    expansion: object | None = None

    def __init__(self, scene: Scene, options: NewtonOptions | None = None) -> None:
        auto = [e.name for e in scene.elements if getattr(e, "segments", 1) == "auto"]
        if auto:
            raise SceneError(
                "elements[].segments",
                f"beams {', '.join(auto)} have segments 'auto', which one given "
                "mesh cannot solve: use flexopt.model.Analysis (model.curve), which resolves them",
            )
        self.scene = scene
        self.structure = compile_scene(scene)
        self.system = System(self.structure)
        self.options = options or NewtonOptions()
        self._checked = False  # check() has run (once per analysis)

    @property
    def stroke(self) -> Stroke:
        """The scene's stroke, never None here: :class:`System` refuses a scene without one."""
        st = self.scene.stroke
        if st is None:  # System(self.structure) raised for it in __init__; this narrows the type
            raise SceneError("stroke", f"scene '{self.scene.name}' has no stroke: add a 'stroke'")
        return st

    def label_modes(self, modes: Modes, tangent: np.ndarray | None = None) -> tuple[list[str], float]:
        """Labels of the modes (``drive``, ``parasitic``, ``intended``) and the first parasitic frequency.

        With the drive free, the drive mode is the one that moves the drive coordinate itself: the largest
        mass-weighted MAC with ``tangent``, the equilibrium path's ``d xi / d s`` (how the whole structure
        follows a change of the drive coordinate: for a rotation drive, the spin of the driven part about
        the drive's fixed axis at the pivot, with the flexures deforming as the drive bends them). Without
        the tangent (callers that hold no equilibrium) the mode with the largest kinetic-energy share in the
        driven master's drive DOF, which misreads a rotor whose centre of mass lies off the pivot axis.
        """
        hz = modes.hz
        part = participation(self.system, modes)
        drive_free = self.stroke.drive == "free"
        labels = ["parasitic"] * len(hz)
        if drive_free and len(hz):
            if tangent is not None and np.any(tangent):
                Mt = modes.M @ tangent
                num = (modes.phi.T @ Mt) ** 2
                den = np.einsum("ik,ik->k", modes.phi, modes.M @ modes.phi) * float(tangent @ Mt)
                frac = num / np.where(den > 0, den, 1.0)
            else:
                dd = self.system.drive
                frac = modes.phi[dd] * (modes.M[dd] @ modes.phi)
            labels[int(np.argmax(np.abs(frac)))] = "drive"
        if part is not None:
            labels = [
                lab if lab == "drive" else ("parasitic" if p > 0.5 else "intended") for lab, p in zip(labels, part)
            ]
        par = [h for h, lab in zip(hz, labels) if lab == "parasitic"]
        return labels, (min(par) if par else float("nan"))

    def check(self) -> None:
        """The checks run before continuation (:mod:`model.causes`): mass underflow, parts not connected
        to anything and mechanisms raise an error that names them. Run once per analysis."""
        if self._checked:
            return
        check_mass(self.structure)
        check_free_motions(self.structure)
        self._checked = True

    def _locate_loss(self, eq_a: Equilibrium, w2_a: float, target: float) -> Equilibrium | WalkFailure:
        """Confirm and locate a loss of stability between the stable ``eq_a`` (lowest eigenvalue ``w2_a``)
        and ``target`` (internal units), where the continuation found the tangent stiffness indefinite or
        Newton failing.

        The interval is walked again in :data:`LOSS_SUBSTEPS` equal steps with the stability check at each
        step, and the failing step is subdivided the same way, until the bracket is at most
        :data:`LOSS_RESOLUTION` of the stroke at the loss. If the small steps reach ``target`` on a stable
        path the coarse step had jumped to another (unstable) branch: returns the equilibrium at
        ``target``. Otherwise the loss is where the lowest ``omega^2`` extrapolates to zero: the
        quadratic through the last three stable points (``omega^2`` of a stability loss falls smoothly to
        zero, linearly in the stroke at a simple root, so the extrapolation from just before it is
        accurate to the square of the step; interpolating linearly between the last stable and the first
        unstable point reads early on a concave ``omega^2``). For a fold (Newton fails, no equilibrium
        beyond) the end of the last bracket. Returns the failure with the loss and the last stable stroke.
        """
        sys, opts, drive = self.system, self.options, self.stroke.drive
        hist: list[tuple[float, float]] = [(eq_a.stroke, w2_a)]  # stable (stroke, lowest omega^2)
        st: dict = {"a": eq_a, "b": float("nan"), "w2_b": float("nan")}

        def check(eq: Equilibrium) -> WalkFailure | None:
            m = modes_at(sys, eq, 1, drive)
            lam = float(m.omega2[0]) if len(m.omega2) else 1.0
            if not lam > 0:
                st["b"], st["w2_b"] = eq.stroke, lam
                return WalkFailure("unstable", eq.stroke, st["a"].stroke, "")
            st["a"] = eq
            hist.append((eq.stroke, lam))
            return None

        step = (target - eq_a.stroke) / LOSS_SUBSTEPS
        first = abs(target - eq_a.stroke)
        while True:
            a = st["a"]
            n = max(1, int(np.ceil(abs(target - a.stroke) / abs(step) - 1e-9)))
            grid = a.stroke + step * np.arange(1, n + 1)
            grid[-1] = target
            fail = walk(sys, grid, opts, check, start=a)
            if fail is None:
                return st["a"]
            a = st["a"]
            b = st["b"] if fail.reason == "unstable" else float(grid[np.abs(grid) > abs(a.stroke)][0])
            if abs(b - a.stroke) <= LOSS_RESOLUTION * max(abs(b), 1e-6 * first):
                break
            target = b
            step = (b - a.stroke) / LOSS_SUBSTEPS
        if fail.reason != "unstable":
            return WalkFailure(fail.reason, b, a.stroke, "")
        # omega^2 -> 0: quadratic through the last three stable points, else the line through the last two,
        # else (the first substep was already unstable) the line to the unstable point; kept in [a, b]
        pts = np.array(hist[-3:])
        if len(pts) == 1:
            pts = np.array([hist[-1], (b, st["w2_b"])])
        x = pts[:, 0] - a.stroke
        roots = np.roots(np.polyfit(x, pts[:, 1], len(pts) - 1))
        roots = roots[np.isreal(roots)].real
        hi = b - a.stroke
        inside = roots[(roots * np.sign(hi) >= 0) & (np.abs(roots) <= abs(hi))]
        s_loss = a.stroke + float(inside[np.argmin(np.abs(inside))]) if len(inside) else b
        return WalkFailure("unstable", s_loss, a.stroke, "")

    @functools.cached_property
    def symmetry(self) -> StrokeSymmetry | None:
        """The design's symmetry that reverses the stroke (:func:`model.symmetry.stroke_symmetry`), or None
        (always None with loads or gravity, which the symmetry search does not map)."""
        if self.system.loads is not None:
            return None
        return stroke_symmetry(self.scene)

    def _mirrored(self, sym: StrokeSymmetry, internal: np.ndarray, points: dict, failures: list) -> tuple[dict, list]:
        """The requested points of both sides from the solved side of positive strokes (see
        :meth:`frequency_curve`), and the failures of both sides (a loss at ``s`` is one at ``-s``)."""
        names = list(self.structure.member_names)
        perm = np.array([names.index(sym.element_map[m]) for m in names])
        out: dict = {}
        solved = np.array(sorted(points))
        for v, i in zip(internal, image_indices(solved, internal)):
            if i is None:
                continue
            p = points[float(solved[i])]
            if v >= 0:
                out[float(v)] = p
            else:
                out[float(v)] = _Point(float(v), p.hz, p.labels, p.parasitic, -p.reaction, p.vm[perm], p.iterations)
        both: list = []
        if np.any(internal > 0) or not np.any(internal < 0):
            both += failures
        if np.any(internal < 0):
            for f in failures:
                # the failure's message has the signed strokes in it: built again for the mirrored numbers
                wf = WalkFailure(
                    f.reason,
                    float(-self.stroke.to_internal(f.stroke)),
                    float(-self.stroke.to_internal(f.last_converged)),
                    "",
                )
                both.append(self._failure(wf))
        return out, both

    def _failure(self, fail: WalkFailure) -> Failure:
        """The public :class:`Failure` of a located loss (:meth:`_locate_loss`), in the stroke unit, with
        the cause when the structure shows one (:func:`model.causes.stiff_axis_drives`)."""
        unit = self.stroke.resolved_unit
        f = (lambda v: float(np.degrees(v))) if unit == "deg" else float
        s_loss, s_a = f(fail.stroke), f(fail.last_converged)
        if fail.reason == "unstable":
            what = (
                f"equilibrium becomes unstable at stroke {s_loss:+.5g} {unit} (the tangent stiffness loses "
                f"positive definiteness: a parasitic frequency reaches 0 by extrapolation of omega^2; "
                f"buckling or a bifurcation)"
            )
        else:
            what = (
                f"no equilibrium found beyond stroke {s_a:+.5g} {unit}: Newton fails by {s_loss:+.5g} {unit} "
                f"even with small steps (a limit point, snap-through or loss of equilibrium)"
            )
        causes = stiff_axis_drives(self.structure)
        loads = self.system.loads
        if fail.reason == "unstable" and loads is not None and loads.nonconservative:
            causes = [
                "the non-conservative load(s) "
                + ", ".join(loads.nonconservative_names())
                + " make the stiffness unsymmetric: a real eigenvalue omega^2 crossed zero (divergence)",
                *causes,
            ]
        cause = ("; cause: " + "; ".join(causes)) if causes else ""
        return Failure(
            fail.reason,
            s_loss,
            s_a,
            f"{what}; last stable equilibrium at {s_a:+.5g} {unit}{cause}. The curve stops there",
        )

    @limited()  # one BLAS thread while it computes (model.threads)
    def frequency_curve(
        self,
        stroke: np.ndarray | None = None,
        progress: Callable[[int, int], None] | None = None,
        visit: Callable[[Equilibrium, Modes, list[str]], None] | None = None,
        mirror: bool = True,
    ) -> FrequencyCurve:
        """The exact frequency curve of this mesh with its checks' warnings and provenance
        (:func:`model.checks.annotate_curve`); arguments as :meth:`exact_curve`."""
        curve, _ = self.exact_curve(stroke, progress, visit, mirror)
        return annotate_curve(curve, self.scene, self.options)  # warnings and provenance (model.checks)

    def exact_curve(
        self,
        stroke: np.ndarray | None = None,
        progress: Callable[[int, int], None] | None = None,
        visit: Callable[[Equilibrium, Modes, list[str]], None] | None = None,
        mirror: bool = True,
    ) -> tuple[FrequencyCurve, dict[float, float]]:
        """The exact frequency curve at ``stroke`` (stroke unit; default: the scene's stroke grid), before
        its checks, and the first parasitic frequency at every solved stroke (internal units; the solved
        side only when mirrored), which the mesh estimate reads (:mod:`model.curve`).

        ``visit(eq, modes, labels)``, if given, sees every converged point with its tracked modes and their
        labels (the design sensitivities of :mod:`model.design` are computed there).
        ``mirror``: when the design has a symmetry that reverses the stroke (:attr:`symmetry`), solve the
        side of positive strokes only and give each point at ``-s`` from the one at ``s`` (same frequencies
        and labels, opposite drive reaction, each member's stresses those of its image); the exact curve on
        both sides agrees with it to the Newton tolerance (about 1e-10 relative on the templates). Not with
        ``visit``, which sees every equilibrium solved.
        """
        t0 = time.perf_counter()
        spec = self.stroke
        values = np.asarray(spec.values() if stroke is None else stroke, dtype=float)
        internal = spec.to_internal(values)
        points: dict[float, _Point] = {}
        failures: list[Failure] = []
        iters: list[int] = []
        # Branch order is the frequency order at stroke 0 on both sides: tracking starts from the modes of
        # the reference equilibrium, so a mirror-symmetric design gives the same branches left and right.
        eq0, modes0 = self._reference()
        sym = self.symmetry if (mirror and visit is None) else None
        if sym is not None:  # one side: every requested |s|; the other side is its image (_mirrored)
            sides: tuple[np.ndarray, ...] = (one_side(internal),)
            total = len(sides[0])
        else:
            sides = (internal[internal >= 0], internal[internal < 0][::-1])
            total = len(values)
        report = None if progress is None else (lambda: progress(len(points), total))
        for side in sides:
            if len(side):
                failures += self._walk_side(side, eq0, modes0, points, iters, visit, report)
        solved = dict(points)
        if sym is not None:
            points, failures = self._mirrored(sym, internal, points, failures)
        curve = self._curve_record(
            points,
            failures,
            iters,
            sym if np.any(internal < 0) else None,
            time.perf_counter() - t0,
            dict(zip(internal.tolist(), values.tolist())),
        )
        return curve, {k: p.parasitic for k, p in solved.items()}

    def _reference(self) -> tuple[Equilibrium, Modes]:
        """The checks (:meth:`check`), then the equilibrium at the stress-free reference (stroke 0) and its
        modes, where continuation and mode tracking start on both sides."""
        self.check()
        try:
            eq0 = reference_equilibrium(self.system, self.options)
        except StepFailure as exc:  # past the checks: e.g. a mechanism in a model too large to search
            if self.system.loads is not None:
                raise EquilibriumError(
                    f"no equilibrium under the scene's loads at stroke 0: {exc}; reduce the loads or gravity, or "
                    "stiffen the structure",
                    stroke=0.0,
                    last_converged=float("nan"),
                    reason="divergence",
                ) from exc
            raise EquilibriumError(
                f"no equilibrium at the stress-free reference (stroke 0): {exc}; the tangent stiffness is "
                "singular, so some part moves without deforming anything (a mechanism or an unconnected part); "
                "support it or connect it to the structure",
                stroke=0.0,
                last_converged=float("nan"),
                reason="divergence",
            ) from exc
        s = self.structure
        return eq0, modes_at(self.system, eq0, s.scene.modes + 2, self.stroke.drive)

    def _walk_side(
        self,
        side: np.ndarray,
        eq0: Equilibrium,
        modes0: Modes,
        points: dict[float, _Point],
        iters: list[int],
        visit: Callable[[Equilibrium, Modes, list[str]], None] | None,
        report: Callable[[], None] | None,
    ) -> list[Failure]:
        """Continuation from ``eq0`` through the targets of one side (internal units, ordered away from 0)
        with tracked modes at every point, into ``points`` (and the Newton iterations into ``iters``); a
        loss of stability is located (:meth:`_locate_loss`) and ends the side. Returns its failures."""
        s = self.structure
        n_rep = s.scene.modes
        k_track = n_rep + 2
        drive = self.stroke.drive
        prev: list[Modes | None] = [modes0]
        prev_w2: list[float] = [float(modes0.omega2[0]) if len(modes0.omega2) else float("nan")]
        last_eq: list[Equilibrium] = [eq0]  # last accepted (converged, stable) equilibrium
        bad: list[float] = [float("nan")]  # the target at which accept() found an unstable equilibrium

        def accept(eq: Equilibrium) -> WalkFailure | None:
            modes = modes_at(self.system, eq, k_track, drive, prev[0])
            lowest = float(modes.omega2[0]) if len(modes.omega2) else 1.0
            if not lowest > 0:  # stop here; _locate_loss confirms and locates it
                bad[0] = eq.stroke
                return WalkFailure("unstable", eq.stroke, last_eq[0].stroke, "")
            if prev[0] is not None:
                perm = track(prev[0], modes)
                modes = Modes(modes.omega2[perm], modes.phi[:, perm], modes.M, modes.lanczos, modes.complex_omega2)
            labels, par = self.label_modes(modes, eq.tangent)
            if visit is not None:
                visit(eq, modes, labels)
            vm = von_mises(s, self.system, eq)
            cw = modes.complex_omega2
            points[eq.stroke] = _Point(
                eq.stroke,
                modes.hz[:n_rep].copy(),
                labels[:n_rep],
                par,
                eq.drive_reaction,
                vm,
                eq.iterations,
                complex(cw[0]) if len(cw) else None,
            )
            iters.append(eq.iterations)
            prev[0], prev_w2[0], last_eq[0] = modes, lowest, eq
            if report is not None:
                report()
            return None

        targets = side
        if targets[0] == 0.0:  # the reference itself: eq0, already solved
            if accept(eq0) is not None:
                return [self._failure(WalkFailure("unstable", 0.0, 0.0, ""))]
            targets = targets[1:]
        while len(targets):
            fail = walk(self.system, targets, self.options, accept, start=last_eq[0])
            if fail is None:
                break
            # the requested stroke the walk could not pass: where accept() found instability, else the
            # first target beyond the last accepted point
            target = (
                bad[0] if fail.reason == "unstable" else float(targets[np.abs(targets) > abs(last_eq[0].stroke)][0])
            )
            reached = self._locate_loss(last_eq[0], prev_w2[0], target)
            if isinstance(reached, WalkFailure):
                return [self._failure(reached)]
            # small steps reach the target on a stable path: the coarse step had landed on another
            # (unstable) equilibrium branch. Keep the point and go on.
            accept(reached)
            targets = targets[np.abs(targets) > abs(target)]
        return []

    def _curve_record(
        self,
        points: dict[float, _Point],
        failures: list[Failure],
        iters: list[int],
        sym: StrokeSymmetry | None,
        seconds: float,
        asked: dict[float, float] | None = None,
    ) -> FrequencyCurve:
        """The :class:`FrequencyCurve` of the solved ``points`` (internal strokes, both sides), before its
        checks; ``sym`` the symmetry that mirrored negative strokes, if it did. ``asked``: internal stroke ->
        the value requested in the stroke unit; a requested point is reported as requested (-30.0, not
        -29.999999999999996 from deg -> rad -> deg), a point the walk added (where equilibrium was lost) is
        converted."""
        s = self.structure
        spec = self.stroke
        keys = sorted(points)
        pts = [points[k] for k in keys]
        to_unit = np.degrees if spec.resolved_unit == "deg" else (lambda v: np.asarray(v, dtype=float))
        mats = {m.name: m for m in s.scene.materials}
        allow = {e.name: mats[e.material].allowable_stress for e in s.scene.elements}
        k = min((len(p.hz) for p in pts), default=0)
        return FrequencyCurve(
            scene=s.scene.name,
            method="exact",
            stroke=np.array([asked[k] if asked and k in asked else float(to_unit(k)) for k in keys], dtype=float),
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
            conventions=self._conventions(sym),
            solver={
                "tol": self.options.tol,
                "seconds": seconds,
                "mean_newton_iterations": float(np.mean(iters)) if iters else 0.0,
            },
            warnings=self._flutter_warnings(pts, to_unit, asked),
        )

    def _flutter_warnings(self, pts: list[_Point], to_unit: Callable, asked: dict[float, float] | None) -> tuple:
        """A ``notice`` when the eigenproblem had complex eigenvalues (flutter) at some points: never silent,
        the reported frequencies being those of the real eigenvalues only (model.modal.general_pairs)."""
        bad = [p for p in pts if p.flutter is not None]
        loads = self.system.loads
        if not bad or loads is None:
            return ()
        from .results import ResultWarning

        unit = self.stroke.resolved_unit
        at = [asked[p.stroke] if asked and p.stroke in asked else float(to_unit(p.stroke)) for p in bad]
        w = complex(bad[0].flutter or 0.0)
        names = ", ".join(loads.nonconservative_names())
        return (
            ResultWarning(
                "notice",
                f"flutter: the eigenproblem has complex eigenvalues at {len(bad)} of {len(pts)} stroke points "
                f"({min(at):+.5g} to {max(at):+.5g} {unit}; omega^2 = {w.real:.5g} +- {w.imag:.5g}i rad^2/s^2 at "
                f"{at[0]:+.5g} {unit}): the equilibrium is dynamically unstable under the non-conservative "
                f"load(s) {names}; the frequencies reported are those of the real eigenvalues (the coalesced "
                "modes are left out)",
                stroke_range=(min(at), max(at)),
                value=float(w.imag / abs(w)),
            ),
        )

    def _conventions(self, sym: StrokeSymmetry | None) -> dict[str, str]:
        """What the curve's numbers mean (``FrequencyCurve.conventions``)."""
        s = self.structure
        spec = self.stroke
        return {
            "drive": DRIVE_CONVENTION[spec.kind],
            "drive_in_eigen_analysis": spec.drive,
            "parasitic": "modes with more than half their kinetic energy in the declared support directions"
            if s.support_projector is not None
            else "every mode with the drive locked",
            "warping": ", ".join(f"{n}: {w}" for n, w in zip(s.member_names, s.warping)),
            "mesh": MESH_CONVENTION,
            **(
                {
                    "symmetry": f"negative strokes mirrored from positive ones: {sym.describe()} maps the design "
                    "onto itself and reverses the stroke (model.symmetry); mirror=False solves both sides"
                }
                if sym is not None
                else {}
            ),
            "mass": "consistent translational mass of the cubic (Hermite) centre line (Przemieniecki 1968 ch. 11); "
            "rotary inertia the mean of lumped and consistent (model.elements.beam_mass_spec)",
            **({"loads": self._loads_convention()} if self.system.loads is not None else {}),
        }

    def _loads_convention(self) -> str:
        """What the curve's loads mean for its numbers (``conventions["loads"]``)."""
        ls = self.system.loads
        assert ls is not None  # called only with loads (see _conventions)
        sc = self.structure.scene
        what = f"{len(sc.loads)} load(s)" + (", gravity" if sc.gravity is not None and any(sc.gravity) else "")
        names = ls.nonconservative_names()
        kind = (
            "non-conservative: "
            + ", ".join(names)
            + " (unsymmetric stiffness; the general eigenproblem: frequencies of the real eigenvalues, complex pairs "
            "reported as flutter warnings)"
            if names
            else "conservative (dead forces and gravity: symmetric stiffness)"
        )
        return (
            f"{what} raised from 0 at stroke 0 (in steps where needed) and taken at each stroke's value "
            f"(model.loads); {kind}; "
            "solved on the numpy route (the compiled one-call Newton route does not take loads: the same "
            "equations, slower)"
        )
