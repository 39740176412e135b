"""The one place that creates element symbols: the SPACAR spatial beam and the truss, in CasADi.

Configuration and increments
----------------------------
Every element end is a node carried by a *master* (the node itself, or a rigid body). A master's state
is a position ``x`` and a rotation matrix ``R`` (no angles are stored, so nothing is singular at any
stroke). Increments are taken in the exponential chart at the current state:

    x_node(d) = x* + u + (exp(psi) - I) r,       R_node(d) = exp(psi) R*,

with ``u`` the master's translation, ``psi`` its *spatial* rotation vector (so ``d psi / dt`` is the
angular velocity) and ``r`` the node's current offset from its master. Kernels return values and exact
derivatives at ``d = 0``; the solver then updates ``R <- expm(psi) R`` exactly. Because only derivatives
at ``d = 0`` up to third order are needed, ``exp(psi)`` is replaced by its cubic Taylor polynomial, which
has the same first, second and third derivatives at 0 and keeps the expressions free of ``sqrt(psi.psi)``.

Deformations (seed 002, eq. 2; Jonker and Meijaard 2009)
-------------------------------------------------------
``eps1`` elongation, ``eps2`` torsion, ``eps3, eps4`` bending about local y, ``eps5, eps6`` bending about
local z, with second-order terms and the torsion-elongation coupling ``c_t = (Iy + Iz)/A``.

Constitutive stiffness (Jonker and Meijaard; shared/PHYSICS.md)
--------------------------------------------------------------
``sigma = S eps`` with ``S11 = EA/l0``, ``S22 = GJ/l0^3``, ``S[3:5,3:5] = EIy/l0^3 [[4,-2],[-2,4]]``,
``S[5:7,5:7] = EIz/l0^3 [[4,-2],[-2,4]]``; a circular arc of curvature kappa gives eps3 = eps4 =
kappa l0^2/2 and energy EI kappa^2 l0/2. With SPACAR's shear flexibility ``S_y = EIy / (k G A)`` (``ESTIFF``;
a general section's ``shear_y``) and ``phi = 12 S_y / l0^2``, the bending block is Timoshenko's,
``EIy / (l0^3 (1 + phi)) [[4 + phi, -(2 - phi)], [-(2 - phi), 4 + phi]]``: a beam's end rotations relative to
its chord under end moments with shear deformation (Przemieniecki 1968, ch. 5, the beam element with shear deformation), which leaves the
symmetric mode (eps3 = eps4, uniform curvature: 2 EIy/l0^3) alone and softens the antisymmetric one (eps3 =
-eps4, shear force along the beam) from 6 EIy/l0^3 to 6 EIy/(l0^3 (1 + phi)); likewise ``S_z`` for eps5,
eps6. The element energy is the Lagrangian

    L = 1/2 (m * eps)^T S (m * eps) + lambda^T ((1 - m) * eps),

with ``m`` the mask of flexible deformations and ``lambda`` the multipliers (generalised stresses) of the
rigid ones, so a rigid deformation is an exact constraint, not a penalty.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from typing import overload

import casadi as ca

__all__ = [
    "KernelSpec",
    "beam_spec",
    "truss_spec",
    "BEAM_CONST",
    "TRUSS_CONST",
    "beam_input_jvp",
    "beam_segment_design",
    "beam_von_mises",
    "beam_von_mises_squared",
    "rotation_update_spec",
    "rotation_log_spec",
    "beam_mass_spec",
    "beam_mass_jvp_spec",
    "HERMITE_MASS",
    "point_load_spec",
    "beam_gravity_spec",
    "POINT_LOAD_IN",
    "BEAM_GRAVITY_IN",
    "load_jvp_spec",
    "joint_spec",
    "JOINT_CONST",
]

# Layout of a beam's packed input vector.
BEAM_STATE = 30  # xp(3) Rp(9, column-major) rp(3) xq(3) Rq(9) rq(3)
BEAM_CONST = 23  # l0, E0 (9, columns ex ey ez of the local frame in node axes), k1 k2 ky kz, ct, mask(6), phi_y phi_z
TRUSS_STATE = 12  # xp(3) rp(3) xq(3) rq(3)
TRUSS_CONST = 3  # l0, k1, mask


@dataclass(frozen=True)
class KernelSpec:
    """A CasADi function of one element with a flat input and a flat output.

    The main kernel takes ``a = [state, const, lam]`` and returns ``[g(12), H(144, column-major), e(ne),
    De(ne*12)]``; the third-derivative kernel takes ``[state, const, lam, v]`` and returns ``dH`` (144),
    the directional derivative of ``H`` along the increment direction ``v`` (used by modal derivatives).
    """

    name: str
    function: ca.Function
    n_in: int
    n_out: int
    n_def: int  # deformation parameters per element
    n_state: int
    n_const: int


def _skew(v: ca.SX) -> ca.SX:
    return ca.vertcat(
        ca.horzcat(0, -v[2], v[1]),
        ca.horzcat(v[2], 0, -v[0]),
        ca.horzcat(-v[1], v[0], 0),
    )


def _expm3(psi: ca.SX) -> ca.SX:
    """Cubic Taylor polynomial of the rotation exponential: exact derivatives at 0 up to third order."""
    S = _skew(psi)
    S2 = S @ S
    return ca.SX.eye(3) + S + S2 / 2 + (S2 @ S) / 6


@overload
def _end(x0: ca.SX, R0: ca.SX, r: ca.SX, u: ca.SX, psi: ca.SX) -> tuple[ca.SX, ca.SX]: ...
@overload
def _end(x0: ca.SX, R0: None, r: ca.SX, u: ca.SX, psi: ca.SX) -> tuple[ca.SX, None]: ...
def _end(x0: ca.SX, R0: ca.SX | None, r: ca.SX, u: ca.SX, psi: ca.SX) -> tuple[ca.SX, ca.SX | None]:
    """The displaced end point and, when the reference orientation ``R0`` is given, the end's orientation."""
    E = _expm3(psi)
    x = x0 + u + (E - ca.SX.eye(3)) @ r
    R = E @ R0 if R0 is not None else None
    return x, R


