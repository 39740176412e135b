"""Numeric assembly: evaluate the compiled kernels on numpy state and scatter to g, H, G and M.

All quantities are in the exponential chart at the current state (see model.elements), in global axes,
except that the driven master's block is expressed in the drive basis (first vector = drive axis), so the
drive is the single DOF ``structure.drive_dof``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .elements import beam_spec, truss_spec
from .kernels import compiled
from .rotations import expm_so3, skew, twist_angle, twist_gradient
from .structure import Structure

__all__ = ["State", "Assembled", "System"]


@dataclass
class State:
    """Configuration of all masters and the multipliers of the rigid deformations."""

    X: np.ndarray  # (nm, 3) master positions
    R: np.ndarray  # (nm, 3, 3) master rotation matrices
    lam: np.ndarray  # (nr,) generalised stresses of the rigid deformations

    def copy(self) -> "State":
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


class System:
    """Kernels, index arrays and buffers of one structure; evaluates states fast."""

    def __init__(self, structure: Structure) -> None:
        s = structure
        self.s = s
        n = s.n_dof
        self.n = n
        self.beam_kernel = compiled(beam_spec()[0]) if s.n_beams else None
        self.truss_kernel = compiled(truss_spec()[0]) if len(s.truss_nodes) else None
        blocks = np.arange(6)

        def dofs(nodes: np.ndarray) -> np.ndarray:
            m = s.node_master[nodes]  # (ne, 2)
            return (6 * m[:, :, None] + blocks).reshape(len(nodes), 12)

        self.beam_dofs = dofs(s.beam_nodes)
        self.truss_dofs = dofs(s.truss_nodes)
        self.beam_flat = (self.beam_dofs[:, :, None] * n + self.beam_dofs[:, None, :]).ravel()
        self.truss_flat = (self.truss_dofs[:, :, None] * n + self.truss_dofs[:, None, :]).ravel()
        nb, nt = s.n_beams, len(s.truss_nodes)
        self.beam_in = np.zeros((nb, 30 + s.beam_const.shape[1] + 6))
        self.beam_in[:, 30 : 30 + s.beam_const.shape[1]] = s.beam_const
        self.truss_in = np.zeros((nt, 12 + 3 + 1))
        self.truss_in[:, 12:15] = s.truss_const
        # constraint bookkeeping: multiplier k belongs to (kind, element, mode)
        self.n_con = len(s.constraints)
        cb = s.constraints[s.constraints[:, 0] == 0]
        ct = s.constraints[s.constraints[:, 0] == 1]
        self.con_beam = (np.flatnonzero(s.constraints[:, 0] == 0), cb[:, 1], cb[:, 2])
        self.con_truss = (np.flatnonzero(s.constraints[:, 0] == 1), ct[:, 1])
        # drive basis
        off = 3 if s.drive_kind == "rotation" else 0
        self.drive_block = np.arange(6 * s.drive_master + off, 6 * s.drive_master + off + 3)
        self.Q = s.drive_basis
        # mass: the translational mass of elements whose nodes sit on their masters (offset 0) and the
        # bodies' translational mass are constant; the rest is recomputed per state
        self.mcoef = np.array([[2.0, 1.0], [1.0, 2.0]]) / 6.0
        off = np.linalg.norm(s.node_offset, axis=1) > 0
        self._mvar = []
        const = np.zeros(n * n)
        for nodes, mass, flat in ((s.beam_nodes, s.beam_mass, self.beam_dofs),
                                  (s.truss_nodes, s.truss_mass, self.truss_dofs)):
            if not len(nodes):
                continue
            var = off[nodes].any(axis=1)
            fl = (flat[:, :, None] * n + flat[:, None, :])
            zero = np.zeros((len(nodes), 2, 3))
            const += np.bincount(fl[~var].ravel(), self._trans_mass(zero[~var], nodes[~var] * 0, mass[~var]),
                                 minlength=n * n)
            if var.any():
                self._mvar.append((nodes[var], mass[var], fl[var].ravel()))
        nm = len(s.master_names)
        for m in range(nm):
            const[(6 * m + np.arange(3)) * (n + 1)] += s.master_mass[m]
        self._mass_const = const
        rb = 6 * np.arange(nm)[:, None, None] + 3 + np.arange(3)[None, :, None]
        self._rot_flat = (rb * n + (6 * np.arange(nm)[:, None, None] + 3 + np.arange(3)[None, None, :])).ravel()
        self._has_body_inertia = bool(np.any(s.master_inertia))

    # ------------------------------------------------------------------ state
    def reference_state(self) -> State:
        """The undeformed reference configuration."""
        nm = len(self.s.master_names)
        return State(self.s.master_pos.copy(), np.tile(np.eye(3), (nm, 1, 1)), np.zeros(self.n_con))

    def node_states(self, st: State) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Node positions (nn, 3), rotations (nn, 3, 3) and current offsets from their masters (nn, 3)."""
        m = self.s.node_master
        r = np.einsum("nij,nj->ni", st.R[m], self.s.node_offset)
        return st.X[m] + r, st.R[m], r

    def to_global(self, xi: np.ndarray) -> np.ndarray:
        """Increment vector from drive-basis DOFs to global-axes DOFs."""
        out = xi.copy()
        out[self.drive_block] = self.Q @ xi[self.drive_block]
        return out

    def to_basis_vec(self, v: np.ndarray) -> np.ndarray:
        """Covector (gradient) from global axes to drive basis."""
        out = v.copy()
        out[self.drive_block] = self.Q.T @ v[self.drive_block]
        return out

    def to_basis_mat(self, A: np.ndarray, both: bool = True) -> np.ndarray:
        """Congruence ``T^T A T`` (both) or ``A T`` (columns only) with the drive basis change ``T``."""
        b = self.drive_block
        A[:, b] = A[:, b] @ self.Q
        if both:
            A[b, :] = self.Q.T @ A[b, :]
        return A

    def update(self, st: State, xi: np.ndarray, dlam: np.ndarray | None = None) -> State:
        """New state after the increment ``xi`` (drive basis): x += u, R <- expm(psi) R, exactly."""
        d = self.to_global(xi).reshape(-1, 6)
        new = State(st.X + d[:, :3], expm_so3(d[:, 3:]) @ st.R, st.lam.copy())
        if dlam is not None:
            new.lam += dlam
        return new

    # ------------------------------------------------------------ kernels
    def _fill_inputs(self, st: State) -> None:
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

    def evaluate(self, st: State) -> Assembled:
        """Gradient, Hessian and constraint rows at ``st`` (one kernel call per element type)."""
        s, n = self.s, self.n
        self._fill_inputs(st)
        g = np.zeros(n)
        Hflat = np.zeros(n * n)
        G = np.zeros((self.n_con, n))
        c = np.zeros(self.n_con)
        e_beam = np.zeros((s.n_beams, 6))
        e_truss = np.zeros(len(s.truss_nodes))
        if s.n_beams:
            out = self.beam_kernel(self.beam_in)
            g += np.bincount(self.beam_dofs.ravel(), out[:, :12].ravel(), minlength=n)
            Hflat += np.bincount(self.beam_flat, out[:, 12:156].ravel(), minlength=n * n)
            e_beam = out[:, 156:162]
            k, el, mode = self.con_beam
            if len(k):
                De = out[:, 162:234].reshape(-1, 12, 6)  # column-major (6 x 12) -> [elem, col, row]
                c[k] = e_beam[el, mode]
                np.add.at(G, (k[:, None], self.beam_dofs[el]), De[el, :, mode])
        if len(s.truss_nodes):
            out = self.truss_kernel(self.truss_in)
            g += np.bincount(self.truss_dofs.ravel(), out[:, :12].ravel(), minlength=n)
            Hflat += np.bincount(self.truss_flat, out[:, 12:156].ravel(), minlength=n * n)
            e_truss = out[:, 156]
            k, el = self.con_truss
            if len(k):
                c[k] = e_truss[el]
                np.add.at(G, (k[:, None], self.truss_dofs[el]), out[el, 157:169])
        H = Hflat.reshape(n, n)
        H = self.to_basis_mat(H)
        g = self.to_basis_vec(g)
        if self.n_con:
            G = self.to_basis_mat(G, both=False)
        return Assembled(g, H, c, G, e_beam, e_truss)

    def hessian_derivative(self, st: State, v: np.ndarray) -> np.ndarray:
        """Directional derivative of the Hessian along ``v`` (drive basis): the exact third derivative of
        the Lagrangian contracted once, ``dH_ij = sum_k d3L/(dxi_i dxi_j dxi_k) v_k``, from CasADi."""
        s, n = self.s, self.n
        self._fill_inputs(st)
        vg = self.to_global(np.asarray(v, dtype=float))
        dH = np.zeros(n * n)
        for kernel_spec, inputs, dofs, flat in (
            (beam_spec()[1], self.beam_in, self.beam_dofs, self.beam_flat),
            (truss_spec()[1], self.truss_in, self.truss_dofs, self.truss_flat),
        ):
            if not len(inputs):
                continue
            out = compiled(kernel_spec)(np.hstack([inputs, vg[dofs]]))
            dH += np.bincount(flat, out.ravel(), minlength=n * n)
        return self.to_basis_mat(dH.reshape(n, n))

    def energy(self, st: State) -> float:
        """The Lagrangian at ``st`` from the kernels' deformations (for checks; not used by solvers)."""
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
        return U

    # --------------------------------------------------------------- drive
    def drive_value(self, st: State, near: float = 0.0) -> float:
        """Current drive coordinate: twist angle [rad] about the axis, or displacement along it."""
        s = self.s
        m = s.drive_master
        if s.drive_kind == "rotation":
            return twist_angle(st.R[m], s.drive_axis, near)
        return float((st.X[m] - s.master_pos[m]) @ s.drive_axis)

    def drive_gradient(self, st: State) -> np.ndarray:
        """Gradient of the drive coordinate with respect to the increments (drive basis), length n."""
        s = self.s
        grad = np.zeros(self.n)
        if s.drive_kind == "rotation":
            grad[self.drive_block] = self.Q.T @ twist_gradient(st.R[s.drive_master], s.drive_axis)
        else:
            grad[self.drive_block[0]] = 1.0
        return grad

    # ---------------------------------------------------------------- mass
    def mass(self, st: State) -> np.ndarray:
        """Mass matrix at ``st`` in the exponential chart (drive basis applied).

        Beams and trusses: consistent mass of linearly interpolated positions, ``m/6 [[2, 1], [1, 2]]``,
        with node velocities ``v = u_dot - skew(r) psi_dot`` for nodes offset by ``r`` from their master;
        beam rotary inertia ``rho l0/2 diag(Iy+Iz, Iy, Iz)`` lumped at each end in the element frame,
        rotated with the node; rigid bodies ``diag(m I, R J R^T)`` at their centre of mass.
        """
        s, n = self.s, self.n
        Mflat = self._mass_const.copy()
        if self._mvar:
            _, _, rn = self.node_states(st)
            for nodes, mass, flat in self._mvar:
                Mflat += np.bincount(flat, self._trans_mass(rn[nodes], nodes, mass), minlength=n * n)
        Rn = st.R[s.node_master]
        Jn = Rn @ s.node_rot_inertia @ Rn.transpose(0, 2, 1)
        Jm = np.zeros((len(s.master_names), 3, 3))
        np.add.at(Jm, s.node_master, Jn)
        if self._has_body_inertia:
            Jm += st.R @ s.master_inertia @ st.R.transpose(0, 2, 1)
        Mflat[self._rot_flat] += Jm.ravel()
        return self.to_basis_mat(Mflat.reshape(n, n))

    def _trans_mass(self, r: np.ndarray, nodes: np.ndarray, mass: np.ndarray) -> np.ndarray:
        """Flattened 12 x 12 translational mass blocks of elements whose end offsets are ``r`` (ne, 2, 3)."""
        T = np.zeros(r.shape[:2] + (3, 6))
        T[..., :3] = np.eye(3)
        T[..., 3:] = -skew(r)
        return np.einsum("e,ab,eaik,ebil->eakbl", mass, self.mcoef, T, T).ravel()
