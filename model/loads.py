"""External loads and gravity: their generalised gradient and its Jacobian, added to the Lagrangian's.

A *dead force* (its direction fixed in space) and gravity are conservative: they enter the total energy as a
potential and the kernels of :mod:`model.elements` give its exact derivatives:

- a force ``F`` on a node or on a point of a body: ``V = -F . x`` of its point of application
  (:func:`model.elements.point_load_spec`); on a point offset from its master (a body's node, a body's
  ``point``) its Hessian is the load stiffness of the offset;
- gravity ``g`` on a body: ``V = -m g . x_c`` (centre of mass, the body's master); on a truss half its weight
  at each end (its mass is linearly interpolated); on a beam segment the weight of its cubic centre line,
  consistent with its mass (:func:`model.elements.beam_gravity_spec`).

A *follower* force or moment (turning with its node: ``R F_ref``) and a moment (dead or follower) under
finite 3D rotations have no potential: they are non-conservative. The same kernel gives their generalised
gradient ``-Q`` (the virtual work ``Q . (du, dpsi)``) and its exact Jacobian, which is unsymmetric (the load
stiffness of a follower force; the ``-1/2 skew(M)`` of a moment that the chart term of the Newton matrix
cancels). Statics and continuation solve with the unsymmetric Jacobian (LU), and the eigen analysis solves
the general eigenproblem (:func:`model.modal.modes_at`): complex eigenvalues (flutter) and negative ones
(divergence) are reported, naming the loads (:meth:`LoadSet.nonconservative_names`). A planar moment about
the axis of a planar motion is conservative in that plane; its out-of-plane stiffness still carries the
skew part, which is the physics of a space-fixed moment, so no special case is made for it.

Total ``g``: its free rows vanish at equilibrium, the drive row is the actuator's reaction with the loads
applied, and its Jacobian (the tangent stiffness of statics and of the eigen analysis) includes the loads'
stiffness. A load given per stroke point (a ramp or a table) is the value at the stroke being solved
(:attr:`model.assembly.System.load_stroke`, internal units); ``d g / d s`` enters the path tangent
(model.statics). ``System.load_scale`` multiplies every load: the stroke-0 equilibrium is found by raising
it from 0 to 1 (model.statics.reference_equilibrium).
"""

from __future__ import annotations

import numpy as np

from .elements import beam_gravity_spec, point_load_spec
from .kernels import compiled
from .scene import Scene
from .structure import Structure

__all__ = ["LoadSet", "has_loads"]


def has_loads(scene: Scene) -> bool:
    """Whether ``scene`` has loads or a nonzero gravity."""
    return bool(scene.loads) or (scene.gravity is not None and any(v != 0.0 for v in scene.gravity))