def _beam_deformations(xp, Rp, xq, Rq, l0, E0, ct) -> ca.SX:
    """The six deformation parameters of seed 002, eq. 2."""
    dx = xq - xp
    l = ca.sqrt(ca.dot(dx, dx))
    el = dx / l
    tp = Rp @ E0
    tq = Rq @ E0
    eyp, ezp = tp[:, 1], tp[:, 2]
    eyq, ezq = tq[:, 1], tq[:, 2]
    b1 = l - l0
    b2 = l0 * (ca.dot(ezp, eyq) - ca.dot(eyp, ezq)) / 2
    b3 = -l0 * ca.dot(el, ezp)
    b4 = l0 * ca.dot(el, ezq)
    b5 = l0 * ca.dot(el, eyp)
    b6 = -l0 * ca.dot(el, eyq)
    e1 = b1 + (2 * b3**2 + b3 * b4 + 2 * b4**2 + 2 * b5**2 + b5 * b6 + 2 * b6**2) / (30 * l0) + ct * b2**2 / (2 * l0**3)
    e2 = b2 + (-b3 * b6 + b4 * b5) / l0
    e3 = b3 + b2 * (b5 + b6) / (6 * l0)
    e4 = b4 - b2 * (b5 + b6) / (6 * l0)
    e5 = b5 - b2 * (b3 + b4) / (6 * l0)
    e6 = b6 + b2 * (b3 + b4) / (6 * l0)
    return ca.vertcat(e1, e2, e3, e4, e5, e6)


def _bending(kb: ca.SX, phi: ca.SX, a: ca.SX, b: ca.SX) -> ca.SX:
    """Twice the bending energy of one plane: ``kb (a, b) [[4 + phi, phi - 2], [phi - 2, 4 + phi]] (a, b)^T /
    (1 + phi)`` (the module docstring; Euler-Bernoulli at ``phi = 0``)."""
    return kb * ((4 + phi) * (a**2 + b**2) + 2 * (phi - 2) * a * b) / (1 + phi)


def _beam_energy(e: ca.SX, k: ca.SX, mask: ca.SX, lam: ca.SX, phi: ca.SX) -> ca.SX:
    k1, k2, ky, kz = k[0], k[1], k[2], k[3]
    f = mask * e
    U = 0.5 * (k1 * f[0] ** 2 + k2 * f[1] ** 2 + _bending(ky, phi[0], f[2], f[3]) + _bending(kz, phi[1], f[4], f[5]))
    return U + ca.dot(lam, (1 - mask) * e)


def _finish(
    name: str,
    a: ca.SX,
    d: ca.SX,
    v: ca.SX,
    L: ca.SX,
    e: ca.SX,
    n_def: int,
    n_state: int,
    n_const: int,
    dense: bool = False,
) -> tuple[KernelSpec, KernelSpec]:
    g = ca.gradient(L, d)
    H = ca.jacobian(g, d)
    De = ca.jacobian(e, d)
    zero = ca.DM.zeros(12)
    out = ca.substitute(ca.vertcat(g, ca.vec(H), e, ca.vec(De)), d, zero)  # needed at d = 0 only
    dH = ca.substitute(ca.vec(ca.hessian(ca.jtimes(L, d, v), d)[0]), d, zero)
    if dense:  # the batch wrapper writes nonzeros only: a kernel with structural zeros must be densified
        out, dH = ca.densify(out), ca.densify(dH)
    f = ca.Function(name, [a], [out], ["a"], ["out"])
    av = ca.vertcat(a, v)
    f3 = ca.Function(name + "_d3", [av], [dH], ["a"], ["out"])
    return (
        KernelSpec(name, f, a.numel(), out.numel(), n_def, n_state, n_const),
        KernelSpec(name + "_d3", f3, av.numel(), 144, n_def, n_state, n_const),
    )


def _beam_expr() -> tuple[ca.SX, ca.SX, ca.SX, ca.SX]:
    """The beam's packed input ``a``, increment ``d``, Lagrangian ``L(a, d)`` and deformations ``e(a, d)``."""
    a = ca.SX.sym("a", BEAM_STATE + BEAM_CONST + 6)
    d = ca.SX.sym("d", 12)
    s, c = a[:BEAM_STATE], a[BEAM_STATE : BEAM_STATE + BEAM_CONST]
    lam = a[BEAM_STATE + BEAM_CONST : BEAM_STATE + BEAM_CONST + 6]
    xp0, Rp0, rp = s[0:3], ca.reshape(s[3:12], 3, 3), s[12:15]
    xq0, Rq0, rq = s[15:18], ca.reshape(s[18:27], 3, 3), s[27:30]
    l0, E0 = c[0], ca.reshape(c[1:10], 3, 3)
    k, ct, mask, phi = c[10:14], c[14], c[15:21], c[21:23]
    xp, Rp = _end(xp0, Rp0, rp, d[0:3], d[3:6])
    xq, Rq = _end(xq0, Rq0, rq, d[6:9], d[9:12])
    e = _beam_deformations(xp, Rp, xq, Rq, l0, E0, ct)
    return a, d, _beam_energy(e, k, mask, lam, phi), e


