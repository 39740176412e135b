"""Static equilibrium along the stroke: Newton with the exact tangent, continuation with step control.

Equations at a stroke value ``s`` (drive basis, see model.assembly): the gradient of the Lagrangian
vanishes in every active DOF except the drive (``g_f = 0``: the actuator exerts a force or moment along
its axis only), the drive coordinate equals ``s`` (twist about the fixed axis, or displacement along
it), and every rigid deformation is zero. Newton solves this square system with its exact Jacobian

    [ H_fa   G_f^T ] [dxi ]     [ g_f       ]
    [ dD_a     0   ] [    ] = - [ D(q) - s  ]
    [ G_a      0   ] [dlam]     [ c         ]

where ``H`` is the Hessian of the Lagrangian (material plus geometric stiffness, from CasADi) and ``dD``
the drive gradient. Convergence needs the Jacobi-scaled residual below ``tol`` and the Newton increment
below ``polish`` (or below ``tol`` once it stalls at the rounding floor), translations relative to the
structure's length scale and rotations in rad, so the criterion is the same in any consistent units; the
state accepted is the one at which the residual was evaluated.
Continuation starts at the stress-free reference (stroke 0) and walks outwards to each requested stroke
value, with a tangent (and, when available, second-order) predictor and step halving on failure.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from . import linalg
from .assembly import Assembled, State, System

__all__ = ["NewtonOptions", "Equilibrium", "solve_point", "StepFailure", "path_curvature"]


@dataclass(frozen=True)
class NewtonOptions:
    """Solver settings (dimensionless, see the module docstring)."""

    tol: float = 1e-9
    #: Newton increment aimed for. Frequencies of thin leaves are sensitive to the axial force, which an
    #: increment of 1e-9 L in a stiff direction still changes by about 1e-5 relative; Newton converges
    #: quadratically, so one more step from 1e-9 costs little and reaches rounding level. A state whose
    #: increment stalls between ``polish`` and ``tol`` (the rounding floor of a badly scaled model) is
    #: accepted at ``tol``.
    polish: float = 1e-12
    max_iter: int = 12
    max_halvings: int = 12


@dataclass
class Equilibrium:
    """A converged equilibrium with everything evaluated at it."""

    stroke: float  # internal units (rad or length)
    state: State
    ev: Assembled
    free: np.ndarray  # active DOFs except the drive
    tangent: np.ndarray  # d(xi)/ds over all DOFs (drive basis)
    iterations: int
    residual: float  # Jacobi-scaled residual at the accepted state
    increment: float  # scaled Newton increment at the accepted state
    extra: dict = field(default_factory=dict)

    @property
    def drive_reaction(self) -> float:
        """Actuator force [N] or moment [N m] along the drive axis (energy gradient of the drive DOF)."""
        return float(self.ev.g[self.extra["drive_dof"]])


#: Newton gives up (and the continuation halves its step) when an increment above ``1e3 tol`` is more than this
#: fraction of the increment two iterations earlier.
CONTRACTION = 0.5


class StepFailure(Exception):
    """Newton did not converge from a predictor (internal; continuation halves the step)."""


def _scaled_residual(sys: System, ev: Assembled, dval: float, s_target: float) -> float:
    """Largest Jacobi-scaled residual: |g_i| / (|H_ii| l_i), the drive mismatch and rigid deformations."""
    free = sys.free
    diag = np.abs(ev.H.diagonal()[free])
    dscale = np.maximum(diag, 1e-12 * max(diag.max(initial=0.0), 1e-300))
    res = float(np.max(np.abs(ev.g[free]) / (dscale * sys.scale_free), initial=0.0))
    res = max(res, abs(dval - s_target) / sys.scale[sys.drive])
    if sys.n_con:
        res = max(res, float(np.max(np.abs(ev.c))) / sys.s.length_scale)
    return res


def _solve(A: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, int]:
    """``A x = b`` by LU with partial pivoting; ``A`` (C order) and ``b`` (Fortran order) are overwritten.
    The compiled driver (model.linalg) without Python between the LAPACK calls; scipy's dgesv without it."""
    info = linalg.solve(A, b)
    if info is None:
        from scipy.linalg import lapack

        _, _, b, info = lapack.dgesv(A, b, overwrite_a=1, overwrite_b=1)
    return b, info


