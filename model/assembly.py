"""Numeric assembly: evaluate the compiled kernels on numpy state and scatter to g, H, G and M.

All quantities are in the exponential chart at the current state (see model.elements), in global axes,
except that the driven master's block is expressed in the drive basis (first vector = drive axis), so the
drive is the single DOF ``structure.drive_dof``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from . import linalg
from .elements import beam_mass_spec, beam_spec, joint_spec, rotation_log_spec, rotation_update_spec, truss_spec
from .kernels import CompiledKernel, c_enum, compiled
from .rotations import log_so3, skew, twist_angle, twist_gradient
from .scene import Stroke
from .structure import Structure

__all__ = ["State", "Assembled", "System", "NativeRoute", "ASSEMBLE_SLOTS", "MASS_SLOTS", "newton_system_of"]

_ASSEMBLER: list = []


def assemble_source_definitions() -> tuple[tuple, str]:
    """What model/native/assemble.c needs defined before it: the enum of :data:`MASS_SLOTS` (no defines)."""
    return (), c_enum(MASS_SLOTS, "mass_slot")


def _assembler():
    """The compiled model/native/assemble.c (gather, element kernel and scatter of :meth:`System.evaluate`, the
    mass and the update in one C call each; cached like the kernels), or None without a C compiler."""
    if not _ASSEMBLER:
        import ctypes

        from .errors import KernelBuildError
        from .kernels import native_library

        try:
            lib = native_library("flexopt_assemble", "assemble.c", *assemble_source_definitions())
            fn = lib.assemble
            fn.restype = ctypes.c_int
            fn.argtypes = (
                [ctypes.c_void_p]
                + [ctypes.c_longlong] * 3
                + [ctypes.c_void_p] * 10
                + [ctypes.c_longlong] * 2
                + [ctypes.c_void_p] * 3
                + [ctypes.c_longlong] * 2
            )
            lib.mass_matrix.restype = ctypes.c_int
            lib.mass_matrix.argtypes = [ctypes.c_void_p] * 4
            up = lib.update_state
            up.restype = ctypes.c_int
            up.argtypes = (
                [ctypes.c_void_p, ctypes.c_longlong]
                + [ctypes.c_void_p] * 5
                + [ctypes.c_longlong]
                + [ctypes.c_void_p] * 4
            )
            _ASSEMBLER.append((lib, fn, up))
        except KernelBuildError:
            _ASSEMBLER.append(None)
    return _ASSEMBLER[0]


def function_address(fn: Any) -> int:
    """The address of a function of a loaded library (a ctypes function pointer), for the compiled contexts."""
    import ctypes

    at = ctypes.cast(fn, ctypes.c_void_p).value
    if at is None:  # ctypes resolved the symbol, so its address is not NULL; this narrows the type
        from .errors import KernelBuildError

        raise KernelBuildError(f"the native function {getattr(fn, '__name__', fn)!r} has a NULL address")
    return at


def rotate(R: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``R v`` row by row (``R`` (k, 3, 3), ``v`` (k, 3)) as plain sums of products taken left to right, the
    way the C routes (the compiled Newton loop of model.statics) compute them: the same numbers to the bit."""
    return R[:, :, 0] * v[:, None, 0] + R[:, :, 1] * v[:, None, 1] + R[:, :, 2] * v[:, None, 2]


def rjrt(R: np.ndarray, J: np.ndarray) -> np.ndarray:
    """``R J R^T`` for stacks of 3 x 3 matrices (..., 3, 3): ``A = R J``, then ``A R^T``, each entry a sum of
    products taken left to right, as the compiled mass (``mass_matrix``) sums it: the same numbers to the bit."""
    A = (
        R[..., :, 0, None] * J[..., None, 0, :]
        + R[..., :, 1, None] * J[..., None, 1, :]
        + R[..., :, 2, None] * J[..., None, 2, :]
    )
    return (
        A[..., :, 0, None] * R[..., None, :, 0]
        + A[..., :, 1, None] * R[..., None, :, 1]
        + A[..., :, 2, None] * R[..., None, :, 2]
    )


@dataclass
class State:
    """Configuration of all masters and the multipliers of the rigid deformations."""

    X: np.ndarray  # (nm, 3) master positions
    R: np.ndarray  # (nm, 3, 3) master rotation matrices
    lam: np.ndarray  # (nr,) generalised stresses of the rigid deformations

    def copy(self) -> State:
        """A deep copy."""
        return State(self.X.copy(), self.R.copy(), self.lam.copy())


@dataclass
class Assembled:
    """Gradient, Hessian and constraints at a state (drive basis applied)."""

    g: np.ndarray  # (n,) gradient of the Lagrangian
    H: np.ndarray  # (n, n) Hessian of the Lagrangian: material + geometric stiffness
    c: np.ndarray  # (nr,) rigid deformations (must be 0)
    G: np.ndarray  # (nr, n) their Jacobian
    e_beam: np.ndarray  # (nb, 6) beam deformations
    e_truss: np.ndarray  # (nt,) truss elongations
    _chart: np.ndarray | Callable[[], np.ndarray] | None = None  # the matrix, or what makes it on first use
    dg_ds: np.ndarray | None = None  # (n,) d g / d stroke of loads given per stroke point (model.loads), or None
    g_load: np.ndarray | None = None  # (n,) the loads' part of g (model.loads), or None without loads

    @property
    def chart(self) -> np.ndarray | None:
        """(n, n) ``-1/2 skew(g)`` per rotation block: the Newton matrix is ``H + chart`` (see
        :meth:`System.evaluate`). The compiled Newton loop (model.statics) keeps only what makes it and
        forms the matrix here, on first use (design sensitivities, tests)."""
        if callable(self._chart):
            self._chart = self._chart()
        return self._chart