class LoadSet:
    """The loads of one structure in the numbering of its System (see :meth:`add`)."""

    def __init__(self, s: Structure, pos: np.ndarray, beam_dofs: np.ndarray, beam_flat: np.ndarray, N: int) -> None:
        scene = s.scene
        self.s, self.N = s, N
        node_index = {n: i for i, n in enumerate(s.node_names)}
        body_index = {n: i for i, n in enumerate(s.master_names)}  # bodies are the first masters
        self._unit = (
            (lambda v: np.degrees(v))
            if (scene.stroke is not None and scene.stroke.resolved_unit == "deg")
            else (lambda v: v)
        )
        st = scene.stroke
        vals = st.values() if st is not None else np.zeros(2)
        self._first, self._last = float(vals[0]), float(vals[-1])
        self._per_unit = 180.0 / np.pi if (st is not None and st.resolved_unit == "deg") else 1.0
        # point loads: (master, offset from the master at the reference (nk, 3)), a Load or a constant force
        masters: list[int] = []
        offsets: list[np.ndarray] = []
        self.loads: list = []  # a scene Load, or a constant force vector (gravity on a point mass)
        #: per load, where it comes from: ("node", node index) or ("body", master) for a scene load, ("weight",
        #: master) for a body's weight, ("truss", node index) for half a truss's (model.design differentiates them)
        self.source: list[tuple[str, int]] = []
        for ld in scene.loads:  # a scene's loads first: their indices are the scene's
            if ld.node is not None:
                i = node_index[ld.node]
                masters.append(int(s.node_master[i]))
                offsets.append(s.node_offset[i])
                self.source.append(("node", i))
            else:
                assert ld.body is not None  # a load names a node or a body (the scene's validator)
                m = body_index[ld.body]
                masters.append(m)
                p = np.asarray(ld.point if ld.point is not None else s.master_pos[m], dtype=float)
                offsets.append(p - s.master_pos[m])
                self.source.append(("body", m))
            self.loads.append(ld)
        g = np.zeros(3) if scene.gravity is None else np.asarray(scene.gravity, dtype=float)
        self.gravity = g
        if np.any(g):
            for mw in np.flatnonzero(s.master_mass):  # bodies: the weight at the centre of mass (the master)
                masters.append(int(mw))
                offsets.append(np.zeros(3))
                self.loads.append(s.master_mass[mw] * g)
                self.source.append(("weight", int(mw)))
            for (a, b), mass in zip(s.truss_nodes, s.truss_mass):  # trusses: half the weight at each end
                for i in (a, b):
                    masters.append(int(s.node_master[i]))
                    offsets.append(s.node_offset[i])
                    self.loads.append(0.5 * mass * g)
                    self.source.append(("truss", int(i)))
        self.masters = np.array(masters, dtype=int)
        scene_loads = [ld for ld in self.loads if not isinstance(ld, np.ndarray)]
        #: per load: a moment (else a force), following its master's rotation (else dead)
        self.is_moment = np.array([not isinstance(ld, np.ndarray) and ld.is_moment for ld in self.loads], dtype=bool)
        self.follower = np.array([not isinstance(ld, np.ndarray) and ld.follower for ld in self.loads], dtype=bool)
        #: whether some load is non-conservative (a follower load or a moment): unsymmetric stiffness
        self.nonconservative = any(not ld.conservative for ld in scene_loads)
        self._flags = np.stack([self.follower & ~self.is_moment, self.follower & self.is_moment], axis=1).astype(float)
        self.offsets = np.array(offsets, dtype=float).reshape(-1, 3)
        dofs_full = (6 * self.masters[:, None] + np.arange(6)).reshape(-1, 6)
        self.dofs_full = dofs_full
        self.dofs = pos[dofs_full]
        self.flat = (self.dofs[:, :, None] * N + self.dofs[:, None, :]).ravel()
        self.point_kernel = compiled(point_load_spec()) if len(masters) else None
        self.beam_gravity = bool(np.any(g)) and s.n_beams > 0
        if self.beam_gravity:
            self.beam_kernel = compiled(beam_gravity_spec())
            self.beam_dofs, self.beam_flat = beam_dofs, beam_flat

    def forces(self, stroke: float, rate: bool = False) -> np.ndarray:
        """The loads' vectors (nk, 3: forces or moments, as given: a follower's at the reference) at ``stroke``
        (internal units), times :attr:`System.load_scale` by the caller; ``rate``: their derivative with
        respect to the stroke (internal units)."""
        out = np.zeros((len(self.loads), 3))
        v = float(self._unit(stroke))
        for k, ld in enumerate(self.loads):
            if isinstance(ld, np.ndarray):
                out[k] = 0.0 if rate else ld
            elif rate:
                out[k] = ld.rate(v, self._first, self._last) * self._per_unit
            else:
                out[k] = ld.value(v, self._first, self._last)
        return out

    def stroke_value(self, stroke: float) -> tuple[float, float, float]:
        """``stroke`` (internal units) in the stroke unit, and the stroke's first and last values: the
        arguments of :meth:`model.scene.Load.value`."""
        return float(self._unit(stroke)), self._first, self._last

    def kernel_input(self, R: np.ndarray, vec: np.ndarray) -> np.ndarray:
        """The point kernel's input rows ``[r, F, M, fF, fM]`` for the loads' vectors ``vec`` (nk, 3) at the
        masters' rotations ``R``: current offsets, followers turned with their masters."""
        Rm = R[self.masters]
        r = np.einsum("kij,kj->ki", Rm, self.offsets)
        cur = np.where(self.follower[:, None], np.einsum("kij,kj->ki", Rm, vec), vec)
        F = np.where(self.is_moment[:, None], 0.0, cur)
        M = np.where(self.is_moment[:, None], cur, 0.0)
        return np.hstack([r, F, M, self._flags])

    def nonconservative_names(self) -> list[str]:
        """The scene's non-conservative loads, described for messages (``loads[0] (follower force on node
        'B')``)."""
        return [ld.describe(i) for i, ld in enumerate(self.s.scene.loads) if not ld.conservative]

    def add(
        self,
        R: np.ndarray,
        beam_in: np.ndarray,
        stroke: float,
        scale: float,
        g: np.ndarray,
        g_full: np.ndarray,
        Hflat: np.ndarray,
    ) -> None:
        """Add the loads' gradient and Hessian at a state to the extended ``g`` (N), ``g_full`` (all masters'
        DOFs) and ``Hflat`` (N * N). ``R`` the masters' rotations (nm, 3, 3); ``beam_in`` the beam kernels'
        filled inputs (state and constants first)."""
        N = self.N
        if self.point_kernel is not None:
            out = self.point_kernel(self.kernel_input(R, scale * self.forces(stroke)))
            g += np.bincount(self.dofs.ravel(), out[:, :6].ravel(), minlength=N)
            g_full += np.bincount(self.dofs_full.ravel(), out[:, :6].ravel(), minlength=len(g_full))
            Hflat += np.bincount(self.flat, out[:, 6:].ravel(), minlength=N * N)
        if self.beam_gravity:
            s = self.s
            nc = 30 + s.beam_const.shape[1]
            inp = np.hstack([beam_in[:, :nc], s.beam_mass[:, None], np.tile(scale * self.gravity, (s.n_beams, 1))])
            out = self.beam_kernel(inp)
            g += np.bincount(self.beam_dofs.ravel(), out[:, :12].ravel(), minlength=N)
            full = (6 * s.node_master[s.beam_nodes][:, :, None] + np.arange(6)).reshape(-1, 12)
            g_full += np.bincount(full.ravel(), out[:, :12].ravel(), minlength=len(g_full))
            Hflat += np.bincount(self.beam_flat, out[:, 12:].ravel(), minlength=N * N)

    def gradient_rate(self, R: np.ndarray, stroke: float, scale: float) -> np.ndarray | None:
        """``d g / d s`` (extended numbering, N) of the loads given per stroke point at ``stroke``, or None
        when every load is constant (linear in the vectors: the point kernel at their rates)."""
        if self.point_kernel is None or not any(
            not isinstance(ld, np.ndarray) and ld.force is None and ld.moment is None for ld in self.loads
        ):
            return None
        out = self.point_kernel(self.kernel_input(R, scale * self.forces(stroke, rate=True)))
        return np.bincount(self.dofs.ravel(), out[:, :6].ravel(), minlength=self.N)

    def potential(
        self, x_nodes: np.ndarray, X: np.ndarray, R: np.ndarray, beam_in: np.ndarray | None, stroke: float, scale: float
    ) -> float:
        """The loads' potential ``V`` at a state (for checks: its gradient is what :meth:`add` adds). Raises
        ValueError for non-conservative loads, which have none."""
        if self.nonconservative:
            raise ValueError(f"non-conservative loads have no potential: {', '.join(self.nonconservative_names())}")
        V = 0.0
        if len(self.loads):
            x = X[self.masters] + np.einsum("kij,kj->ki", R[self.masters], self.offsets)
            V -= float(np.sum(scale * self.forces(stroke) * x))
        if self.beam_gravity:
            s = self.s
            E0x = s.beam_const[:, 1:4]  # first column of E0: the local x axis in node axes
            l0 = s.beam_const[:, 0]
            p, q = s.beam_nodes[:, 0], s.beam_nodes[:, 1]
            Rp, Rq = R[s.node_master[p]], R[s.node_master[q]]
            tp, tq = np.einsum("eij,ej->ei", Rp, E0x), np.einsum("eij,ej->ei", Rq, E0x)
            mid = (x_nodes[p] + x_nodes[q]) / 2 + l0[:, None] * (tp - tq) / 12
            V -= float(np.sum(s.beam_mass[:, None] * (scale * self.gravity) * mid))
        return V