def _newton_step(sys: System, ev: Assembled, dd: np.ndarray, rhs_drive: float) -> tuple[np.ndarray, np.ndarray,
                                                                                      np.ndarray, np.ndarray]:
    """Solve the Newton system for the correction and the path tangent.

    The Jacobian of the free rows is ``H + chart`` (the Hessian plus ``-1/2 skew(g)`` on rotation blocks,
    see ``System._chart_correction``): exact, so Newton converges quadratically even under a large drive
    moment. Without rigid deformations and with the drive gradient along the drive DOF only (no swing of
    the driven node), the system reduces to the free block (one LU solve, two right-hand sides);
    otherwise an LU solve of the full bordered system. Returns (dxi, dlam, tangent, dlam_ds).
    """
    n, nr, f, d = sys.n, sys.n_con, sys.free, sys.drive
    A = ev.H if ev.chart is None else ev.H + ev.chart
    dd_d = dd[d]
    other = float(np.abs(dd).sum()) - abs(dd_d)
    if nr == 0 and other <= 1e-14 * abs(dd_d):
        Afd = A[f, d]
        dxd = -rhs_drive / dd_d
        rhs = np.empty((len(f), 2), order="F")
        rhs[:, 0] = -ev.g[f] - Afd * dxd
        rhs[:, 1] = -Afd / dd_d
        if len(f) == 0:
            sol = rhs
        else:  # LAPACK directly (model.linalg): scipy's wrappers cost more than a 60-DOF factorisation
            sol, info = _solve(sys.free_block(A), rhs)
            if info > 0:
                raise np.linalg.LinAlgError(f"singular tangent stiffness (LAPACK dgesv info {info})")
        dxi = np.empty(n)
        tan = np.empty(n)
        dxi[f], dxi[d] = sol[:, 0], dxd
        tan[f], tan[d] = sol[:, 1], 1.0 / dd_d
        return dxi, np.zeros(0), tan, np.zeros(0)
    J = np.zeros((n + nr, n + nr))
    J[: len(f), :n] = A[f, :]
    J[len(f), :n] = dd
    if nr:
        J[: len(f), n:] = ev.G[:, f].T
        J[len(f) + 1 :, :n] = ev.G
    b = np.zeros((n + nr, 2), order="F")
    b[: len(f), 0] = -ev.g[f]
    b[len(f), 0] = -rhs_drive
    b[len(f) + 1 :, 0] = -ev.c
    b[len(f), 1] = 1.0
    sol, info = _solve(J, b)
    if info > 0:
        raise np.linalg.LinAlgError(f"singular Newton matrix (LAPACK dgesv info {info})")
    return sol[:n, 0], sol[n:, 0], sol[:n, 1], sol[n:, 1]


def _compiled_system(sys: System) -> "linalg.NewtonSystem | None":
    """The compiled Newton system of ``sys`` (cached on it), or None where the numpy route applies: no C
    driver, rigid deformations, a drive basis that is not made of global axes, or no one-call evaluate."""
    ns = sys._newton_system
    if ns is False:
        ns = None
        if sys._fast is not None and sys.direct and sys.n_con == 0 and sys.n > 0:
            comp = np.argmax(sys.Qa, axis=0)  # the global axis of each active basis column
            ns = linalg.newton_system(sys.n, sys.drive, 0 if sys.s.drive_kind == "rotation" else 1,
                                      sys.free, sys.block_pos, comp, np.asarray(sys.s.drive_axis, dtype=float),
                                      sys.scale, sys.scale_free, pattern=sys.pattern())
        sys._newton_system = ns
    return ns


def _compiled_step(sys: System, ns, ev: Assembled, st: State, s_target: float, near: float):
    """:func:`_newton_step`, the drive and :func:`_scaled_residual` in one C call; raises like them."""
    rotation = sys.s.drive_kind == "rotation"
    dval = 0.0 if rotation else sys.drive_value(st, near=near)
    dxi, tan, sc = linalg.newton(ns, ev.H, ev.chart, ev.g, st.R[sys.s.drive_master] if rotation else None, near,
                                 s_target, dval)
    if sc[3] != 1.0:
        raise StepFailure("non-finite residual")
    if sc[4] > 0:
        what = "singular tangent stiffness" if sc[5] else "singular Newton matrix"
        lu = "dgbtrf" if ns.bands["reduced" if sc[5] else "bordered"] else "dgetrf"
        raise StepFailure(f"singular tangent ({what} (LAPACK {lu} info {int(sc[4])}))")
    return dxi, tan, sc