class System:
    """Kernels, index arrays and buffers of one structure; evaluates states fast.

    Vectors and matrices are in *active numbering*: one entry per active DOF (``n`` of them), the driven
    master's block expressed in the drive basis. Element DOFs are scattered straight into that numbering
    (inactive DOFs go to a dump slot); the driven block is first assembled in global axes in three extra
    slots and then rotated into the drive basis, so no full-size matrix is ever formed.

    Evaluation, mass, update and the Newton loop run in C where they can (:attr:`native`, a :class:`NativeRoute`,
    owns that route's state); the methods here are the numpy route, with the same numbers.
    """

    def __init__(self, structure: Structure) -> None:
        s = structure
        if s.drive_kind == "none":
            from .errors import SceneError

            raise SceneError(
                "stroke",
                f"scene '{s.scene.name}' has no stroke (stroke: null), which only the "
                "exact-constraint diagnosis accepts; a frequency curve or equilibrium needs a "
                "driven coordinate: add a 'stroke'",
            )
        self.s = s
        self.n_full = s.n_dof
        self.beam_kernel = compiled(beam_spec()[0]) if s.n_beams else None
        self.truss_kernel = compiled(truss_spec()[0]) if len(s.truss_nodes) else None
        self.joint_kernel = compiled(joint_spec()[0]) if len(s.joint_nodes) else None
        self._number_dofs(s)
        self._index_elements(s)
        self._index_constraints(s)
        self._prepare_mass(s)
        self._prepare_rotations(s)
        # caches, made on first use
        #: :meth:`eigen_band`'s results per drive (``locked``); an entry set to None switches the banded routes off
        #: (bench/bench_ab.py)
        self.eigen_bands: dict[bool, tuple[np.ndarray, int] | None] = {}
        self._pencils: dict[bool, tuple] = {}  # banded_pencil's per drive, with the band each was made for
        self._proj: np.ndarray | None = None  # support_projector's
        #: model.statics.path_curvature's upper band storage of the reference stiffness: ``(band, source flat
        #: indices, target flat indices)`` for the band (:meth:`eigen_band`) it was made for, made there
        self.curvature_band: tuple | None = None
        #: the compiled route (model/native): its state, the parts that apply and their C calls
        self.native = NativeRoute(self)

    @property
    def stroke(self) -> Stroke:
        """The scene's stroke, never None here: the constructor refuses a scene without one."""
        st = self.s.scene.stroke
        if st is None:  # __init__ raised for it; this narrows the type
            from .errors import SceneError

            raise SceneError("stroke", f"scene '{self.s.scene.name}' has no stroke: add a 'stroke'")
        return st

    def _number_dofs(self, s: Structure) -> None:
        """Active numbering: active DOFs 0..n-1; the drive block's three global coordinates n..n+2 (staging); a
        dump slot n+3 for inactive DOFs (``pos``: the extended position of every global DOF), the drive basis,
        the drive DOF, the free DOFs and the DOF scales."""
        off = 3 if s.drive_kind == "rotation" else 0
        blk_full = np.arange(6 * s.drive_master + off, 6 * s.drive_master + off + 3)
        act_full = np.flatnonzero(s.active)
        n = len(act_full)
        self.n = n
        pos = np.full(self.n_full, n + 3)
        pos[act_full] = np.arange(n)
        self.block_active = np.flatnonzero(s.active[blk_full])  # basis coordinates that are active
        self.block_pos = pos[blk_full[self.block_active]]  # their active indices
        self.Q = s.drive_basis
        self.Qa = self.Q[:, self.block_active]  # (3, nba) basis columns that are active
        # a drive basis made of global axes (a permutation) needs no staging: scatter straight into place
        self.direct = bool(np.all((self.Q == 0) | (self.Q == 1)))
        if self.direct:
            inv = np.argmax(self.Q, axis=1)  # global coordinate i is basis coordinate inv[i]
            target = np.full(3, n + 3)
            target[self.block_active] = self.block_pos
            pos[blk_full] = target[inv]
        else:
            pos[blk_full] = n + np.arange(3)  # global block coordinates go to the staging slots
        self.pos = pos
        self.drive = int(self.block_pos[0]) if len(self.block_pos) and self.block_active[0] == 0 else -1
        assert self.drive >= 0, "the drive coordinate must be active"
        self.free = np.setdiff1d(np.arange(n), [self.drive])
        self.ix_free = np.ix_(self.free, self.free)
        plain = np.setdiff1d(act_full, blk_full)  # active DOFs outside the drive block (global = basis)
        self.plain_full, self.plain_pos = plain, pos[plain]
        self.blk_full = blk_full
        self.scale = s.dof_scale[act_full]
        self.scale[self.block_pos] = s.dof_scale[blk_full[0]]
        self.act_full = act_full
        self.scale_free = self.scale[self.free]
        self.N = n + 4

    def _index_elements(self, s: Structure) -> None:
        """The elements' 12 DOFs (global and extended numbering), their flat indices into the N x N matrices and
        the kernels' input buffers with the constant columns filled."""
        blocks, pos, N = np.arange(6), self.pos, self.N

        def dofs(nodes: np.ndarray) -> np.ndarray:
            m = s.node_master[nodes]  # (ne, 2)
            return (6 * m[:, :, None] + blocks).reshape(len(nodes), 12)

        self.beam_dofs_full = dofs(s.beam_nodes)
        self.truss_dofs_full = dofs(s.truss_nodes)
        self.beam_dofs = pos[self.beam_dofs_full]
        self.truss_dofs = pos[self.truss_dofs_full]
        self.beam_flat = (self.beam_dofs[:, :, None] * N + self.beam_dofs[:, None, :]).ravel()
        self.truss_flat = (self.truss_dofs[:, :, None] * N + self.truss_dofs[:, None, :]).ravel()
        nb, nt = s.n_beams, len(s.truss_nodes)
        self.beam_in = np.zeros((nb, 30 + s.beam_const.shape[1] + 6))
        self.beam_in[:, 30 : 30 + s.beam_const.shape[1]] = s.beam_const
        self.truss_in = np.zeros((nt, 12 + 3 + 1))
        self.truss_in[:, 12:15] = s.truss_const
        # ideal joints (model.elements.joint_spec): the beam's state layout, so the same gather and scatter
        self.joint_dofs_full = dofs(s.joint_nodes)
        self.joint_dofs = pos[self.joint_dofs_full]
        self.joint_flat = (self.joint_dofs[:, :, None] * N + self.joint_dofs[:, None, :]).ravel()
        nc = s.joint_const.shape[1]
        self.joint_in = np.zeros((len(s.joint_nodes), 30 + nc + 6))
        self.joint_in[:, 30 : 30 + nc] = s.joint_const
        # external loads and gravity (model.loads): evaluated at load_stroke (internal units, set by the
        # statics before each solve), each multiplied by load_scale (raised from 0 to 1 at stroke 0)
        from .loads import LoadSet, has_loads

        self.loads = LoadSet(s, self.pos, self.beam_dofs, self.beam_flat, N) if has_loads(s.scene) else None
        self.load_stroke = 0.0
        self.load_scale = 1.0

    def _index_constraints(self, s: Structure) -> None:
        """Constraint bookkeeping: multiplier k belongs to (kind, element, mode)."""
        self.n_con = len(s.constraints)
        cb = s.constraints[s.constraints[:, 0] == 0]
        ct = s.constraints[s.constraints[:, 0] == 1]
        self.con_beam = (np.flatnonzero(s.constraints[:, 0] == 0), cb[:, 1], cb[:, 2])
        self.con_truss = (np.flatnonzero(s.constraints[:, 0] == 1), ct[:, 1])
        cj = s.constraints[s.constraints[:, 0] == 2]
        self.con_joint = (np.flatnonzero(s.constraints[:, 0] == 2), cj[:, 1], cj[:, 2])

    def _prepare_mass(self, s: Structure) -> None:
        """The mass matrix's constant part and the indices of its state-dependent parts. The translational mass of
        trusses whose nodes sit on their masters (offset 0) and the bodies' translational mass are constant; the
        rest (every beam: its cubic mass follows the end tangents) is recomputed per state."""
        N, pos = self.N, self.pos
        self.mcoef = np.array([[2.0, 1.0], [1.0, 2.0]]) / 6.0  # trusses: linear interpolation
        self.beam_mass_kernel = compiled(beam_mass_spec()) if s.n_beams else None
        moved = np.linalg.norm(s.node_offset, axis=1) > 0
        self._mvar = []
        const = np.zeros(N * N)
        for nodes, mass, flat in ((s.truss_nodes, s.truss_mass, self.truss_flat),):
            if not len(nodes):
                continue
            var = moved[nodes].any(axis=1)
            fl = flat.reshape(len(nodes), 144)
            const += np.bincount(
                fl[~var].ravel(), self._trans_mass(np.zeros((int((~var).sum()), 2, 3)), mass[~var]), minlength=N * N
            )
            if var.any():
                self._mvar.append((nodes[var], mass[var], fl[var].ravel()))
        nm = len(s.master_names)
        diag = pos[(6 * np.arange(nm)[:, None] + np.arange(3)).ravel()]
        np.add.at(const, diag * (N + 1), np.repeat(s.master_mass, 3))
        const[(N - 1) * (N + 1)] = 0.0
        self._mass_const = const
        rb = pos[6 * np.arange(nm)[:, None] + 3 + np.arange(3)]  # (nm, 3)
        #: flat indices (extended N x N) of each master's 3 x 3 rotation block, masters in order (rotary inertia)
        self.rot_flat = (rb[:, :, None] * N + rb[:, None, :]).ravel()
        self._has_body_inertia = bool(np.any(s.master_inertia))

    def _prepare_rotations(self, s: Structure) -> None:
        """The masters an increment can rotate (those with an active rotational DOF), the entries of the chart
        correction on their rotation blocks (:meth:`chart_correction`), and the compiled Rodrigues update and
        relative logarithm with their input buffers."""
        N, nm = self.N, len(s.master_names)
        self._rot_masters = rm = np.flatnonzero(s.active.reshape(nm, 6)[:, 3:].any(axis=1))
        # chart correction C = -1/2 skew(g) of each such master's rotation block: entry (i, j) is
        # sign * g_k / 2 with (i, j, k, sign) below; positions in the extended numbering
        rp = self.pos[6 * rm[:, None] + 3 + np.arange(3)]  # (k, 3)
        ijks = ((0, 1, 2, 1.0), (1, 0, 2, -1.0), (0, 2, 1, -1.0), (2, 0, 1, 1.0), (1, 2, 0, 1.0), (2, 1, 0, -1.0))
        self._chart_flat = np.concatenate([rp[:, i] * N + rp[:, j] for i, j, _, _ in ijks])
        self._chart_src = np.concatenate([6 * rm + 3 + k for _, _, k, _ in ijks])
        self._chart_sign = np.repeat([0.5 * sg for _, _, _, sg in ijks], len(rm))
        self._rot_update = compiled(rotation_update_spec())
        self._rot_log = compiled(rotation_log_spec())
        self._rot_in = np.zeros((len(rm), 12))
        self._log_in = np.zeros((len(rm), 18))

    def pattern(self) -> np.ndarray:
        """Every entry of ``H + chart`` and of the mass matrix (active numbering, n x n, bool) that can be
        nonzero: the elements' 12 x 12 DOF blocks, the masters' rotation blocks (chart, body inertia) and the
        diagonal. All True where the drive basis is not made of global axes (its rotation mixes the drive
        block; the banded routes are not used there)."""
        n, N = self.n, self.N
        if not self.direct:
            return np.ones((n, n), dtype=bool)
        P = np.zeros(N * N, dtype=bool)
        for flat in (self.beam_flat, self.truss_flat, self._chart_flat, self.rot_flat):
            P[np.asarray(flat, dtype=np.int64).ravel()] = True
        P = P.reshape(N, N)[:n, :n].copy()
        np.fill_diagonal(P, True)
        return P

    def eigen_band(self, locked: bool = True) -> tuple[np.ndarray, int] | None:
        """The band order (:func:`model.linalg.band_order`) of the eigen problem's pencil, the free block
        (``locked``) or all DOFs: ``(perm, kd)`` when the Lanczos route applies (no rigid deformations, a band
        of at most :data:`model.linalg.BAND_FRACTION` of the order), else None. Found once per System. At
        every order where it applies Lanczos was the faster route on the templates, down to the 10-element
        leaf (order 59: 0.22-0.26 against 0.41-0.58 ms a solve)."""
        cache = self.eigen_bands
        if locked not in cache:
            dofs = self.free if locked else np.arange(self.n)
            out = None
            if self.n_con == 0 and self.direct:
                perm, kl, ku = linalg.band_order(self.pattern()[np.ix_(dofs, dofs)])
                kd = max(kl, ku)
                if kd + 1 <= linalg.BAND_FRACTION * len(dofs):
                    out = (perm, kd)
            cache[locked] = out
        return cache[locked]

    def banded_pencil(self, locked: bool = True) -> linalg.BandedPencil | None:
        """The eigen problem's :class:`model.linalg.BandedPencil` (free block of the extended-numbering
        matrices, read in place; :meth:`eigen_band`'s order), made once per drive, or None where
        :meth:`eigen_band` is None."""
        band = self.eigen_band(locked)
        if band is None:
            return None
        pencils = self._pencils
        got = pencils.get(locked)
        if got is None or got[0] is not band:
            got = pencils[locked] = (
                band,
                linalg.BandedPencil(self.free if locked else np.arange(self.n), self.N, *band),
            )
        return got[1]

    def free_block(self, A: np.ndarray, locked: bool = True) -> np.ndarray:
        """The free-DOF block ``A[free, free]`` (``locked``; else all of ``A``) as a new C-contiguous array: the
        same numbers as indexing with :attr:`ix_free`, by two ``take`` calls at a third of its cost."""
        return A.take(self.free, 0).take(self.free, 1) if locked else np.array(A, order="C")

    # ------------------------------------------------------------------ state
    def reference_state(self) -> State:
        """The undeformed reference configuration."""
        nm = len(self.s.master_names)
        return State(self.s.master_pos.copy(), np.tile(np.eye(3), (nm, 1, 1)), np.zeros(self.n_con))

    def node_states(self, st: State) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Node positions (nn, 3), rotations (nn, 3, 3) and current offsets from their masters (nn, 3)."""
        m = self.s.node_master
        Rn = st.R[m]
        r = rotate(Rn, self.s.node_offset)
        return st.X[m] + r, Rn, r

    def to_global(self, xi: np.ndarray) -> np.ndarray:
        """Increments in active numbering (vector or columns) -> all masters' DOFs in global axes."""
        xi = np.asarray(xi, dtype=float)
        out = np.zeros((self.n_full,) + xi.shape[1:])
        out[self.plain_full] = xi[self.plain_pos]
        out[self.blk_full] = self.Qa @ xi[self.block_pos]
        return out

    def from_global(self, v: np.ndarray) -> np.ndarray:
        """Covectors (or vectors) in global axes over all masters' DOFs -> active numbering (T^T v)."""
        v = np.asarray(v, dtype=float)
        out = np.zeros((self.n,) + v.shape[1:])
        out[self.plain_pos] = v[self.plain_full]
        out[self.block_pos] = self.Qa.T @ v[self.blk_full]
        return out

    def support_projector(self) -> np.ndarray:
        """The structure's support-direction projector in active numbering, ``T^T P T`` (cached)."""
        if self._proj is None:
            P = self.s.support_projector
            if P is None:  # model.modal.participation asks only when the scene declares support directions
                raise ValueError("the scene declares no support_directions: no support projector")
            full = np.kron(np.eye(len(self.s.master_names)), P)
            self._proj = self.from_global(full @ self.to_global(np.eye(self.n)))
        return self._proj

    def reduce_vector(self, ext: np.ndarray) -> np.ndarray:
        """Extended vector (N) -> active numbering: rotate the staged drive block into the basis."""
        n = self.n
        out = ext[:n].copy()
        if not self.direct:
            out[self.block_pos] += self.Qa.T @ ext[n : n + 3]
        return out

    def reduce_matrix(self, ext: np.ndarray, rows: bool = True) -> np.ndarray:
        """Extended matrix (N x N, or r x N with rows=False) -> active numbering, congruence with T."""
        n, p, Qa = self.n, self.block_pos, self.Qa
        if self.direct:
            return ext[:n, :n] if rows else ext[:, :n]
        if not rows:
            out = ext[:, :n].copy()
            out[:, p] += ext[:, n : n + 3] @ Qa
            return out
        out = ext[:n, :n].copy()
        out[:, p] += ext[:n, n : n + 3] @ Qa
        out[p, :] += Qa.T @ ext[n : n + 3, :n]
        out[np.ix_(p, p)] += Qa.T @ ext[n : n + 3, n : n + 3] @ Qa
        return out

    def update(self, st: State, xi: np.ndarray, dlam: np.ndarray | None = None) -> State:
        """New state after the increment ``xi`` (active numbering): x += u, R <- expm(psi) R, exactly."""
        if self.native.update_call is not None and xi.ndim == 1:  # one C call, the same numbers
            return self.native.update(st, xi, dlam)
        d = self.to_global(xi).reshape(-1, 6)
        R = st.R.copy()
        moving = self._rot_masters
        if len(moving):
            buf = self._rot_in
            buf[:, :3] = d[moving, 3:]
            buf[:, 3:] = st.R[moving].transpose(0, 2, 1).reshape(-1, 9)
            R[moving] = self._rot_update(buf).reshape(-1, 3, 3).transpose(0, 2, 1)
        new = State(st.X + d[:, :3], R, st.lam.copy())
        if dlam is not None:
            new.lam += dlam
        return new

    def difference(self, st: State, base: State) -> np.ndarray:
        """The increment (active numbering) that takes ``base`` to ``st``: ``update(base, d) == st``.

        Translations ``X - X_base``; rotations the spatial rotation vector ``log(R R_base^T)``.
        """
        d = np.zeros((len(self.s.master_names), 6))
        d[:, :3] = st.X - base.X
        m = self._rot_masters
        if len(m):
            buf = self._log_in
            buf[:, :9] = st.R[m].transpose(0, 2, 1).reshape(-1, 9)
            buf[:, 9:] = base.R[m].transpose(0, 2, 1).reshape(-1, 9)
            out = self._rot_log(buf)
            d[m, 3:] = out[:, :3]
            far = out[:, 3] > np.pi - 1e-3  # near pi the skew part loses the axis: quaternion route
            if far.any():
                d[m[far], 3:] = log_so3(st.R[m[far]] @ base.R[m[far]].transpose(0, 2, 1))
        return self.from_global(d.ravel())

    # ------------------------------------------------------------ kernels
    def fill_inputs(self, st: State) -> None:
        """Write the state columns (node positions, rotations, offsets; multipliers) of ``st`` into the kernels'
        input buffers :attr:`beam_in` and :attr:`truss_in` (the numpy route; model.design and model.methods
        evaluate other kernels on them)."""
        xn, Rn, rn = self.node_states(st)
        s = self.s
        if s.n_beams:
            p, q = s.beam_nodes[:, 0], s.beam_nodes[:, 1]
            bi = self.beam_in
            bi[:, 0:3] = xn[p]
            bi[:, 3:12] = Rn[p].transpose(0, 2, 1).reshape(-1, 9)  # column-major
            bi[:, 12:15] = rn[p]
            bi[:, 15:18] = xn[q]
            bi[:, 18:27] = Rn[q].transpose(0, 2, 1).reshape(-1, 9)
            bi[:, 27:30] = rn[q]
            lam = np.zeros((s.n_beams, 6))
            k, el, mode = self.con_beam
            lam[el, mode] = st.lam[k]
            bi[:, 30 + s.beam_const.shape[1] :] = lam
        if len(s.truss_nodes):
            p, q = s.truss_nodes[:, 0], s.truss_nodes[:, 1]
            ti = self.truss_in
            ti[:, 0:3], ti[:, 3:6], ti[:, 6:9], ti[:, 9:12] = xn[p], rn[p], xn[q], rn[q]
            ti[:, 15] = 0.0
            k, el = self.con_truss
            ti[el, 15] = st.lam[k]
        if len(s.joint_nodes):
            p, q = s.joint_nodes[:, 0], s.joint_nodes[:, 1]
            ji = self.joint_in
            ji[:, 0:3], ji[:, 12:15], ji[:, 15:18], ji[:, 27:30] = xn[p], rn[p], xn[q], rn[q]
            ji[:, 3:12] = Rn[p].transpose(0, 2, 1).reshape(-1, 9)
            ji[:, 18:27] = Rn[q].transpose(0, 2, 1).reshape(-1, 9)
            lam = np.zeros((len(p), 6))
            k, el, mode = self.con_joint
            lam[el, mode] = st.lam[k]
            ji[:, 30 + s.joint_const.shape[1] :] = lam

    def evaluate(self, st: State) -> Assembled:
        """Gradient, Hessian and constraint rows at ``st`` (one kernel call per element type)."""
        s, N = self.s, self.N
        if self.native.assemble_call is not None:
            return self.native.evaluate(st)
        self.fill_inputs(st)
        g = np.zeros(N)
        g_full = np.zeros(self.n_full)
        Hflat = np.zeros(N * N)
        G = np.zeros((self.n_con, N))
        c = np.zeros(self.n_con)
        e_beam = np.zeros((s.n_beams, 6))
        e_truss = np.zeros(len(s.truss_nodes))
        if self.beam_kernel is not None:  # the structure has beams
            out = self.beam_kernel(self.beam_in)
            g += np.bincount(self.beam_dofs.ravel(), out[:, :12].ravel(), minlength=N)
            g_full += np.bincount(self.beam_dofs_full.ravel(), out[:, :12].ravel(), minlength=self.n_full)
            Hflat += np.bincount(self.beam_flat, out[:, 12:156].ravel(), minlength=N * N)
            e_beam = out[:, 156:162]
            k, el, mode = self.con_beam
            if len(k):
                De = out[:, 162:234].reshape(-1, 12, 6)  # column-major (6 x 12) -> [elem, col, row]
                c[k] = e_beam[el, mode]
                np.add.at(G, (k[:, None], self.beam_dofs[el]), De[el, :, mode])
        if self.truss_kernel is not None:  # the structure has trusses
            out = self.truss_kernel(self.truss_in)
            g += np.bincount(self.truss_dofs.ravel(), out[:, :12].ravel(), minlength=N)
            g_full += np.bincount(self.truss_dofs_full.ravel(), out[:, :12].ravel(), minlength=self.n_full)
            Hflat += np.bincount(self.truss_flat, out[:, 12:156].ravel(), minlength=N * N)
            e_truss = out[:, 156]
            k, el = self.con_truss
            if len(k):
                c[k] = e_truss[el]
                np.add.at(G, (k[:, None], self.truss_dofs[el]), out[el, 157:169])
        if self.joint_kernel is not None:  # the structure has joints
            out = self.joint_kernel(self.joint_in)
            g += np.bincount(self.joint_dofs.ravel(), out[:, :12].ravel(), minlength=N)
            g_full += np.bincount(self.joint_dofs_full.ravel(), out[:, :12].ravel(), minlength=self.n_full)
            Hflat += np.bincount(self.joint_flat, out[:, 12:156].ravel(), minlength=N * N)
            k, el, mode = self.con_joint
            De = out[:, 162:234].reshape(-1, 12, 6)
            c[k] = out[el, 156 + mode]
            np.add.at(G, (k[:, None], self.joint_dofs[el]), De[el, :, mode])
        dg_ds = g_load = None
        if self.loads is not None:
            g_el = g.copy()
            self.loads.add(st.R, self.beam_in, self.load_stroke, self.load_scale, g, g_full, Hflat)
            g_load = self.reduce_vector(g - g_el)
            rate = self.loads.gradient_rate(st.R, self.load_stroke, self.load_scale)
            dg_ds = None if rate is None else self.reduce_vector(rate)
        H = self.reduce_matrix(Hflat.reshape(N, N))
        return Assembled(
            self.reduce_vector(g),
            H,
            c,
            self.reduce_matrix(G, rows=False),
            e_beam,
            e_truss,
            self.chart_correction(g_full),
            dg_ds,
            g_load,
        )

    def chart_correction(self, g_full: np.ndarray) -> np.ndarray:
        """``-1/2 skew(g_m)`` on each master's rotation block, in active numbering.

        The residual is the gradient in the chart at the *current* state, ``r(psi) = d/d delta
        L(exp(delta) exp(psi) R)``; by the Baker-Campbell-Hausdorff formula ``log(exp(delta) exp(psi)) =
        psi + delta + 1/2 delta x psi + ...``, so ``r(psi) = (I + 1/2 skew(psi)) grad f(psi)`` and its exact
        Jacobian is ``dr/dpsi = H - 1/2 skew(g)``. At an equilibrium ``g`` vanishes except for the actuator's
        moment, which stays: without this term Newton converges only linearly on a driven body. ``g_full``
        is the gradient over all masters' DOFs in global axes, reactions of supported rotations included
        (they multiply the free ones in the cross product).
        """
        N = self.N
        vals = self._chart_sign * g_full[self._chart_src]
        return self.reduce_matrix(np.bincount(self._chart_flat, vals, minlength=N * N).reshape(N, N))

    def hessian_derivative(self, st: State, v: np.ndarray) -> np.ndarray:
        """Directional derivative of the Hessian along ``v`` (drive basis): the exact third derivative of
        the Lagrangian contracted once, ``dH_ij = sum_k d3L/(dxi_i dxi_j dxi_k) v_k``, from CasADi."""
        N = self.N
        vg = self.to_global(np.asarray(v, dtype=float))
        kernel = compiled(beam_spec()[1])
        if self.native.assemble_call is not None and kernel.address is not None:  # one call, the same numbers
            return self.native.hessian_derivative(st, kernel, vg)
        self.fill_inputs(st)
        dH = np.zeros(N * N)
        for kernel_spec, inputs, dofs, flat in (
            (beam_spec()[1], self.beam_in, self.beam_dofs_full, self.beam_flat),
            (truss_spec()[1], self.truss_in, self.truss_dofs_full, self.truss_flat),
            (joint_spec()[1], self.joint_in, self.joint_dofs_full, self.joint_flat),
        ):
            if not len(inputs):
                continue
            out = compiled(kernel_spec)(np.hstack([inputs, vg[dofs]]))
            dH += np.bincount(flat, out.ravel(), minlength=N * N)
        return self.reduce_matrix(dH.reshape(N, N))

    def energy(self, st: State) -> float:
        """The Lagrangian at ``st`` from the kernels' deformations, plus the loads' potential (model.loads) at
        :attr:`load_stroke` (for checks; not used by solvers)."""
        ev = self.evaluate(st)
        s = self.s
        U = 0.0
        if s.n_beams:
            f = ev.e_beam * s.beam_mask
            U += 0.5 * float(np.einsum("ei,eij,ej->", f, s.beam_stiff, f))
            k, el, mode = self.con_beam
            U += float(st.lam[k] @ ev.e_beam[el, mode])
        if len(s.truss_nodes):
            mask = s.truss_const[:, 2]
            U += 0.5 * float(np.sum(s.truss_const[:, 1] * (mask * ev.e_truss) ** 2))
            k, el = self.con_truss
            U += float(st.lam[k] @ ev.e_truss[el])
        if self.joint_kernel is not None:  # the structure has joints
            self.fill_inputs(st)
            e_joint = self.joint_kernel(self.joint_in)[:, 156:162]
            k, el, mode = self.con_joint
            U += float(st.lam[k] @ e_joint[el, mode])
        if self.loads is not None:
            U += self.loads.potential(
                self.node_states(st)[0], st.X, st.R, self.beam_in, self.load_stroke, self.load_scale
            )
        return U

    # --------------------------------------------------------------- drive
    def drive_value(self, st: State, near: float = 0.0) -> float:
        """Current drive coordinate: twist angle [rad] about the axis, or displacement along it."""
        s = self.s
        m = s.drive_master
        if s.drive_kind == "rotation":
            return twist_angle(st.R[m], s.drive_axis, near)
        d, a = st.X[m] - s.master_pos[m], s.drive_axis  # the sum as the compiled Newton loop takes it
        return float(d[0] * a[0] + d[1] * a[1] + d[2] * a[2])

    def drive_gradient(self, st: State) -> np.ndarray:
        """Gradient of the drive coordinate with respect to the increments (drive basis), length n."""
        s = self.s
        grad = np.zeros(self.n)
        if s.drive_kind == "rotation":
            grad[self.block_pos] = self.Qa.T @ twist_gradient(st.R[s.drive_master], s.drive_axis)
        else:
            grad[self.drive] = 1.0
        return grad

    # ---------------------------------------------------------------- mass
    def mass(self, st: State) -> np.ndarray:
        """Mass matrix at ``st`` in the exponential chart (drive basis applied).

        Beams: consistent mass of the cubic (Hermite) centre line through the end positions and tangents
        (:func:`model.elements.beam_mass_spec`, Przemieniecki 1968 ch. 11); trusses: consistent mass of
        linearly interpolated positions, ``m/6 [[2, 1], [1, 2]]``; node velocities ``v = u_dot - skew(r)
        psi_dot`` for nodes offset by ``r`` from their master; beam rotary inertia ``rho l0/2 diag(Iy+Iz, Iy, Iz)`` lumped at each end in the element frame,
        rotated with the node; rigid bodies ``diag(m I, R J R^T)`` at their centre of mass.
        """
        s, N, native = self.s, self.N, self.native
        if native.mass_context() is not None:  # all of it in one C call (mass_matrix), the same numbers
            return native.mass(st)
        bmk = self.beam_mass_kernel  # None without beams
        if native.assemble_call is not None and bmk is not None and bmk.address is not None:
            Mflat = self._mass_const + native.call(st, bmk, native.mass_in_at, False)[3]
        else:
            Mflat = self._mass_const.copy()
            if s.n_beams:
                Mflat += np.bincount(self.beam_flat, self.beam_mass_blocks(st).ravel(), minlength=N * N)
        if self._mvar:
            _, _, rn = self.node_states(st)
            for nodes, mass, flat in self._mvar:
                Mflat += np.bincount(flat, self._trans_mass(rn[nodes], mass), minlength=N * N)
        Jn = rjrt(st.R[s.node_master], s.node_rot_inertia)
        Jm = np.zeros((len(s.master_names), 3, 3))
        np.add.at(Jm, s.node_master, Jn)
        if self._has_body_inertia:
            Jm += rjrt(st.R, s.master_inertia)
        np.add.at(Mflat, self.rot_flat, Jm.ravel())
        return self.reduce_matrix(Mflat.reshape(N, N))

    def beam_mass_blocks(self, st: State) -> np.ndarray:
        """The beams' 12 x 12 translational mass blocks at ``st`` (nb, 144, column-major)."""
        if self.beam_mass_kernel is None:  # made for every structure with beams
            raise ValueError("the structure has no beams: no beam mass blocks")
        self.fill_inputs(st)
        nc = 30 + self.s.beam_const.shape[1]
        return self.beam_mass_kernel(np.hstack([self.beam_in[:, :nc], self.s.beam_mass[:, None]]))

    def _trans_mass(self, r: np.ndarray, mass: np.ndarray) -> np.ndarray:
        """Flattened 12 x 12 translational mass blocks of elements whose end offsets are ``r`` (ne, 2, 3)."""
        T = np.zeros(r.shape[:2] + (3, 6))
        T[..., :3] = np.eye(3)
        T[..., 3:] = -skew(r)
        return np.einsum("e,ab,eaik,ebil->eakbl", mass, self.mcoef, T, T).ravel()