@cache
def beam_spec() -> tuple[KernelSpec, KernelSpec]:
    """The spatial beam kernels (main input: state 30, const 23, lam 6; third-derivative input adds v 12)."""
    a, d, L, e = _beam_expr()
    v = ca.SX.sym("v", 12)
    return _finish("flexopt_beam", a, d, v, L, e, 6, BEAM_STATE, BEAM_CONST)


@cache
def truss_spec() -> tuple[KernelSpec, KernelSpec]:
    """The truss kernels: elongation ``l - l0`` with stiffness ``EA/l0`` (state 12, const 3, lam 1; + v 12)."""
    a = ca.SX.sym("a", TRUSS_STATE + TRUSS_CONST + 1)
    v = ca.SX.sym("v", 12)
    d = ca.SX.sym("d", 12)
    s, c = a[:TRUSS_STATE], a[TRUSS_STATE : TRUSS_STATE + TRUSS_CONST]
    lam = a[TRUSS_STATE + TRUSS_CONST]
    xp, _ = _end(s[0:3], None, s[3:6], d[0:3], d[3:6])
    xq, _ = _end(s[6:9], None, s[9:12], d[6:9], d[9:12])
    dx = xq - xp
    e = ca.sqrt(ca.dot(dx, dx)) - c[0]
    mask = c[2]
    L = 0.5 * c[1] * (mask * e) ** 2 + lam * (1 - mask) * e
    return _finish("flexopt_truss", a, d, v, L, e, 1, TRUSS_STATE, TRUSS_CONST)


# ----------------------------------------------------------------- fourth-derivative kernel
def _expm4(psi: ca.SX) -> ca.SX:
    """Quartic Taylor polynomial of the rotation exponential: exact derivatives at 0 up to fourth order."""
    S = _skew(psi)
    S2 = S @ S
    return ca.SX.eye(3) + S + S2 / 2 + (S2 @ S) / 6 + (S2 @ S2) / 24


def _end4(x0: ca.SX, R0: ca.SX | None, r: ca.SX, u: ca.SX, psi: ca.SX) -> tuple[ca.SX, ca.SX | None]:
    E = _expm4(psi)
    return x0 + u + (E - ca.SX.eye(3)) @ r, (E @ R0 if R0 is not None else None)


def _d4(a: ca.SX, d: ca.SX, v: ca.SX, L: ca.SX, name: str) -> ca.Function:
    H = ca.hessian(L, d)[0]
    d2H = ca.jtimes(ca.jtimes(H, d, v), d, v)
    out = ca.substitute(ca.vec(d2H), d, ca.DM.zeros(12))
    return ca.Function(name, [ca.vertcat(a, v)], [out])


@cache
def beam_d4() -> ca.Function:
    """Second directional derivative of a beam's Hessian, ``sum_kl d4L/(dxi_i dxi_j dxi_k dxi_l) v_k v_l``."""
    a = ca.SX.sym("a", BEAM_STATE + BEAM_CONST + 6)
    v, d = ca.SX.sym("v", 12), ca.SX.sym("d", 12)
    s, c = a[:BEAM_STATE], a[BEAM_STATE : BEAM_STATE + BEAM_CONST]
    lam = a[BEAM_STATE + BEAM_CONST :]
    xp, Rp = _end4(s[0:3], ca.reshape(s[3:12], 3, 3), s[12:15], d[0:3], d[3:6])
    xq, Rq = _end4(s[15:18], ca.reshape(s[18:27], 3, 3), s[27:30], d[6:9], d[9:12])
    e = _beam_deformations(xp, Rp, xq, Rq, c[0], ca.reshape(c[1:10], 3, 3), c[14])
    return _d4(a, d, v, _beam_energy(e, c[10:14], c[15:21], lam, c[21:23]), "flexopt_beam_d4")


@cache
def truss_d4() -> ca.Function:
    """Second directional derivative of a truss's Hessian (see :func:`beam_d4`)."""
    a = ca.SX.sym("a", TRUSS_STATE + TRUSS_CONST + 1)
    v, d = ca.SX.sym("v", 12), ca.SX.sym("d", 12)
    s, c = a[:TRUSS_STATE], a[TRUSS_STATE : TRUSS_STATE + TRUSS_CONST]
    lam = a[TRUSS_STATE + TRUSS_CONST]
    xp, _ = _end4(s[0:3], None, s[3:6], d[0:3], d[3:6])
    xq, _ = _end4(s[6:9], None, s[9:12], d[6:9], d[9:12])
    dx = xq - xp
    e = ca.sqrt(ca.dot(dx, dx)) - c[0]
    L = 0.5 * c[1] * (c[2] * e) ** 2 + lam * (1 - c[2]) * e
    return _d4(a, d, v, L, "flexopt_truss_d4")