def solve_point(
    sys: System,
    start: State,
    s_target: float,
    opts: NewtonOptions,
    theta_near: float,
) -> Equilibrium:
    """Newton iterations from ``start`` to the equilibrium at drive value ``s_target``.

    Raises
    ------
    StepFailure
        If the iteration diverges, produces non-finite numbers or exceeds ``max_iter``.
    """
    st = start
    inc = res = float("nan")
    incs: list[float] = []  # the increments of the iterations so far
    ns = _compiled_system(sys)
    for it in range(opts.max_iter + 1):
        ev = sys.evaluate(st)
        if ns is not None:  # the same system and numbers in one C call (model.linalg.newton)
            dxi, tan, sc = _compiled_step(sys, ns, ev, st, s_target, theta_near)
            dlam, dlam_ds = np.zeros(0), np.zeros(0)
            dval, inc, res = float(sc[0]), float(sc[1]), float(sc[2])
        else:
            if not (np.isfinite(ev.g).all() and np.isfinite(ev.H).all()):
                raise StepFailure("non-finite residual")
            dval = sys.drive_value(st, near=theta_near)
            dd = sys.drive_gradient(st)
            try:
                dxi, dlam, tan, dlam_ds = _newton_step(sys, ev, dd, dval - s_target)
            except np.linalg.LinAlgError as exc:
                raise StepFailure(f"singular tangent ({exc})") from exc
            inc = float(np.max(np.abs(dxi / sys.scale))) if sys.n else 0.0
            res = _scaled_residual(sys, ev, dval, s_target)
        if not np.isfinite(inc):
            raise StepFailure("non-finite increment")
        stalled = bool(incs) and inc > 0.25 * incs[-1]
        if res <= opts.tol and (inc <= opts.polish or (inc <= opts.tol and stalled)):
            return Equilibrium(
                stroke=s_target, state=st, ev=ev, free=sys.free, tangent=tan, iterations=it,
                residual=res, increment=inc, extra={"drive_dof": sys.drive, "dlam_ds": dlam_ds},
            )
        if it > 2 and inc > 1e3 * opts.tol and inc > 0.5:
            raise StepFailure(f"diverging (increment {inc:.3g})")
        if it >= 2 and inc > 1e3 * opts.tol and inc > CONTRACTION * incs[it - 2]:
            # Newton with the exact Jacobian contracts inside its basin (quadratically near the solution):
            # an increment not halved in two iterations means a predictor outside it, and iterating on
            # to max_iter only delays the step halving that brings the predictor back in
            raise StepFailure(f"not converging (increment {inc:.3g}, {incs[it - 2]:.3g} two iterations before)")
        incs.append(inc)
        st = sys.update(st, dxi, dlam if sys.n_con else None)
    raise StepFailure(f"no convergence in {opts.max_iter} iterations (increment {inc:.3g}, residual {res:.3g})")


def path_curvature(sys: System, eq: Equilibrium) -> np.ndarray:
    """``d^2 xi / ds^2`` of the equilibrium path at the stress-free reference ``eq`` (stroke 0).

    Differentiating the free rows ``g_f(xi(s)) = 0`` twice: ``H_ff xi''_f = -(DH[xi'] xi')_f`` with the
    drive coordinate's second derivative zero; ``DH[xi']`` is the exact third derivative of the Lagrangian
    contracted with the tangent (CasADi, :meth:`System.hessian_derivative`). At the reference the chart
    of the state is the reference's own and the gradient vanishes, so no chart terms enter (elsewhere they
    would: model.methods.taylor). Used as the second-order predictor of a long first step from stroke 0,
    where the tangent alone leaves Newton outside its basin on the hinges (cross-spring pivot, 11.25 deg:
    no convergence from the tangent, 4 iterations from the parabola; tests/test_hermite.py).
    """
    if eq.stroke != 0.0 or sys.n_con:
        raise ValueError("path_curvature is derived at the stress-free reference without rigid deformations")
    t = np.asarray(eq.tangent, dtype=float)
    f = sys.free
    rhs = np.asfortranarray(-(sys.hessian_derivative(eq.state, t) @ t)[f][:, None])
    sol, info = _solve(sys.free_block(eq.ev.H), rhs)
    if info > 0:
        raise np.linalg.LinAlgError(f"singular tangent stiffness (LAPACK dgesv info {info})")
    out = np.zeros(sys.n)
    out[f] = sol[:, 0]
    return out


