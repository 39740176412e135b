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

import ctypes
from dataclasses import dataclass, field

import numpy as np

from . import linalg
from .assembly import ASSEMBLE_SLOTS, Assembled, State, System, function_address
from .elements import beam_spec
from .kernels import c_enum
from .lapack import routines

__all__ = ["NewtonOptions", "Equilibrium", "solve_point", "StepFailure", "path_curvature", "reference_equilibrium"]


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


def _scaled_residual(sys: System, ev: Assembled, dval: float, s_target: float, lam: np.ndarray | None = None) -> float:
    """Largest Jacobi-scaled residual: |g_i| / (|H_ii| l_i), the drive mismatch and rigid deformations.

    With loads (model.loads) the denominator is ``|H_ii| l_i + |p_i| + sum_k |G_ki lam_k|``, ``p`` the loads'
    part of ``g`` and ``lam`` the multipliers: a load carried by rigid deformations (a column whose
    elongation is rigid: ``H_ii`` along its axis only geometric) balances to the rounding of the forces that
    meet at the DOF, not of ``|H_ii| l_i``."""
    free = sys.free
    diag = np.abs(ev.H.diagonal()[free])
    dscale = np.maximum(diag, 1e-12 * max(diag.max(initial=0.0), 1e-300))
    den = dscale * sys.scale_free
    if ev.g_load is not None:
        den = den + np.abs(ev.g_load[free])
        if lam is not None and len(lam):
            den = den + (np.abs(lam) @ np.abs(ev.G))[free]
    res = float(np.max(np.abs(ev.g[free]) / den, initial=0.0))
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