# ----------------------------------------------------------------- design sensitivities
@cache
def beam_input_jvp() -> ca.Function:
    """Directional derivative of a beam's ``g`` (12), ``H`` (144, column-major) and ``e`` (6) at ``d = 0``
    along a change ``da`` of its whole packed input (state, constants, multipliers).

    The state inputs are absolute (node positions, rotation matrices, offsets), and ``H`` is the Hessian in
    the chart *at* that state, so one derivative along ``da`` covers both a change of the design (the
    constants and reference offsets) and a move of the equilibrium, without any change of chart.
    Input ``[a, da]`` (2 x 59), output ``[dg, dH, de]`` (162).
    """
    a, d, L, e = _beam_expr()
    da = ca.SX.sym("da", a.numel())
    g = ca.gradient(L, d)
    out = ca.vertcat(g, ca.vec(ca.jacobian(g, d)), e)
    dout = ca.substitute(ca.jtimes(out, a, da), d, ca.DM.zeros(12))
    return ca.Function("flexopt_beam_jvp", [ca.vertcat(a, da)], [dout])


@cache
def beam_input_jvp_gradient() -> ca.Function:
    """The ``dg`` part (12) of :func:`beam_input_jvp` alone: the implicit-function step of the design
    sensitivities needs only the gradient's change, and the Hessian's is most of that kernel's work. The
    same forward derivative of the same expressions, so the same numbers (tests/test_design.py)."""
    a, d, L, _ = _beam_expr()
    da = ca.SX.sym("da", a.numel())
    dout = ca.substitute(ca.jtimes(ca.gradient(L, d), a, da), d, ca.DM.zeros(12))
    return ca.Function("flexopt_beam_jvp_g", [ca.vertcat(a, da)], [dout])


@cache
def beam_jvp_gradient_spec() -> KernelSpec:
    """:func:`beam_input_jvp_gradient` as a compiled kernel (input 114, output 12)."""
    f = beam_input_jvp_gradient()
    return KernelSpec("flexopt_beam_jvp_g", f, f.size1_in(0), f.size1_out(0), 6, BEAM_STATE, BEAM_CONST)


@cache
def beam_jvp_spec() -> KernelSpec:
    """:func:`beam_input_jvp` as a compiled kernel (input 114, output 162)."""
    f = beam_input_jvp()
    return KernelSpec("flexopt_beam_jvp", f, f.size1_in(0), f.size1_out(0), 6, BEAM_STATE, BEAM_CONST)


#: Layout of :func:`beam_segment_design`'s output: constants (l0, E0 9 column-major, k1, k2, ky, kz, ct),
#: mass, lumped rotary inertia (9), stress data (A, Iy, Iz, cy, cz, tau per torque, l0).
SEGMENT_OUT = 15 + 1 + 9 + 7
#: Continuous inputs of :func:`beam_segment_design`: p (3), q (3), y_axis (3), width, thickness, E, G, density.
SEGMENT_IN = 14


@cache
def beam_segment_design(warping: str) -> ca.Function:
    """Constants of a rectangular beam segment and their exact Jacobian with respect to the member's
    geometry, section and material: ``[x (14), n] -> [out (32), d out / d x (32 x 14)]``.

    Built from the same formulas the numeric model uses (:func:`model.sections.rectangular_properties`,
    :func:`model.sections.beam_segment`) evaluated on symbols, so numbers and derivatives cannot disagree.
    """
    from .sections import beam_segment, rectangular_properties

    x = ca.SX.sym("x", SEGMENT_IN)
    n = ca.SX.sym("n")
    p, q, y = x[0:3], x[3:6], x[6:9]
    w, t, E, G, rho = x[9], x[10], x[11], x[12], x[13]
    props = rectangular_properties(w, t, warping)
    seg = beam_segment(
        [p[i] for i in range(3)], [q[i] for i in range(3)], [y[i] for i in range(3)], props, E, G, rho, n
    )
    E0 = seg["E0"]
    rot = seg["rot"]
    # rectangular_properties gives a rectangle's fibre distances and shear stress per torque (never None)
    assert props.cy is not None and props.cz is not None and props.tau_per_torque is not None
    out = ca.vertcat(
        seg["l0"],
        *[E0[i][j] for j in range(3) for i in range(3)],
        seg["k1"],
        seg["k2"],
        seg["ky"],
        seg["kz"],
        props.ct,
        seg["mass"],
        *[rot[i][j] for j in range(3) for i in range(3)],
        props.A,
        props.Iy,
        props.Iz,
        props.cy,
        props.cz,
        props.tau_per_torque,
        seg["l0"],
    )
    assert out.numel() == SEGMENT_OUT
    return ca.Function("flexopt_segment_" + warping, [x, n], [out, ca.jacobian(out, x)])


def _von_mises_squared_expr() -> tuple[ca.SX, ca.SX]:
    z = ca.SX.sym("z", 13)
    sig, (A, Iy, Iz, cy, cz, tau, l0) = z[0:6], [z[6 + i] for i in range(7)]
    N = ca.fabs(sig[0]) / A
    T = ca.fabs(l0 * sig[1]) * tau
    ends = [
        (N + ca.fabs(l0 * sig[iy]) * cz / Iy + ca.fabs(l0 * sig[iz]) * cy / Iz) ** 2 + 3 * T**2
        for iy, iz in ((2, 4), (3, 5))
    ]
    return z, ca.vertcat(*ends)


def _von_mises_expr() -> tuple[ca.SX, ca.SX]:
    z, vm2 = _von_mises_squared_expr()
    return z, ca.sqrt(vm2)


@cache
def beam_von_mises() -> ca.Function:
    """Von Mises bound at both ends of a beam segment from its generalised stresses and section data.

    Input ``[sig (6), data (7: A, Iy, Iz, cy, cz, tau per torque, l0)]``; output the two end values and
    their Jacobian (2 x 13). End moments are ``l0 sig_3..6``, torque ``l0 sig_2``, axial force ``sig_1``;
    per end ``sqrt((|N|/A + |My| cz/Iy + |Mz| cy/Iz)^2 + 3 tau^2)``: the extreme normal stresses added to
    the largest torsional shear stress (conservative: they need not occur at the same fibre).
    """
    z, vm = _von_mises_expr()
    return ca.Function("flexopt_von_mises", [z], [vm, ca.jacobian(vm, z)])