#: The slots of ``assemble``'s arguments (model/native/assemble.c: the kernel, the sizes, the gather and scatter
#: indices, the node offsets and their rotated copies), in the order both compiled contexts lay them out: the mass
#: routine's (:data:`MASS_SLOTS`) and the Newton loop's (:data:`model.statics.LOOP_SLOTS`), stated once here.
ASSEMBLE_SLOTS = (
    "kernel",
    "ne",
    "n_in",
    "n_out",
    "end_master",
    "end_node",
    "kernel_in",
    "dofs",
    "dofs_full",
    "flat",
    "n_ext",
    "n_full",
    "node_master",
    "node_offset",
    "nodes",
    "offsets",
)

#: The slots of the compiled mass's context (``mass_matrix`` of model/native/assemble.c), in order: the one list of
#: them, which the C source sees as an enum of the same names upper-cased (:func:`assemble_source_definitions`).
MASS_SLOTS = (
    *ASSEMBLE_SLOTS,
    "mass_const",
    "node_inertia",
    "masters",
    "body_inertia",
    "rot_flat",
    "inertia_work",
)


class NativeRoute:
    """The compiled route of one :class:`System`: the C of model/native that evaluates, updates and solves its
    states in one call each, with the same numbers as the numpy route (tests/test_linalg.py compares them bit for
    bit). It owns that route's state: which parts apply, their fixed arrays with the addresses taken once (each
    ``.ctypes.data`` costs about 1.5 us, which at 17 arguments was a third of a leaf's evaluate), and what is
    built on first use. A part that is None runs in numpy: no C compiler, trusses, rigid deformations, or a drive
    basis not made of global axes.

    Attributes
    ----------
    assemble_call
        ``(assemble, end_master, end_node, dofs, dofs_full, flat)``: the C ``assemble`` (model/native/assemble.c)
        and the addresses of the beams' end masters, end nodes, DOFs (extended, global) and flat matrix indices;
        None where :meth:`System.evaluate`, :meth:`System.mass` and :meth:`System.hessian_derivative` run in
        numpy (applies to beams only, without rigid deformations).
    update_call
        ``(update_state, rodrigues, act, moving, rin, rout)``: the C ``update_state``, the compiled Rodrigues
        kernel's batch entry and the addresses of each global DOF's active index (-1: not active), the rotating
        masters and the kernel's buffers; None where :meth:`System.update` runs in numpy (a drive basis not made
        of global axes).
    point_loop
        model.statics' compiled Newton loop of this system, built there on first use (``False``: not built yet;
        None: not applicable).
    """

    def __init__(self, sys: System) -> None:
        self.sys = sys
        s = sys.s
        self.assemble_call: tuple | None = None
        self.update_call: tuple | None = None
        self.point_loop: object = False
        self._newton: linalg.NewtonSystem | None | Literal[False] = False  # newton_system's; False: not built yet
        self._d3: tuple[np.ndarray, int] | None = None  # hessian_derivative's input buffer and its address
        self._parts: dict[str, int] | None = None  # point_parts'
        self._mass_ctx: int | None | Literal[False] = False  # mass_context's; False: not made yet
        self._keep: dict[str, list] = {}  # arrays whose addresses the contexts hold, by context
        self.mass_in: np.ndarray | None = None  # the mass kernel's input buffer (state, constants, mass)
        self.beam_in_at = self.mass_in_at = 0  # addresses of System.beam_in and mass_in
        self.mass_size = 0  # doubles of the compiled mass's output (kernel outputs, g, g_full, M)
        asm = (
            _assembler()
            if (
                sys.beam_kernel is not None  # the structure has beams
                and not len(s.truss_nodes)
                and not sys.n_con
                and sys.loads is None
                and sys.beam_kernel.address is not None
            )
            else None
        )
        if asm is not None:
            ends = s.beam_nodes.ravel()
            nc = 30 + s.beam_const.shape[1]
            self.mass_in = np.zeros((s.n_beams, nc + 1))  # the mass kernel's input: state, constants, mass
            self.mass_in[:, 30:nc] = s.beam_const
            self.mass_in[:, nc] = s.beam_mass
            self._keep["assemble"] = arrays = [
                np.ascontiguousarray(a, dtype=np.int64)
                for a in (s.node_master[ends], ends, sys.beam_dofs, sys.beam_dofs_full, sys.beam_flat)
            ]
            self.assemble_call = (asm[1], *(a.ctypes.data for a in arrays))
            self.beam_in_at, self.mass_in_at = sys.beam_in.ctypes.data, self.mass_in.ctypes.data
        upd = _assembler() if (sys.direct and sys._rot_update.address is not None) else None
        if upd is not None:
            rm = sys._rot_masters
            act = np.where(sys.pos < sys.n, sys.pos, -1).astype(np.int64)
            self._keep["update"] = upd_arrays = [  # act, moving (int64), the kernel's buffers (float64)
                act,
                np.ascontiguousarray(rm, dtype=np.int64),
                np.zeros((len(rm), 12)),
                np.zeros((len(rm), 9)),
            ]
            self.update_call = (upd[2], sys._rot_update.address, *(a.ctypes.data for a in upd_arrays))

    # ------------------------------------------------------------ switches
    def switch_off(self) -> tuple:
        """Switch every compiled part off (the numpy routes run, for comparisons); returns what :meth:`restore`
        takes to switch them back on."""
        saved = (self.assemble_call, self.update_call, self._newton, self.point_loop)
        self.assemble_call = self.update_call = self._newton = self.point_loop = None
        return saved

    def restore(self, saved: tuple) -> None:
        """Switch the compiled parts back on as :meth:`switch_off` left them."""
        self.assemble_call, self.update_call, self._newton, self.point_loop = saved

    @contextmanager
    def off(self) -> Iterator[None]:
        """Within the block every compiled part is off (:meth:`switch_off`); on again after it."""
        saved = self.switch_off()
        try:
            yield
        finally:
            self.restore(saved)

    # ------------------------------------------------------------ evaluate
    def call(self, st: State, kernel, inputs_at: int, gradient: bool):
        """Gather the beams' state inputs into the kernel's input buffer (address ``inputs_at``: its state
        columns are written, the rest kept), run ``kernel`` and scatter its 144-entry block (after a 12-entry
        gradient when ``gradient``); returns (out, g, g_full, H flat)."""
        sys = self.sys
        assert self.assemble_call is not None  # the callers check that the compiled evaluate applies
        fn, end_master, end_node, dofs, dofs_full, flat = self.assemble_call
        N, n_full, nb = sys.N, sys.n_full, sys.s.n_beams
        X = np.ascontiguousarray(st.X, dtype=np.float64)
        R = np.ascontiguousarray(st.R, dtype=np.float64)
        r = rotate(R[sys.s.node_master], sys.s.node_offset)
        # one new buffer for the outputs (the results keep views of it): one address to take, not four
        no = nb * kernel.n_out
        buf = np.empty(no + N + n_full + N * N)
        b = buf.ctypes.data
        if fn(
            kernel.address,
            nb,
            kernel.n_in,
            kernel.n_out,
            X.ctypes.data,
            R.ctypes.data,
            end_master,
            end_node,
            r.ctypes.data,
            inputs_at,
            b,
            dofs,
            dofs_full,
            flat,
            N,
            n_full,
            b + 8 * no,
            b + 8 * (no + N),
            b + 8 * (no + N + n_full),
            0 if gradient else -1,
            12 if gradient else 0,
        ):
            from .errors import KernelBuildError

            raise KernelBuildError(f"kernel '{kernel.spec.name}' reported an evaluation error")
        return (
            buf[:no].reshape(nb, kernel.n_out),
            buf[no : no + N],
            buf[no + N : no + N + n_full],
            buf[no + N + n_full :],
        )

    def evaluate(self, st: State) -> Assembled:
        """:meth:`System.evaluate` in one C call (beams only, no rigid deformations; same numbers)."""
        sys = self.sys
        N = sys.N
        assert sys.beam_kernel is not None  # the compiled evaluate applies to structures with beams only
        out, g, g_full, Hflat = self.call(st, sys.beam_kernel, self.beam_in_at, True)
        H = sys.reduce_matrix(Hflat.reshape(N, N))
        return Assembled(
            sys.reduce_vector(g),
            H,
            np.zeros(0),
            sys.reduce_matrix(np.zeros((0, N)), rows=False),
            out[:, 156:162],
            np.zeros(0),
            sys.chart_correction(g_full),
        )

    def hessian_derivative(self, st: State, kernel, vg: np.ndarray) -> np.ndarray:
        """:meth:`System.hessian_derivative` in one C call through the compiled third-derivative ``kernel``, the
        direction in global axes ``vg`` (same numbers)."""
        sys = self.sys
        if self._d3 is None:  # input: the main kernel's (constants; state columns gathered), then v
            buf = np.zeros((sys.s.n_beams, kernel.n_in))
            buf[:, : sys.beam_in.shape[1]] = sys.beam_in
            self._d3 = (buf, buf.ctypes.data)
        buf, at = self._d3
        buf[:, sys.beam_in.shape[1] :] = vg[sys.beam_dofs_full]
        return sys.reduce_matrix(self.call(st, kernel, at, False)[3].reshape(sys.N, sys.N))

    def update(self, st: State, xi: np.ndarray, dlam: np.ndarray | None = None) -> State:
        """:meth:`System.update` of a vector ``xi`` in one C call (same numbers)."""
        assert self.update_call is not None  # System.update checks that the compiled update applies
        fn, kernel, act, moving, rin, rout = self.update_call
        X = np.ascontiguousarray(st.X, dtype=np.float64)
        R = np.ascontiguousarray(st.R, dtype=np.float64)
        x = np.ascontiguousarray(xi, dtype=np.float64)
        Xn, Rn = np.empty(X.shape), np.empty(R.shape)
        if fn(
            kernel,
            len(X),
            X.ctypes.data,
            R.ctypes.data,
            x.ctypes.data,
            act,
            moving,
            len(self.sys._rot_masters),
            rin,
            rout,
            Xn.ctypes.data,
            Rn.ctypes.data,
        ):
            from .errors import KernelBuildError

            raise KernelBuildError("the rotation update kernel reported an evaluation error")
        new = State(Xn, Rn, st.lam.copy())
        if dlam is not None:
            new.lam += dlam
        return new

    # ------------------------------------------------- the shared context
    def _assemble_slots(self, kernel: CompiledKernel, kernel_in: int) -> tuple[dict[str, int], list[np.ndarray]]:
        """The values of :data:`ASSEMBLE_SLOTS` (``assemble``'s arguments for ``kernel``, its inputs gathered at
        ``kernel_in``), the part the mass's and the Newton loop's contexts share, with the node arrays they point
        to (node masters, offsets and the rotated offsets' buffer), which the caller keeps referenced."""
        sys = self.sys
        s = sys.s
        assert self.assemble_call is not None  # the callers check that the compiled evaluate applies
        _, end_master, end_node, dofs, dofs_full, flat = self.assemble_call
        nodes = [
            np.ascontiguousarray(s.node_master, dtype=np.int64),
            np.ascontiguousarray(s.node_offset, dtype=np.float64),
            np.zeros((len(s.node_master), 3)),  # the rotated offsets
        ]
        slots = {
            "kernel": kernel.address,
            "ne": s.n_beams,
            "n_in": kernel.n_in,
            "n_out": kernel.n_out,
            "end_master": end_master,
            "end_node": end_node,
            "kernel_in": kernel_in,
            "dofs": dofs,
            "dofs_full": dofs_full,
            "flat": flat,
            "n_ext": sys.N,
            "n_full": sys.n_full,
            "node_master": nodes[0].ctypes.data,
            "node_offset": nodes[1].ctypes.data,
            "nodes": len(s.node_master),
            "offsets": nodes[2].ctypes.data,
        }
        return slots, nodes

    # ---------------------------------------------------------------- mass
    def mass_context(self) -> int | None:
        """The address of the compiled mass's context (``mass_matrix``, one slot per :data:`MASS_SLOTS`), made
        once; None where the compiled evaluate does not apply (the numpy route) or the mass has a part it does
        not compute (trusses)."""
        if self.assemble_call is None:  # not applicable, or switched off (the cached context stays for later)
            return None
        if self._mass_ctx is False:
            sys = self.sys
            ctx = None
            k = sys.beam_mass_kernel  # not None where the compiled evaluate applies (beams)
            if self.assemble_call is not None and k is not None and k.address is not None and not sys._mvar:
                s, N = sys.s, sys.N
                slots, nodes = self._assemble_slots(k, self.mass_in_at)
                keep = [
                    *nodes,
                    np.ascontiguousarray(sys._mass_const, dtype=np.float64),
                    np.ascontiguousarray(s.node_rot_inertia, dtype=np.float64),
                    np.ascontiguousarray(s.master_inertia, dtype=np.float64),
                    np.ascontiguousarray(sys.rot_flat, dtype=np.int64),
                    np.zeros(9 * len(s.master_names)),
                ]
                at = [a.ctypes.data for a in keep]
                slots.update(
                    mass_const=at[3],
                    node_inertia=at[4],
                    masters=len(s.master_names),
                    body_inertia=at[5] if sys._has_body_inertia else 0,
                    rot_flat=at[6],
                    inertia_work=at[7],
                )
                if set(slots) != set(MASS_SLOTS):
                    raise ValueError(f"the mass context has slots {sorted(set(slots) ^ set(MASS_SLOTS))} on one side")
                c = np.array([slots[name] for name in MASS_SLOTS], dtype=np.int64)
                keep.append(c)
                self._keep["mass"] = keep
                self.mass_size = s.n_beams * k.n_out + N + sys.n_full + N * N
                ctx = c.ctypes.data
            self._mass_ctx = ctx
        return self._mass_ctx

    def mass(self, st: State) -> np.ndarray:
        """:meth:`System.mass` in one C call (where :meth:`mass_context` is not None; same numbers)."""
        sys = self.sys
        N = sys.N
        assert sys.beam_mass_kernel is not None  # mass_context made the context (beams) before this call
        out = np.empty(self.mass_size)
        if _assembler()[0].mass_matrix(
            self.mass_context(),
            np.ascontiguousarray(st.X, dtype=np.float64).ctypes.data,
            np.ascontiguousarray(st.R, dtype=np.float64).ctypes.data,
            out.ctypes.data,
        ):
            from .errors import KernelBuildError

            raise KernelBuildError(f"kernel '{sys.beam_mass_kernel.spec.name}' reported an evaluation error")
        return sys.reduce_matrix(out[self.mass_size - N * N :].reshape(N, N))

    # ------------------------------------------------------ the Newton loop
    def newton_system(self) -> linalg.NewtonSystem | None:
        """The compiled Newton system of this system (:class:`model.linalg.NewtonSystem`, made once), or None where
        model.statics' numpy route applies: no C driver, rigid deformations, a drive basis that is not made of
        global axes, or no one-call evaluate."""
        if self._newton is False:
            sys = self.sys
            ns = None
            if self.assemble_call is not None and sys.direct and sys.n_con == 0 and sys.n > 0:
                ns = newton_system_of(sys, sys.pattern())
            self._newton = ns
        return self._newton

    def point_parts(self) -> dict[str, int] | None:
        """What the compiled Newton loop (model.statics) needs of this system, by the names of
        :data:`model.statics.LOOP_SLOTS`: the addresses of the C ``assemble`` and ``update_state``
        (model/native/assemble.c), of the kernels' batch entries, of the fixed index arrays and work buffers, and
        the sizes. None where :meth:`System.evaluate` and :meth:`System.update` do not both run in C (the numpy
        route). Made once; the arrays stay referenced here."""
        sys = self.sys
        kernel = sys.beam_kernel  # not None where the compiled evaluate applies (beams)
        if self.assemble_call is None or self.update_call is None or sys._rot_log.address is None or kernel is None:
            return None
        if self._parts is None:
            s, N = sys.s, sys.N
            lib = _assembler()[0]
            upd, rot_update, act, moving, rin, rout = self.update_call
            nm, nmov = len(s.master_names), len(sys._rot_masters)
            slots, nodes = self._assemble_slots(kernel, self.beam_in_at)
            keep = [
                *nodes,
                np.ascontiguousarray(sys._chart_flat, dtype=np.int64),
                np.ascontiguousarray(sys._chart_src, dtype=np.int64),
                np.ascontiguousarray(sys._chart_sign, dtype=np.float64),
                np.zeros(N * N),  # the chart matrix: its fixed entries rewritten per evaluation, the rest 0
                np.zeros((nmov, 18)),
                np.zeros((nmov, 4)),  # the logarithm kernel's input and output
                np.ascontiguousarray(s.master_pos, dtype=np.float64),
                np.ascontiguousarray(s.drive_axis, dtype=np.float64),
            ]
            at = [a.ctypes.data for a in keep]
            self._keep["point"] = keep
            self._parts = {
                "assemble": function_address(lib.assemble),
                **slots,
                "update": function_address(lib.update_state),
                "rot_update": rot_update,
                "masters": nm,
                "act": act,
                "moving": moving,
                "nmov": nmov,
                "rin": rin,
                "rout": rout,
                "nchart": len(sys._chart_src),
                "chart_flat": at[3],
                "chart_src": at[4],
                "chart_sign": at[5],
                "chart": at[6],
                "rot_log": sys._rot_log.address,
                "log_in": at[7],
                "log_out": at[8],
                "drive_master": s.drive_master,
                "kind": 0 if s.drive_kind == "rotation" else 1,
                "master_pos": at[9],
                "axis": at[10],
                "n_act": sys.n,
            }
        return self._parts

    def assembled_at(self, buf: np.ndarray) -> Assembled:
        """The :class:`Assembled` whose numbers the compiled Newton loop left in ``buf`` (the layout of
        :meth:`call`: kernel outputs, ``g``, ``g_full``, ``H``); the chart matrix is made on first use."""
        sys = self.sys
        N, n, n_full, nb = sys.N, sys.n, sys.n_full, sys.s.n_beams
        assert sys.beam_kernel is not None  # the compiled Newton loop runs on structures with beams only
        no = nb * sys.beam_kernel.n_out
        g_full = buf[no + N : no + N + n_full]
        return Assembled(
            buf[no : no + n],
            buf[no + N + n_full :].reshape(N, N)[:n, :n],
            np.zeros(0),
            np.zeros((0, n)),
            buf[:no].reshape(nb, -1)[:, 156:162],
            np.zeros(0),
            lambda: sys.chart_correction(g_full),
        )


def newton_system_of(sys: System, pattern: np.ndarray | None = None, banded: bool = True) -> linalg.NewtonSystem | None:
    """:func:`model.linalg.newton_system` of ``sys``: its drive, drive kind and axis, free DOFs, rotation blocks,
    the global axis of each active basis column and the scaling; ``pattern`` and ``banded`` as there. None without
    the C driver. :meth:`NativeRoute.newton_system` makes the one that model.statics uses (where it applies)."""
    comp = np.argmax(sys.Qa, axis=0)  # the global axis of each active basis column
    return linalg.newton_system(
        sys.n,
        sys.drive,
        0 if sys.s.drive_kind == "rotation" else 1,
        sys.free,
        sys.block_pos,
        comp,
        np.asarray(sys.s.drive_axis, dtype=float),
        sys.scale,
        sys.scale_free,
        pattern=pattern,
        banded=banded,
    )