def _newton_step(
    sys: System, ev: Assembled, dd: np.ndarray, rhs_drive: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Solve the Newton system for the correction and the path tangent.

    The Jacobian of the free rows is ``H + chart`` (the Hessian plus ``-1/2 skew(g)`` on rotation blocks,
    see ``System.chart_correction``): exact, so Newton converges quadratically even under a large drive
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
        if ev.dg_ds is not None:  # loads given per stroke point (model.loads): H t = -dg/ds
            rhs[:, 1] -= ev.dg_ds[f]
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
    if ev.dg_ds is not None:
        b[: len(f), 1] = -ev.dg_ds[f]
    sol, info = _solve(J, b)
    if info > 0:
        raise np.linalg.LinAlgError(f"singular Newton matrix (LAPACK dgesv info {info})")
    return sol[:n, 0], sol[n:, 0], sol[:n, 1], sol[n:, 1]


def _compiled_step(sys: System, ns, ev: Assembled, st: State, s_target: float, near: float):
    """:func:`_newton_step`, the drive and :func:`_scaled_residual` in one C call; raises like them."""
    rotation = sys.s.drive_kind == "rotation"
    dval = 0.0 if rotation else sys.drive_value(st, near=near)
    dxi, tan, sc = linalg.newton(
        ns, ev.H, ev.chart, ev.g, st.R[sys.s.drive_master] if rotation else None, near, s_target, dval
    )
    if sc[3] != 1.0:
        raise StepFailure("non-finite residual")
    if sc[4] > 0:
        what = "singular tangent stiffness" if sc[5] else "singular Newton matrix"
        lu = "dgbtrf" if ns.bands["reduced" if sc[5] else "bordered"] else "dgetrf"
        raise StepFailure(f"singular tangent ({what} (LAPACK {lu} info {int(sc[4])}))")
    return dxi, tan, sc


#: One whole Newton solve in C (model/native/newton_point.c: :func:`solve_point`'s loop, with the predictor of
#: :func:`predict` in front when asked): per iteration the evaluation (model/native/assemble.c's ``assemble``
#: through its pointer, the rotated node offsets of :func:`model.assembly.rotate` and the chart entries of
#: ``System.chart_correction``), the Newton system (model.linalg's ``newton``), the convergence tests of
#: :func:`solve_point` in its order and the update (``update_state``). The same operations in the same order as the
#: Python loop over the compiled steps, so the same numbers to the bit (tests/test_linalg.py); what it saves is the
#: Python between them: at the templates' sizes the wrappers cost more than the C work of an iteration. ``ctx``:
#: one int64 per slot of this list, in its order, from :meth:`model.assembly.NativeRoute.point_parts` and the
#: Newton system: the one list of them, which the C source sees as an enum of the same names upper-cased
#: (:func:`loop_source_definitions`). Output ``out``: the accepted state ``X`` (3 nm), ``R`` (9 nm), the tangent
#: (n), ``info`` (8: status, iterations, dval, inc, res and two status numbers) and the assembled numbers
#: (:meth:`model.assembly.NativeRoute.assembled_at`). Status: 0 converged, 1 the element kernel or 2 the update
#: kernel reported an error, 3 non-finite residual, 4 singular (LAPACK info, reduced form), 5 non-finite
#: increment, 6 diverging (inc), 7 not converging (inc, the one two iterations before), 8 no convergence
#: (inc, res), 9 the predictor met a relative rotation near pi (the caller predicts in Python).
LOOP_SLOTS = (
    "assemble",
    *ASSEMBLE_SLOTS,
    "update",
    "rot_update",
    "masters",
    "act",
    "moving",
    "nmov",
    "rin",
    "rout",
    "nchart",
    "chart_flat",
    "chart_src",
    "chart_sign",
    "chart",
    "rot_log",
    "log_in",
    "log_out",
    "drive_master",
    "kind",
    "master_pos",
    "axis",
    "n_act",
    "newton",
    "ip",
    "dp",
    "j_work",
    "b_work",
    "ipiv",
    "fp",
    "sc",
    "eye",
    "x_work",
    "r_work",
    "dxi",
    "step",
)
#: The most Newton iterations the compiled loop keeps increments for (``LOOP_MAX_ITER`` of its source, defined
#: from this): options asking for more take the Python loop.
_LOOP_MAX_ITER = 62
_LOOP: list = []


def loop_source_definitions() -> tuple[tuple[tuple[str, int]], str]:
    """What model/native/newton_point.c needs defined before it: ``LOOP_MAX_ITER`` (:data:`_LOOP_MAX_ITER`) and
    the enum of :data:`LOOP_SLOTS`."""
    return (("LOOP_MAX_ITER", _LOOP_MAX_ITER),), c_enum(LOOP_SLOTS, "loop_slot")


def _loop_function():
    """The compiled model/native/newton_point.c entry (cached like the kernels), or None without a C compiler."""
    if not _LOOP:
        import ctypes

        from .errors import KernelBuildError
        from .kernels import native_library

        try:
            fn = native_library("flexopt_newton_point", "newton_point.c", *loop_source_definitions()).newton_point
            fn.restype = ctypes.c_longlong
            fn.argtypes = [ctypes.c_void_p] * 6
            _LOOP.append(fn)
        except KernelBuildError:
            _LOOP.append(None)
    return _LOOP[0]


class _PointLoop:
    """One system's compiled Newton loop (model/native/newton_point.c): its slots, work arrays and their addresses."""

    def __init__(self, sys: System, ns: linalg.NewtonSystem, point_parts: dict[str, int], fn) -> None:
        import ctypes

        parts = dict(point_parts)  # NativeRoute.point_parts()'s, completed here
        nm, n = parts["masters"], parts["n_act"]
        lib, table, _ = ns.drv
        self.work = [np.empty(6 * nm), np.empty(18 * nm), np.empty(max(n, 1)), np.empty(max(n, 1))]
        ip, dp, J, b, ipiv, sc, eye = ns.ptr
        parts.update(
            newton=function_address(lib.newton),
            ip=ip,
            dp=dp,
            j_work=J,
            b_work=b,
            ipiv=ipiv,
            fp=ctypes.addressof(table.table),
            sc=sc,
            eye=eye,
            **dict(zip(("x_work", "r_work", "dxi", "step"), (a.ctypes.data for a in self.work))),
        )
        if set(parts) != set(LOOP_SLOTS):
            raise ValueError(f"the loop's context has slots {sorted(set(parts) ^ set(LOOP_SLOTS))} on one side only")
        self.ctx = np.array([parts[k] for k in LOOP_SLOTS], dtype=np.int64)
        self.opt = np.zeros(12)
        self.pred = np.zeros(5, dtype=np.int64)
        self.fn, self.ns, self.sys = fn, ns, sys
        self.at = (self.ctx.ctypes.data, self.opt.ctypes.data, self.pred.ctypes.data)
        N, no = parts["n_ext"], parts["ne"] * parts["n_out"]
        self.nm, self.n, self.size = nm, n, 12 * nm + n + 8 + no + N + parts["n_full"] + N * N

    def solve(
        self,
        X0: int,
        R0: int,
        s_target: float,
        opts: NewtonOptions,
        near: float,
        pred: tuple[int, int, int, int, int] | None = None,
        ds: float = 0.0,
        h: float = 0.0,
    ) -> Equilibrium:
        """Newton from the state at addresses ``X0``, ``R0`` (or from the predictor's state off it, ``pred``: the
        addresses of newton_point.c's predictor) to the equilibrium at ``s_target``; raises as
        :func:`solve_point` does."""
        o = self.opt
        o[0], o[1], o[2], o[3], o[4], o[5] = s_target, near, opts.tol, opts.polish, opts.max_iter, CONTRACTION
        if pred is not None:
            o[7], o[8], o[9], o[10], o[11] = ds, ds**2, ds**3, h, h**2
            self.pred[:] = pred
        out = np.empty(self.size)
        at = out.ctypes.data
        status = self.fn(self.at[0], self.at[1], X0, R0, None if pred is None else self.at[2], at)
        nm, n = self.nm, self.n
        info = out[12 * nm + n : 12 * nm + n + 8]
        if status:
            raise _loop_failure(self, int(status), info, opts)
        st = State(out[: 3 * nm].reshape(nm, 3), out[3 * nm : 12 * nm].reshape(nm, 3, 3), np.zeros(0))
        sys = self.sys
        return Equilibrium(
            stroke=s_target,
            state=st,
            ev=sys.native.assembled_at(out[12 * nm + n + 8 :]),
            free=sys.free,
            tangent=out[12 * nm : 12 * nm + n],
            iterations=int(info[1]),
            residual=float(info[4]),
            increment=float(info[3]),
            extra={"drive_dof": sys.drive, "dlam_ds": np.zeros(0), "at": at},
        )


def _loop_failure(pl: _PointLoop, status: int, info: np.ndarray, opts: NewtonOptions) -> Exception:
    """The exception :func:`solve_point` raises for a status of the compiled loop (the same messages)."""
    inc, res = float(info[3]), float(info[4])
    if status == 1:
        from .errors import KernelBuildError

        # the name of System.beam_kernel (compiled from this spec)
        return KernelBuildError(f"kernel '{beam_spec()[0].name}' reported an evaluation error")
    if status == 2:
        from .errors import KernelBuildError

        return KernelBuildError("the rotation update kernel reported an evaluation error")
    if status == 3:
        return StepFailure("non-finite residual")
    if status == 4:
        reduced = bool(info[6])
        what = "singular tangent stiffness" if reduced else "singular Newton matrix"
        lu = "dgbtrf" if pl.ns.bands["reduced" if reduced else "bordered"] else "dgetrf"
        return StepFailure(f"singular tangent ({what} (LAPACK {lu} info {int(info[5])}))")
    if status == 5:
        return StepFailure("non-finite increment")
    if status == 9:
        return _NearPi()
    if status == 6:
        return StepFailure(f"diverging (increment {inc:.3g})")
    if status == 7:
        return StepFailure(f"not converging (increment {inc:.3g}, {float(info[5]):.3g} two iterations before)")
    return StepFailure(f"no convergence in {opts.max_iter} iterations (increment {inc:.3g}, residual {res:.3g})")


def _point_loop(sys: System, opts: NewtonOptions) -> _PointLoop | None:
    """The compiled Newton loop of ``sys`` (cached on ``sys.native.point_loop``), or None where the Python loop applies (no compiled
    Newton system or evaluate/update, no C compiler, or more than :data:`_LOOP_MAX_ITER` iterations asked)."""
    native = sys.native
    if native.assemble_call is None or native.update_call is None:  # the compiled routes switched off (tests, bench)
        return None
    if opts.max_iter > _LOOP_MAX_ITER:
        return None
    if native.point_loop is False:
        pl = None
        ns = native.newton_system()
        point_parts = native.point_parts()
        if ns is not None and point_parts is not None:
            fn = _loop_function()
            if fn is not None:
                pl = _PointLoop(sys, ns, point_parts, fn)
        native.point_loop = pl
    # built above, a _PointLoop or None; NativeRoute holds it as an object (model.assembly cannot import this module)
    built = native.point_loop
    return built if isinstance(built, _PointLoop) else None


def _advance(
    sys: System,
    cur: Equilibrium,
    ds: float,
    prev: Equilibrium | None,
    curvature: np.ndarray | None,
    s_new: float,
    opts: NewtonOptions,
) -> Equilibrium:
    """``solve_point(sys, predict(sys, cur, ds, prev, curvature), s_new, opts, cur.stroke)``, predictor and
    Newton in one C call where the compiled loop applies and both points came from it (their arrays' addresses
    are known); the same numbers either way."""
    pl = _point_loop(sys, opts)
    at = cur.extra.get("at") if pl is not None else None
    back = prev if prev is not None and prev.stroke != cur.stroke else None  # the cubic predictor's earlier point
    if pl is not None and at is not None and (back is None or back.extra.get("at") is not None):
        nm8 = 8 * pl.nm
        if back is not None:
            p = back.extra["at"]
            pred = (at + 12 * nm8, 0, p, p + 3 * nm8, p + 12 * nm8)
        else:
            if curvature is not None:  # referenced here until the call returns
                curvature = np.ascontiguousarray(curvature, dtype=np.float64)
            pred = (at + 12 * nm8, 0 if curvature is None else curvature.ctypes.data, 0, 0, 0)
        try:
            return pl.solve(
                at,
                at + 3 * nm8,
                s_new,
                opts,
                cur.stroke,
                pred,
                ds,
                cur.stroke - back.stroke if back is not None else 0.0,
            )
        except _NearPi:
            pass  # a relative rotation near pi: the quaternion route of System.difference, in Python
    return solve_point(sys, predict(sys, cur, ds, prev, curvature), s_new, opts, cur.stroke)


class _NearPi(Exception):
    """The compiled predictor met a relative rotation near pi (status 9): predict in Python instead."""


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
    if sys.loads is not None:
        sys.load_stroke = s_target  # loads given per stroke point take their value there (model.loads)
    pl = _point_loop(sys, opts)
    if pl is not None:  # the whole loop below in one C call (model/native/newton_point.c), the same numbers
        X = np.ascontiguousarray(start.X, dtype=np.float64)
        R = np.ascontiguousarray(start.R, dtype=np.float64)
        return pl.solve(X.ctypes.data, R.ctypes.data, s_target, opts, theta_near)
    st = start
    inc = res = float("nan")
    incs: list[float] = []  # the increments of the iterations so far
    ns = sys.native.newton_system()
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
            res = _scaled_residual(sys, ev, dval, s_target, st.lam)
        if not np.isfinite(inc):
            raise StepFailure("non-finite increment")
        stalled = bool(incs) and inc > 0.25 * incs[-1]
        if res <= opts.tol and (inc <= opts.polish or (inc <= opts.tol and stalled)):
            return Equilibrium(
                stroke=s_target,
                state=st,
                ev=ev,
                free=sys.free,
                tangent=tan,
                iterations=it,
                residual=res,
                increment=inc,
                extra={"drive_dof": sys.drive, "dlam_ds": dlam_ds},
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


def _pbsv(ab: np.ndarray, b: np.ndarray) -> np.ndarray | None:
    """``A x = b`` for a symmetric positive definite band ``A`` in upper band storage ``ab`` ((kd + 1, n),
    ``ab[kd + i - j, j] = A[i, j]``, as ``scipy.linalg.solveh_banded`` takes it) by LAPACK's dpbsv (banded
    Cholesky); None when ``A`` is not positive definite. Through the LAPACK that model.lapack found (numpy's
    OpenBLAS), else scipy.linalg.solveh_banded, which calls the same routine."""
    table = routines()
    addr = None if table is None else table.address("dpbsv")
    if table is None or addr is None:
        from scipy.linalg import solveh_banded

        try:
            return solveh_banded(ab, b, check_finite=False)
        except np.linalg.LinAlgError:
            return None
    I = ctypes.c_longlong if table.int_type == "long long" else ctypes.c_int
    P = ctypes.c_void_p
    fn = ctypes.CFUNCTYPE(None, ctypes.c_char_p, P, P, P, P, P, P, P, P)(addr)
    A = np.asfortranarray(ab, dtype=np.float64).copy(order="F")  # dpbsv overwrites it with the factor
    x = np.array(b, dtype=np.float64, order="F")
    kd1, n = A.shape
    n_, kd_, one, ldab, info = I(n), I(kd1 - 1), I(1), I(kd1), I(0)
    fn(
        b"U",
        ctypes.byref(n_),
        ctypes.byref(kd_),
        ctypes.byref(one),
        A.ctypes.data,
        ctypes.byref(ldab),
        x.ctypes.data,
        ctypes.byref(n_),
        ctypes.byref(info),
    )
    return x if info.value == 0 else None


def reference_equilibrium(sys: System, opts: NewtonOptions) -> Equilibrium:
    """The equilibrium at stroke 0 from the reference configuration.

    Without loads the reference is stress-free and this is one Newton solve. With loads or gravity
    (model.loads) the loads are raised from 0 to their value at stroke 0 (``System.load_scale`` 0 -> 1),
    each step from the last converged state with its tangent ``d xi / d scale = -H_ff^-1 g_load`` as
    predictor (the derivative of ``g_f = 0`` in the load scale, the drive held), halving a step that Newton
    cannot finish (SPACAR's ITERSTEP load steps, with step control). Raises :class:`StepFailure` when a
    step falls below ``2^-max_halvings`` of the first (a quarter of the range): a limit load (e.g. the loads exceed a buckling or
    snap-through load).
    """
    if sys.loads is None:
        return solve_point(sys, sys.reference_state(), 0.0, opts, 0.0)
    sys.load_scale = 1.0
    try:  # most loads need no steps: Newton straight from the reference
        return solve_point(sys, sys.reference_state(), 0.0, opts, 0.0)
    except StepFailure:
        pass
    lam, h = 0.0, 0.25
    sys.load_scale = 0.0
    cur = solve_point(sys, sys.reference_state(), 0.0, opts, 0.0)
    try:
        while lam < 1.0:
            step = min(h, 1.0 - lam)
            f = sys.free
            sys.load_scale = 1.0  # the loads' gradient at scale 1 minus the elastic part: g_load
            g1 = sys.evaluate(cur.state).g
            sys.load_scale = lam
            g0 = sys.evaluate(cur.state).g
            dg = (g1 - g0) / (1.0 - lam)  # g is affine in the scale: exact
            xi = np.zeros(sys.n)
            # the exact Newton matrix H + chart (the chart term matters where the loads leave a moment on a
            # supported or driven rotation, and under non-conservative loads)
            A = cur.ev.H if cur.ev.chart is None else cur.ev.H + cur.ev.chart
            try:
                xi[f] = np.linalg.solve(sys.free_block(A), -dg[f]) * step
            except np.linalg.LinAlgError:
                xi[:] = 0.0
            sys.load_scale = lam + step
            try:
                cur = solve_point(sys, sys.update(cur.state, xi), 0.0, opts, 0.0)
                lam += step
                h = min(2 * h, 0.25)
            except StepFailure as exc:
                h /= 2
                if h < 0.25 * 2.0**-opts.max_halvings:
                    raise StepFailure(
                        f"the loads could not be applied beyond {lam:.4g} of their value at stroke "
                        f"0 ({exc}): a limit load (buckling or snap-through under the loads)"
                    ) from exc
    finally:
        sys.load_scale = 1.0
    return cur


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
    rhs = -(sys.hessian_derivative(eq.state, t) @ t)[f]
    K = sys.free_block(eq.ev.H)
    out = np.zeros(sys.n)
    band = sys.eigen_band(True)
    if band is not None:
        # the reference stiffness is symmetric positive definite (a stable reference): banded Cholesky (dpbsv)
        # in the eigen problem's band order, O(n kd^2) where the dense LU below is O(n^3) (double cross hinge,
        # order 179: the whole curvature 400 -> 265 us); LAPACK's dpbsv called directly (_pbsv: importing
        # scipy.linalg for solveh_banded cost a cold process 0.2-1 s, issue 26 item 2)
        perm, kd = band
        m = len(perm)
        got = sys.curvature_band
        if got is None or got[0] is not band:  # upper band storage ab[kd - u, j] = K[perm[j - u], perm[j]]
            j, u = np.meshgrid(np.arange(m), np.arange(kd + 1))
            ok = j - u >= 0
            src = perm[(j - u)[ok]] * m + perm[j[ok]]  # flat index into K (free order)
            got = sys.curvature_band = (band, src, ((kd - u) * m + j)[ok])
        ab = np.zeros((kd + 1, m))
        ab.flat[got[2]] = K.flat[got[1]]
        x = _pbsv(ab, rhs[perm])
        if x is not None:
            out[f[perm]] = x
            return out
        # not positive definite: the LU below says whether it is singular
    sol, info = _solve(K, np.asfortranarray(rhs[:, None]))
    if info > 0:
        raise np.linalg.LinAlgError(f"singular tangent stiffness (LAPACK dgesv info {info})")
    out[f] = sol[:, 0]
    return out


def predict(
    sys: System, eq: Equilibrium, ds: float, prev: Equilibrium | None, curvature: np.ndarray | None = None
) -> State:
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


def walk(
    sys: System,
    targets: np.ndarray,
    opts: NewtonOptions,
    accept,
    start: Equilibrium | None = None,
    on_step=None,
    curvature: np.ndarray | None = None,
) -> WalkFailure | None:
    """Continue from the reference through ``targets`` (internal units, monotone away from 0).

    ``start`` is the equilibrium at stroke 0 when the caller has it already; ``on_step(eq)``, when given,
    sees every converged step, targets and intermediate strokes alike; ``curvature``: the path's second
    derivative at ``start`` (:func:`path_curvature`), for the predictor of the steps from it.

    ``accept(eq)`` is called at each target and returns ``None`` to go on, or a :class:`WalkFailure` to
    stop (e.g. the equilibrium became unstable). Returns the failure, or ``None`` when all converged.
    """
    cur = start if start is not None else reference_equilibrium(sys, opts)
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
                new = _advance(sys, cur, h, prev, curvature, s_new, opts)
            except StepFailure as exc:
                halvings += 1
                h /= 2.0
                if halvings > opts.max_halvings:
                    return WalkFailure(
                        "divergence",
                        cur.stroke + 2 * h,
                        cur.stroke,
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