@cache
def beam_von_mises_squared() -> ca.Function:
    """The square of :func:`beam_von_mises` at both segment ends and its Jacobian (2 x 13).

    Same input and formula (the square of the bound, before the root). Its gradient is finite everywhere,
    also where the stress vanishes (an unstressed design, the stroke's zero), where the root's gradient is
    ``0/0``: constraints on the stress use this form (``(sigma / sigma_allow)^2 <= 1``).
    """
    z, vm2 = _von_mises_squared_expr()
    return ca.Function("flexopt_von_mises_squared", [z], [vm2, ca.jacobian(vm2, z)])


@cache
def von_mises_spec() -> KernelSpec:
    """The values of :func:`beam_von_mises` as a compiled kernel (the curve evaluates it at every point)."""
    z, vm = _von_mises_expr()
    return KernelSpec("flexopt_von_mises_value", ca.Function("flexopt_von_mises_value", [z], [vm]), 13, 2, 6, 6, 7)


# ------------------------------------------------------------ rotation kernels (numeric use only)
@cache
def rotation_update_spec() -> KernelSpec:
    """``R_new = exp(skew(psi)) R`` per master: input ``[psi (3), R (9, column-major)]``, output R_new (9).

    Rodrigues' formula ``exp(S) = I + a S + b S^2``, ``a = sin t / t``, ``b = 2 sin^2(t/2) / t^2``
    (``t = |psi|``; the half-angle form avoids the cancellation of ``1 - cos t``), with the Taylor series of
    ``a`` and ``b`` below ``t = 1e-4`` (truncation error below 1e-17). Used by the Newton update, not
    differentiated (the elements use the Taylor polynomials above).
    """
    a = ca.SX.sym("a", 12)
    psi, R = a[:3], ca.reshape(a[3:], 3, 3)
    t2 = ca.dot(psi, psi)
    t = ca.sqrt(t2)
    small = t < 1e-4
    ts = ca.if_else(small, 1.0, t)
    ca_ = ca.if_else(small, 1.0 - t2 / 6.0, ca.sin(ts) / ts)
    h = ca.sin(0.5 * ts) / ts
    cb = ca.if_else(small, 0.5 - t2 / 24.0, 2.0 * h * h)
    S = _skew(psi)
    out = ca.reshape((ca.SX.eye(3) + ca_ * S + cb * (S @ S)) @ R, 9, 1)
    f = ca.Function("flexopt_rot_update", [a], [out])
    return KernelSpec("flexopt_rot_update", f, 12, 9, 0, 12, 0)


@cache
def rotation_log_spec() -> KernelSpec:
    """``psi = log(R Rb^T)`` per master: input ``[R (9), Rb (9)]`` (column-major), output ``[psi (3),
    angle (1)]``.

    ``A = R Rb^T``; ``psi = atan2(s, c) v / s`` with ``v = vee(A - A^T) / 2``, ``s = |v|`` (sine of the
    angle) and ``c = (tr A - 1) / 2``; ``psi = (1 + s^2 / 6) v`` below ``s = 1e-6``. Accurate for angles
    below about ``pi - 1e-3`` (the axis comes from the skew part, whose size is the sine): the caller
    re-does larger angles by the quaternion route (``angle`` returned for that check).
    """
    a = ca.SX.sym("a", 18)
    A = ca.reshape(a[:9], 3, 3) @ ca.reshape(a[9:], 3, 3).T
    v = 0.5 * ca.vertcat(A[2, 1] - A[1, 2], A[0, 2] - A[2, 0], A[1, 0] - A[0, 1])
    s = ca.norm_2(v)
    c = 0.5 * (A[0, 0] + A[1, 1] + A[2, 2] - 1.0)
    ang = ca.atan2(s, c)
    small = s < 1e-6
    fac = ca.if_else(small, 1.0 + s * s / 6.0, ang / ca.if_else(small, 1.0, s))
    out = ca.vertcat(fac * v, ang)
    f = ca.Function("flexopt_rot_log", [a], [out])
    return KernelSpec("flexopt_rot_log", f, 18, 4, 0, 18, 0)


# ----------------------------------------------------------------- consistent mass
#: Integrals ``C_ab = int_0^1 H_a H_b dxi`` of the cubic Hermite shape functions ``H1 = 1 - 3 xi^2 + 2 xi^3``,
#: ``H2 = xi - 2 xi^2 + xi^3``, ``H3 = 3 xi^2 - 2 xi^3``, ``H4 = xi^3 - xi^2`` (times 420: Przemieniecki's
#: 156, 22, 54, -13, 4, 13, -3 pattern, Theory of Matrix Structural Analysis, 1968, ch. 11).
HERMITE_MASS = [
    [156.0, 22.0, 54.0, -13.0],
    [22.0, 4.0, 13.0, -3.0],
    [54.0, 13.0, 156.0, -22.0],
    [-13.0, -3.0, -22.0, 4.0],
]
#: Input of :func:`beam_mass_spec`: the beam's state (30) and constants (23), then its mass ``rho A l0``.
BEAM_MASS_IN = BEAM_STATE + BEAM_CONST + 1