def predict(sys: System, eq: Equilibrium, ds: float, prev: Equilibrium | None,
            curvature: np.ndarray | None = None) -> State:
    """Predictor from a converged point ``eq`` to the stroke ``eq.stroke + ds``.

    With a previous point, the cubic Hermite extrapolation through both points and both tangents
    (error O(h^4), so that after one Newton correction the increment is usually at the rounding level
    and the ``polish`` criterion costs no extra iteration); otherwise the tangent step, plus
    ``curvature ds^2 / 2`` when the path's second derivative at ``eq`` is given (:func:`path_curvature`).
    """
    step = eq.tangent * ds
    if curvature is not None and prev is None:
        step = step + 0.5 * ds**2 * curvature
    dlam = eq.extra["dlam_ds"] * ds if sys.n_con else None
    if prev is not None and prev.stroke != eq.stroke:
        # p(s) = x1 + t1 s + a s^2 + b s^3 through (x0, t0) at s = -h and (x1, t1) at s = 0
        h = eq.stroke - prev.stroke
        delta = sys.difference(eq.state, prev.state)
        t0, t1 = prev.tangent, eq.tangent
        b = (t0 + t1 - 2.0 * delta / h) / h**2
        a = (t1 * h - delta) / h**2 + b * h
        step = step + a * ds**2 + b * ds**3
    return sys.update(eq.state, step, dlam)


@dataclass
class WalkFailure:
    """Why the continuation stopped before the last requested stroke value."""

    reason: str  # "divergence" | "unstable"
    stroke: float  # internal units: where equilibrium was lost (estimate)
    last_converged: float
    message: str


def walk(sys: System, targets: np.ndarray, opts: NewtonOptions, accept,
         start: Equilibrium | None = None, on_step=None, curvature: np.ndarray | None = None) -> WalkFailure | None:
    """Continue from the reference through ``targets`` (internal units, monotone away from 0).

    ``start`` is the equilibrium at stroke 0 when the caller has it already; ``on_step(eq)``, when given,
    sees every converged step, targets and intermediate strokes alike; ``curvature``: the path's second
    derivative at ``start`` (:func:`path_curvature`), for the predictor of the steps from it.

    ``accept(eq)`` is called at each target and returns ``None`` to go on, or a :class:`WalkFailure` to
    stop (e.g. the equilibrium became unstable). Returns the failure, or ``None`` when all converged.
    """
    cur = start if start is not None else solve_point(sys, sys.reference_state(), 0.0, opts, 0.0)
    prev: Equilibrium | None = None
    for s_t in targets:
        h = s_t - cur.stroke
        halvings = 0
        full = abs(h) if h != 0 else 1.0
        while cur.stroke != s_t:
            remaining = s_t - cur.stroke
            if abs(h) >= abs(remaining) * (1 - 1e-12):
                h, s_new = remaining, s_t
            else:
                s_new = cur.stroke + h
            try:
                new = solve_point(sys, predict(sys, cur, h, prev, curvature), s_new, opts, cur.stroke)
            except StepFailure as exc:
                halvings += 1
                h /= 2.0
                if halvings > opts.max_halvings:
                    return WalkFailure(
                        "divergence", cur.stroke + 2 * h, cur.stroke,
                        f"no equilibrium found beyond stroke {cur.stroke:.6g}: Newton failed with steps down "
                        f"to {abs(2 * h):.3g} ({exc}); a limit point, snap-through or loss of equilibrium",
                    )
                continue
            prev, cur = cur, new
            if on_step is not None:
                on_step(new)
            if abs(h) < full:
                h = np.sign(h) * min(2 * abs(h), full)
        failure = accept(cur)
        if failure is not None:
            return failure
    return None