def _beam_mass_expr() -> tuple[ca.SX, ca.SX]:
    """The packed input ``a`` (:data:`BEAM_MASS_IN`) and the 12 x 12 translational mass ``M(a)``."""
    a = ca.SX.sym("a", BEAM_MASS_IN)
    s, c = a[:BEAM_STATE], a[BEAM_STATE : BEAM_STATE + BEAM_CONST]
    m = a[BEAM_STATE + BEAM_CONST]
    Rp, rp = ca.reshape(s[3:12], 3, 3), s[12:15]
    Rq, rq = ca.reshape(s[18:27], 3, 3), s[27:30]
    l0, E0 = c[0], ca.reshape(c[1:10], 3, 3)
    tp, tq = Rp @ E0[:, 0], Rq @ E0[:, 0]
    Z, I3 = ca.SX.zeros(3, 3), ca.SX.eye(3)
    B = [
        ca.horzcat(I3, -_skew(rp), Z, Z),
        ca.horzcat(Z, -l0 * _skew(tp), Z, Z),
        ca.horzcat(Z, Z, I3, -_skew(rq)),
        ca.horzcat(Z, Z, Z, -l0 * _skew(tq)),
    ]
    M = ca.SX.zeros(12, 12)
    for i in range(4):
        for j in range(4):
            M += (m * HERMITE_MASS[i][j] / 420.0) * (B[i].T @ B[j])
    # rotary inertia: the lumped ends (model.structure) plus -rho l0/12 (w_p - w_q)^T J (w_p - w_q), which
    # makes the mean of the lumped and the consistent (linear) rotary inertia, rho l0/12 [[5, 1], [1, 5]]
    # per axis; rho l0 (Iy + Iz, Iy, Iz) = m (ct, ky l0^2 / k1, kz l0^2 / k1) from the kernel constants
    k1, ky, kz, ct = c[10], c[12], c[13], c[14]
    D = ca.diag(ca.vertcat(m * ct, m * ky * l0**2 / k1, m * kz * l0**2 / k1))
    J = (Rp @ E0 @ D @ E0.T @ Rp.T + Rq @ E0 @ D @ E0.T @ Rq.T) / 24.0  # mean of both ends, / 12
    W = ca.horzcat(Z, I3, Z, -I3)
    M -= W.T @ J @ W
    return a, M


@cache
def beam_mass_spec() -> KernelSpec:
    """Consistent translational mass of a beam segment for the cubic (Hermite) shape of its centre line.

    Input ``[state (30), const (23), m]`` (the beam kernels' state and constants and ``m = rho A l0``);
    output the 12 x 12 mass (column-major) over the increments ``(u, psi)`` of both ends' masters.

    Derivation. The centre line is the cubic Hermite interpolant of the end positions and end tangents,
    ``x(xi) = H1 x_p + H2 l0 t_p + H3 x_q + H4 l0 t_q`` (``t = R E0 e_x`` the tangent carried by each end
    node, ``xi = s / l0``), the same cubic the beam's bending energy measures (seed 002, eq. 2: ``eps3..6``
    are the end rotations relative to the chord of exactly this shape). Its velocity follows from the end
    velocities ``v = u_dot + psi_dot x r`` (``r`` the node's offset from its master) and tangent rates
    ``t_dot = psi_dot x t``: ``v(xi) = H1 v_p + H2 l0 psi_dot_p x t_p + H3 v_q + H4 l0 psi_dot_q x t_q =
    sum_a H_a B_a d_dot``. The kinetic energy ``T = 1/2 int rho A |v|^2 ds = 1/2 d_dot^T M d_dot`` gives
    ``M = m sum_ab C_ab B_a^T B_b`` with ``C_ab = int_0^1 H_a H_b dxi`` (:data:`HERMITE_MASS` / 420). For a
    straight segment the lateral blocks are Przemieniecki's consistent beam mass (Theory of Matrix
    Structural Analysis, 1968, ch. 11: ``m/420 [[156, 22 l], [22 l, 4 l^2], ...]``); the axial
    direction shares the cubic (rows ``156, 54`` instead of Przemieniecki's linear ``140, 70``), which keeps
    ``M`` a quadratic polynomial of the end rotations and independent of the positions (the modal
    derivatives of :mod:`model.derivatives` rely on both); both are consistent (rigid translations and
    rotations of a straight segment have their exact kinetic energy). Frequencies converge at O(h^4) in
    bending instead of the O(h^2) of the linearly interpolated mass (shared/PHYSICS.md "Mass
    discretisation").

    Rotary inertia of the sections (``rho l0 E0 diag(Iy + Iz, Iy, Iz) E0^T`` per segment, ``J_e``) is lumped
    at the ends by :mod:`model.structure` (``J_e/2`` each); this kernel adds ``-1/12 (w_p - w_q)^T J_e
    (w_p - w_q)`` (``w`` the end angular velocities, ``J_e`` the mean of its two end orientations), so the
    total is the mean of the lumped and the consistent (linearly interpolated) rotary inertia, ``J_e/12
    [[5, 1], [1, 5]]``: the lumped one reads torsion frequencies low by ``(k h)^2 / 24`` and the consistent
    one high by as much, their mean is fourth-order accurate (the dispersion of a linear element with mass
    ``alpha M_consistent + (1 - alpha) M_lumped`` is ``(k h)^2 (alpha/6 - 1/12)`` to leading order, zero
    at ``alpha = 1/2``; Krieg and Key 1973, Int. J. Numer. Meth. Eng.). A rigid rotation has ``w_p = w_q``
    and its exact kinetic energy.
    """
    a, M = _beam_mass_expr()
    f = ca.Function("flexopt_beam_mass", [a], [ca.vec(M)], ["a"], ["out"])
    return KernelSpec("flexopt_beam_mass", f, BEAM_MASS_IN, 144, 6, BEAM_STATE, BEAM_CONST)


@cache
def beam_mass_jvp_spec() -> KernelSpec:
    """Directional derivative of :func:`beam_mass_spec`'s output along a change ``da`` of its whole input:
    ``[a, da]`` (2 x :data:`BEAM_MASS_IN`) -> ``dM`` (144, column-major); for design sensitivities."""
    a, M = _beam_mass_expr()
    da = ca.SX.sym("da", a.numel())
    f = ca.Function("flexopt_beam_mass_jvp", [ca.vertcat(a, da)], [ca.jtimes(ca.vec(M), a, da)])
    return KernelSpec("flexopt_beam_mass_jvp", f, 2 * BEAM_MASS_IN, 144, 6, BEAM_STATE, BEAM_CONST)


# ----------------------------------------------------------------- external loads and gravity
#: Input of :func:`point_load_spec`: the point's current offset from its master ``r`` (3), the current force
#: (3) and moment (3) in global axes, and two flags (1: the force, the moment follows the master's rotation).
POINT_LOAD_IN = 11
#: Input of :func:`beam_gravity_spec`: the beam's state (30) and constants (23), its mass and the gravity (3).
BEAM_GRAVITY_IN = BEAM_STATE + BEAM_CONST + 4


def _load_finish(name: str, a: ca.SX, d: ca.SX, V: ca.SX, n_in: int) -> KernelSpec:
    """A load potential's gradient and Hessian at ``d = 0`` (``[g, H column-major]``) as a kernel."""
    return _gradient_finish(name, a, d, ca.gradient(V, d), n_in)


def _gradient_finish(name: str, a: ca.SX, d: ca.SX, g: ca.SX, n_in: int) -> KernelSpec:
    """A load's generalised gradient ``g(d)`` (base chart) and its Jacobian at ``d = 0`` (``[g, H row-major]``:
    entry ``6 i + j`` is ``d g_i / d d_j``, the order the assembly scatters blocks in; the same as column-major
    for a potential's symmetric Hessian) as a kernel."""
    H = ca.jacobian(g, d)
    out = ca.densify(
        ca.substitute(ca.vertcat(g, ca.vec(H.T)), d, ca.DM.zeros(d.numel()))
    )  # dense: the batch wrapper writes every entry
    f = ca.Function(name, [a], [out], ["a"], ["out"])
    return KernelSpec(name, f, n_in, out.numel(), 0, n_in, 0)


@cache
def point_load_spec() -> KernelSpec:
    """A force ``F`` on a point carried by a master at offset ``r`` and a moment ``M`` on the master, each dead
    (fixed in space) or following the master's rotation (flags ``fF``, ``fM``), as the generalised gradient
    ``-Q`` of their virtual work over the master's ``(u, psi)`` and its exact Jacobian.

    At the state ``exp(psi) R*`` (the element chart, module docstring) the point is at ``x* + u + (E - I) r``
    (``E = exp(psi)``), a follower force is ``E F`` and a follower moment ``E M``; the virtual work of a
    spatial increment ``(du, dpsi)`` there is ``F(d) . du + (E r x F(d) + M(d)) . dpsi``, so the residual
    in the chart at that state is ``-Q(d) = -[F(d), E r x F(d) + M(d)]``. Pulled back to the chart at ``d =
    0`` (Baker-Campbell-Hausdorff, as :meth:`model.assembly.System.chart_correction`: ``g(d) = (I - 1/2
    skew(psi)) r(d)`` on the rotation rows) its Jacobian ``H`` is what the assembly adds to the Hessian: the
    Newton matrix ``H + chart`` is then the exact Jacobian of the residual. For a dead force ``g`` is the
    gradient of the potential ``-F . x`` and ``H`` its (symmetric) Hessian, the load stiffness of the
    offset; a follower force or a moment has no potential and ``H`` is unsymmetric (a dead moment ``M``
    gives ``H_psi psi = -1/2 skew(M)``, which the chart term cancels: its residual does not change with the
    rotation). Input ``[r (3), F (3), M (3), fF, fM]``; output ``[g (6), H (36, row-major)]``."""
    a = ca.SX.sym("a", POINT_LOAD_IN)
    d = ca.SX.sym("d", 6)
    psi = d[3:6]
    E = _expm3(psi)
    r, F, M, fF, fM = a[0:3], a[3:6], a[6:9], a[9], a[10]
    Fd = F + fF * ((E - ca.SX.eye(3)) @ F)
    Md = M + fM * ((E - ca.SX.eye(3)) @ M)
    Q_psi = ca.cross(E @ r, Fd) + Md
    g = -ca.vertcat(Fd, Q_psi - ca.cross(psi, Q_psi) / 2)
    return _gradient_finish("flexopt_point_load", a, d, g, POINT_LOAD_IN)


@cache
def load_jvp_spec(which: str) -> KernelSpec:
    """The directional derivative of a load kernel's output (``"point"``: :func:`point_load_spec`,
    ``"beam_gravity"``: :func:`beam_gravity_spec`) along a change ``da`` of its whole input: ``[a, da]`` ->
    ``d out``; for design sensitivities (model.design)."""
    spec = point_load_spec() if which == "point" else beam_gravity_spec()
    a = ca.SX.sym("a", spec.n_in)
    da = ca.SX.sym("da", spec.n_in)
    out = spec.function(a)
    name = f"flexopt_{which}_load_jvp"
    f = ca.Function(name, [ca.vertcat(a, da)], [ca.densify(ca.jtimes(out, a, da))])
    return KernelSpec(name, f, 2 * spec.n_in, spec.n_out, 0, 2 * spec.n_in, 0)


@cache
def beam_gravity_spec() -> KernelSpec:
    """Gravity on a beam segment, consistent with its mass (:func:`beam_mass_spec`): the potential of the
    weight of the cubic (Hermite) centre line, ``V = -m g . int_0^1 x(xi) dxi = -m g . (x_p / 2 + l0 t_p / 12
    + x_q / 2 - l0 t_q / 12)`` (``int H1 = int H3 = 1/2``, ``int H2 = -int H4 = 1/12``; ``t`` the end tangents
    ``R E0 e_x``), so a rotating end feels the moment ``m g l0 / 12`` of the clamped-beam load vector
    (Przemieniecki 1968, ch. 5: ``w l^2 / 12``) and its stiffness. Input ``[state (30), const (23), m,
    g (3)]``; output ``[g (12), H (144, column-major)]``."""
    a = ca.SX.sym("a", BEAM_GRAVITY_IN)
    d = ca.SX.sym("d", 12)
    s, c = a[:BEAM_STATE], a[BEAM_STATE : BEAM_STATE + BEAM_CONST]
    m, grav = a[BEAM_STATE + BEAM_CONST], a[BEAM_STATE + BEAM_CONST + 1 :]
    xp, Rp = _end(s[0:3], ca.reshape(s[3:12], 3, 3), s[12:15], d[0:3], d[3:6])
    xq, Rq = _end(s[15:18], ca.reshape(s[18:27], 3, 3), s[27:30], d[6:9], d[9:12])
    l0, E0 = c[0], ca.reshape(c[1:10], 3, 3)
    tp, tq = Rp @ E0[:, 0], Rq @ E0[:, 0]
    V = -m * ca.dot(grav, (xp + xq) / 2 + l0 * (tp - tq) / 12)
    return _load_finish("flexopt_beam_gravity", a, d, V, BEAM_GRAVITY_IN)


# ----------------------------------------------------------------- ideal joints (hinge, slider)
#: Layout of a joint's constants: d0 (3, q's offset from p in p's node axes at the reference), B (9, column-major:
#: the joint basis a, b1, b2 in node axes, a the joint axis), mask (6: 1 = free joint coordinate, 0 = rigid).
JOINT_CONST = 18


def _joint_coordinates(xp, Rp, xq, Rq, d0, B) -> ca.SX:
    """Six joint coordinates, zero at the reference and invariant under rigid motions of the pair: the relative
    position in p's joint basis ``B^T (Rp^T (xq - xp) - d0)`` (along a, b1, b2) and the relative rotation's
    sines about a, b1, b2, e.g. ``((Rp b1).(Rq b2) - (Rp b2).(Rq b1)) / 2`` about a (the skew part of
    ``(Rp B)^T Rq B``: exactly ``sin`` of a rotation of q relative to p about a; to first order the relative
    rotation vector)."""
    a, b1, b2 = B[:, 0], B[:, 1], B[:, 2]
    d = B.T @ (Rp.T @ (xq - xp) - d0)
    pa, p1, p2 = Rp @ a, Rp @ b1, Rp @ b2
    qa, q1, q2 = Rq @ a, Rq @ b1, Rq @ b2
    s_a = (ca.dot(p1, q2) - ca.dot(p2, q1)) / 2
    s_1 = (ca.dot(p2, qa) - ca.dot(pa, q2)) / 2
    s_2 = (ca.dot(pa, q1) - ca.dot(p1, qa)) / 2
    return -ca.vertcat(-d, s_a, s_1, s_2)  # rotations of q relative to p: positive about a, b1, b2


@cache
def joint_spec() -> tuple[KernelSpec, KernelSpec]:
    """An ideal joint between two nodes: its rigid joint coordinates are exact constraints (multipliers), its
    free ones carry no energy. A hinge (revolute) leaves the rotation about its axis free (mask ``[0, 0, 0, 1,
    0, 0]``), a slider (prismatic) the translation along it (``[1, 0, 0, 0, 0, 0]``). Input ``[state (30, the
    beam's layout), const (JOINT_CONST), lam (6)]``; output the beam kernel's layout ``[g (12), H (144), e (6),
    De (72)]``, so assembly treats it as a beam whose deformations are the joint coordinates."""
    a = ca.SX.sym("a", BEAM_STATE + JOINT_CONST + 6)
    d = ca.SX.sym("d", 12)
    v = ca.SX.sym("v", 12)
    s, c = a[:BEAM_STATE], a[BEAM_STATE : BEAM_STATE + JOINT_CONST]
    lam = a[BEAM_STATE + JOINT_CONST :]
    xp, Rp = _end(s[0:3], ca.reshape(s[3:12], 3, 3), s[12:15], d[0:3], d[3:6])
    xq, Rq = _end(s[15:18], ca.reshape(s[18:27], 3, 3), s[27:30], d[6:9], d[9:12])
    e = _joint_coordinates(xp, Rp, xq, Rq, c[0:3], ca.reshape(c[3:12], 3, 3))
    mask = c[12:18]
    L = ca.dot(lam, (1 - mask) * e)
    return _finish("flexopt_joint", a, d, v, L, e, 6, BEAM_STATE, JOINT_CONST, dense=True)
