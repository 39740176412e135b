"""compile_scene(scene) -> Structure: the numeric form of a scene (meshed, indexed, frozen).

Masters and DOFs
----------------
Every node is carried by a *master*: a rigid body (whose master sits at its centre of mass) or the node
itself. Each master has six increments ``(u, psi)`` in global axes (translation, spatial rotation vector);
DOF ``6 m + k``. Rotational DOFs of a master that no beam and no body uses are inactive (a truss-only
node has none), as are supported coordinates. The drive's master block is expressed in a basis whose first
vector is the drive axis, so the drive is one DOF (``drive_dof``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .elements import BEAM_CONST, JOINT_CONST, TRUSS_CONST
from .errors import ModelSizeError, SceneError
from .scene import AUTO_START, Beam, Scene, Truss, expand_modes
from .sections import beam_segment, section_properties

__all__ = ["Structure", "compile_scene", "MAX_DOFS"]

#: Largest number of active degrees of freedom accepted (dense linear algebra; about 500 beam nodes).
MAX_DOFS = 3000

_DOF_INDEX = {"x": 0, "y": 1, "z": 2, "rx": 3, "ry": 4, "rz": 5}


@dataclass(frozen=True)
class Structure:
    """A meshed, indexed scene. Array shapes in the comments (nn nodes, nm masters, nb beams, nt trusses)."""

    scene: Scene
    length_scale: float  # characteristic length: largest extent of the reference geometry
    node_names: tuple[str, ...]  # (nn,)
    node_master: np.ndarray  # (nn,) master index of each node
    node_offset: np.ndarray  # (nn, 3) node position minus master position, reference
    master_names: tuple[str, ...]  # (nm,)
    master_pos: np.ndarray  # (nm, 3) reference positions
    active: np.ndarray  # (6 nm,) bool: DOF is free (not supported, not an unused rotation)
    # beams
    beam_nodes: np.ndarray  # (nb, 2) node indices
    beam_const: np.ndarray  # (nb, BEAM_CONST) packed kernel constants
    beam_member: np.ndarray  # (nb,) index of the scene element
    beam_stiff: np.ndarray  # (nb, 6, 6) constitutive matrix S of eq. 2's deformations
    beam_mask: np.ndarray  # (nb, 6) 1 = flexible, 0 = rigid
    beam_stress: np.ndarray  # (nb, 7): A, Iy, Iz, cy, cz, tau_per_torque, l0 (nan where unknown)
    beam_mass: np.ndarray  # (nb,) rho A l0
    # trusses
    truss_nodes: np.ndarray  # (nt, 2)
    truss_const: np.ndarray  # (nt, TRUSS_CONST)
    truss_member: np.ndarray  # (nt,)
    truss_area: np.ndarray  # (nt,)
    truss_mass: np.ndarray  # (nt,)
    # mass of nodes and bodies
    node_rot_inertia: np.ndarray  # (nn, 3, 3) rotary inertia lumped at nodes, global axes at reference
    master_mass: np.ndarray  # (nm,) rigid-body mass at the master (bodies only)
    master_inertia: np.ndarray  # (nm, 3, 3) rigid-body inertia about the master (bodies), reference axes
    # rigid deformations (constraints): (kind 0 beam / 1 truss / 2 joint, element index, deformation index)
    constraints: np.ndarray  # (nr, 3) int
    # drive
    drive_master: int
    drive_kind: str  # "rotation" | "translation" | "none" (scene without stroke: diagnosis only)
    drive_axis: np.ndarray  # (3,)
    drive_basis: np.ndarray  # (3, 3) columns: axis, two perpendicular directions
    drive_dof: int  # DOF index of the drive in the rotated basis
    support_projector: np.ndarray | None  # (6, 6) projector on support directions of a master block
    member_names: tuple[str, ...] = field(default=())
    warping: tuple[str, ...] = field(default=())  # per member: the torsion assumption used
    # ideal joints (scene.joints): kernel constants (model.elements.joint_spec) and their rigid coordinates
    joint_nodes: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=int))  # (nj, 2)
    joint_const: np.ndarray = field(default_factory=lambda: np.zeros((0, JOINT_CONST)))  # (nj, JOINT_CONST)
    joint_names: tuple[str, ...] = field(default=())

    @property
    def n_dof(self) -> int:
        """Number of master DOFs (active or not)."""
        return 6 * len(self.master_names)

    @property
    def n_beams(self) -> int:
        """Number of beam elements after meshing."""
        return len(self.beam_nodes)

    @property
    def dof_scale(self) -> np.ndarray:
        """Characteristic size of each DOF: the length scale for translations, 1 rad for rotations."""
        s = np.ones(self.n_dof)
        s.reshape(-1, 6)[:, :3] = self.length_scale
        return s

    def dof_label(self, dof: int) -> str:
        """Readable name of a DOF, e.g. ``tip.ry``."""
        m, k = divmod(dof, 6)
        return f"{self.master_names[m]}.{('x', 'y', 'z', 'rx', 'ry', 'rz')[k]}"


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def _basis(a: np.ndarray) -> np.ndarray:
    """Right-handed orthonormal basis with first column ``a`` (a cyclic permutation of the global axes
    when ``a`` is a positive coordinate axis, so assembly needs no rotation)."""
    for k in range(3):
        if np.array_equal(a, np.eye(3)[k]):
            return np.eye(3)[:, [k, (k + 1) % 3, (k + 2) % 3]]
    t = np.eye(3)[np.argmin(abs(a))]
    b = _unit(np.cross(a, t))
    return np.column_stack([a, b, np.cross(a, b)])


@dataclass
class _Mesh:
    """The nodes of a scene being meshed and the masters that carry them (compile_scene's working tables)."""

    master_names: list[str]
    master_pos: list[np.ndarray]
    body_index: dict[str, int]
    node_names: list[str] = field(default_factory=list)
    node_pos: list[np.ndarray] = field(default_factory=list)
    node_master: list[int] = field(default_factory=list)
    node_index: dict[str, int] = field(default_factory=dict)

    def add_node(self, name: str, p: np.ndarray, owner: str | None) -> int:
        """Add node ``name`` at ``p``, carried by body ``owner`` or, with None, its own master."""
        self.node_index[name] = len(self.node_names)
        self.node_names.append(name)
        self.node_pos.append(p)
        if owner is not None:
            self.node_master.append(self.body_index[owner])
        else:
            self.node_master.append(len(self.master_names))
            self.master_names.append(name)
            self.master_pos.append(p)
        return self.node_index[name]


def _masters(scene: Scene, pos0: dict[str, np.ndarray], carrier: dict[str, str]) -> _Mesh:
    """Masters: bodies first (at their centre of mass), then the free nodes; every scene node added."""
    mesh = _Mesh(
        [b.name for b in scene.bodies],
        [np.array(b.center_of_mass, dtype=float) for b in scene.bodies],
        {b.name: i for i, b in enumerate(scene.bodies)},
    )
    for n in scene.nodes:
        mesh.add_node(n.name, pos0[n.name], carrier.get(n.name))
    return mesh


def _truss_row(el: Truss, ie: int, mat, mesh: _Mesh, pos0: dict[str, np.ndarray]) -> dict:  # noqa: ANN001
    """The kernel table row of truss ``el`` (scene element ``ie``)."""
    p_name, q_name = el.nodes
    L = float(np.linalg.norm(pos0[q_name] - pos0[p_name]))
    return dict(
        nodes=(mesh.node_index[p_name], mesh.node_index[q_name]),
        member=ie,
        l0=L,
        k1=mat.E * el.area / L,
        mask=0.0 if el.rigid else 1.0,
        area=el.area,
        mass=mat.density * el.area * L,
    )


def _beam_rows(el: Beam, ie: int, mat, props, mesh: _Mesh, pos0: dict[str, np.ndarray]) -> list[dict]:  # noqa: ANN001
    """The kernel table rows of beam ``el`` (scene element ``ie``) meshed into its segments; adds the
    segment-internal nodes to ``mesh``."""
    p_name, q_name = el.nodes
    p, q = pos0[p_name], pos0[q_name]
    n = el.segments if el.segments != "auto" else AUTO_START  # model.curve resolves "auto" (model.mesh)
    seg = beam_segment(p, q, el.y_axis, props, mat.E, mat.G, mat.density, n)
    E0 = np.array(seg["E0"], dtype=float)
    chain = [mesh.node_index[p_name]]
    for i in range(1, n):
        chain.append(mesh.add_node(f"{el.name}#{i}", p + (q - p) * i / n, None))
    chain.append(mesh.node_index[q_name])
    l0 = float(seg["l0"])
    rigid = expand_modes(el.rigid)
    mask = np.ones(6)
    mask[list(rigid)] = 0.0
    k1, k2, ky, kz, phi_y, phi_z = (float(seg[k]) for k in ("k1", "k2", "ky", "kz", "phi_y", "phi_z"))
    S = np.zeros((6, 6))
    S[0, 0] = k1
    S[1, 1] = k2
    # bending with shear deformation (model.elements): Euler-Bernoulli's [[4, -2], [-2, 4]] at phi = 0
    S[2:4, 2:4] = ky / (1 + phi_y) * np.array([[4.0 + phi_y, phi_y - 2.0], [phi_y - 2.0, 4.0 + phi_y]])
    S[4:6, 4:6] = kz / (1 + phi_z) * np.array([[4.0 + phi_z, phi_z - 2.0], [phi_z - 2.0, 4.0 + phi_z]])
    const = np.concatenate([[l0], E0.ravel(order="F"), [k1, k2, ky, kz, float(props.ct)], mask, [phi_y, phi_z]])
    assert const.size == BEAM_CONST
    nan = float("nan")
    stress = [props.A, props.Iy, props.Iz, props.cy or nan, props.cz or nan, props.tau_per_torque or nan, l0]
    rot = np.array(seg["rot"], dtype=float)
    return [
        dict(nodes=(a_, b_), member=ie, const=const, S=S, mask=mask, stress=stress, mass=float(seg["mass"]), rot=rot)
        for a_, b_ in zip(chain[:-1], chain[1:])
    ]


def _elements(
    scene: Scene, mesh: _Mesh, pos0: dict[str, np.ndarray], carrier: dict[str, str]
) -> tuple[list[dict], list[dict], list[str]]:
    """The meshed beam and truss rows and each member's torsion assumption; refuses a node that is connected
    to nothing."""
    mats = {m.name: m for m in scene.materials}
    beam_rows: list[dict] = []
    truss_rows: list[dict] = []
    used = set(carrier)
    warping: list[str] = []
    for j in scene.joints:
        used.update(j.nodes)
    for ie, el in enumerate(scene.elements):
        used.update(el.nodes)
        if isinstance(el, Truss):
            warping.append("n/a")
            truss_rows.append(_truss_row(el, ie, mats[el.material], mesh, pos0))
            continue
        assert isinstance(el, Beam)
        props = section_properties(el.section)
        warping.append(props.warping)
        beam_rows += _beam_rows(el, ie, mats[el.material], props, mesh, pos0)
    for i, name in enumerate(mesh.node_names):
        if name in pos0 and name not in used:
            raise SceneError(
                f"nodes[{i}]", f"node '{name}' is not connected to any element or body; remove it or connect it"
            )
    return beam_rows, truss_rows, warping


def _active(scene: Scene, mesh: _Mesh, rot_used: np.ndarray, carrier: dict[str, str]) -> np.ndarray:
    """Free DOFs (6 nm,): not supported, and no rotation of a master that no beam and no body uses."""
    nm = len(mesh.master_names)
    active = np.ones(6 * nm, dtype=bool)
    active.reshape(nm, 6)[~rot_used, 3:] = False
    for s in scene.supports:
        if s.body is not None:
            active[6 * mesh.body_index[s.body] : 6 * mesh.body_index[s.body] + 6] = False
        elif s.node in carrier:
            b = mesh.body_index[carrier[s.node]]
            active[6 * b : 6 * b + 6] = False
        else:
            assert s.node is not None  # a support names a body or a node (the scene's validator)
            m = mesh.node_master[mesh.node_index[s.node]]
            for d in s.dofs:
                active[6 * m + _DOF_INDEX[d]] = False
    return active


def _drive(
    scene: Scene, mesh: _Mesh, active: np.ndarray, rot_used: np.ndarray
) -> tuple[int, np.ndarray, int, np.ndarray, str]:
    """The drive: master, axis, DOF, basis of its block (first column the axis) and kind; frees the drive
    block's DOFs in that basis (``active`` is updated)."""
    st = scene.stroke
    if st is None:
        # no drive (a structure for exact-constraint diagnosis only): System refuses it with a clear error
        return -1, np.zeros(3), -1, np.eye(3), "none"
    if st.body is not None:
        drive_master = mesh.body_index[st.body]
    else:
        assert st.node is not None  # a stroke names a body or a node (the scene's validator)
        drive_master = int(mesh.node_master[mesh.node_index[st.node]])
    axis = _unit(st.axis)
    drive_dof = 6 * drive_master + (3 if st.kind == "rotation" else 0)
    if st.kind == "rotation" and not rot_used[drive_master]:
        raise SceneError(
            "stroke.node",
            f"node '{st.node}' has no rotational stiffness (it joins only "
            "trusses); drive it in translation or attach it to a beam",
        )
    blk = np.arange(drive_dof, drive_dof + 3)
    fixed_dirs = [np.eye(3)[k] for k in range(3) if not active[blk[k]]]
    if fixed_dirs:
        # partially supported driven node: the basis keeps the supported coordinate directions, so the
        # drive axis must be perpendicular to them (the scene validator already refuses a parallel one)
        if any(abs(f @ axis) > 1e-12 for f in fixed_dirs):
            raise SceneError(
                "stroke.axis",
                "the drive axis is not perpendicular to the supported "
                "coordinates of the driven node; align it with a free coordinate axis",
            )
        f0 = fixed_dirs[0]
        basis = np.column_stack([axis, f0, np.cross(axis, f0)])
        active[blk] = [True, False, len(fixed_dirs) < 2]
    else:
        basis = _basis(axis)
    return drive_master, axis, drive_dof, basis, st.kind


def _support_projector(scene: Scene) -> np.ndarray | None:
    """(6, 6) projector on the declared support directions of a master block, or None."""
    if scene.support_directions is None:
        return None
    sd = scene.support_directions
    projector = np.zeros((6, 6))
    for off, dirs in ((0, sd.translations), (3, sd.rotations)):
        if dirs:
            Qd, _ = np.linalg.qr(np.array(dirs, dtype=float).T)
            rank = np.linalg.matrix_rank(np.array(dirs, dtype=float))
            Qd = Qd[:, :rank]
            projector[off : off + 3, off : off + 3] = Qd @ Qd.T
    return projector


def _constraints(beam_rows: list[dict], truss_rows: list[dict], joint_const: np.ndarray) -> np.ndarray:
    """(nr, 3) rigid deformations: (kind 0 beam / 1 truss / 2 joint, element index, deformation index)."""
    cons: list[tuple[int, int, int]] = []
    for i, r in enumerate(beam_rows):
        cons += [(0, i, k) for k in range(6) if r["mask"][k] == 0.0]
    for i, r in enumerate(truss_rows):
        if r["mask"] == 0.0:
            cons.append((1, i, 0))
    for i, c in enumerate(joint_const):
        cons += [(2, i, k) for k in range(6) if c[12 + k] == 0.0]
    return np.array(cons, dtype=int).reshape(-1, 3)


def _joints(scene: Scene, node_index: dict[str, int], pos0: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Joint node pairs (nj, 2) and kernel constants (nj, JOINT_CONST): ``d0`` (q's offset from p; node axes are
    the global ones at the reference), the joint basis ``[a, b1, b2]`` (column-major) and the mask of free
    coordinates (hinge: the rotation about a; slider: the translation along a)."""
    nodes, const = [], []
    for j in scene.joints:
        p, q = j.nodes
        a = _unit(j.axis)
        B = _basis(a)
        mask = np.zeros(6)
        mask[3 if j.kind == "hinge" else 0] = 1.0
        nodes.append((node_index[p], node_index[q]))
        const.append(np.concatenate([pos0[q] - pos0[p], B.ravel(order="F"), mask]))
    nj = len(nodes)
    return np.array(nodes, dtype=int).reshape(nj, 2), np.array(const, dtype=float).reshape(nj, JOINT_CONST)


def _element_tables(beam_rows: list[dict], truss_rows: list[dict]) -> dict[str, np.ndarray]:
    """The Structure's beam and truss arrays from the rows."""

    def arr(rows, key, shape):  # noqa: ANN001, ANN202
        return np.array([r[key] for r in rows], dtype=float).reshape(shape) if rows else np.zeros(shape)

    nb, nt = len(beam_rows), len(truss_rows)
    return dict(
        beam_nodes=np.array([r["nodes"] for r in beam_rows], dtype=int).reshape(nb, 2),
        beam_const=arr(beam_rows, "const", (nb, BEAM_CONST)),
        beam_member=np.array([r["member"] for r in beam_rows], dtype=int),
        beam_stiff=arr(beam_rows, "S", (nb, 6, 6)),
        beam_mask=arr(beam_rows, "mask", (nb, 6)),
        beam_stress=arr(beam_rows, "stress", (nb, 7)),
        beam_mass=arr(beam_rows, "mass", (nb,)),
        truss_nodes=np.array([r["nodes"] for r in truss_rows], dtype=int).reshape(nt, 2),
        truss_const=np.array([[r["l0"], r["k1"], r["mask"]] for r in truss_rows]).reshape(nt, TRUSS_CONST),
        truss_member=np.array([r["member"] for r in truss_rows], dtype=int),
        truss_area=arr(truss_rows, "area", (nt,)),
        truss_mass=arr(truss_rows, "mass", (nt,)),
    )


def compile_scene(scene: Scene) -> Structure:
    """Mesh and index a validated scene: masters and nodes (:func:`_masters`), meshed elements
    (:func:`_elements`), lumped rotary inertia and body mass, free DOFs (:func:`_active`), the drive
    (:func:`_drive`), the size limit, support directions and rigid deformations.

    Raises
    ------
    SceneError
        For a node that is connected to nothing.
    ModelSizeError
        When the meshed model has more than ``MAX_DOFS`` active degrees of freedom.
    """
    pos0 = {n.name: np.array(n.position, dtype=float) for n in scene.nodes}
    carrier = {n: b.name for b in scene.bodies for n in b.nodes}
    length_scale = float(np.ptp(np.array(list(pos0.values())), axis=0).max())
    mesh = _masters(scene, pos0, carrier)
    beam_rows, truss_rows, warping = _elements(scene, mesh, pos0, carrier)

    nn, nm = len(mesh.node_names), len(mesh.master_names)
    node_master_a = np.array(mesh.node_master, dtype=int)
    master_pos_a = np.array(mesh.master_pos)
    node_offset = np.array(mesh.node_pos) - master_pos_a[node_master_a]

    node_rot = np.zeros((nn, 3, 3))
    rot_used = np.zeros(nm, dtype=bool)
    rot_used[: len(scene.bodies)] = True
    for r in beam_rows:
        for a_ in r["nodes"]:
            node_rot[a_] += r["rot"]
            rot_used[node_master_a[a_]] = True
    joint_nodes, joint_const = _joints(scene, {n: i for i, n in enumerate(mesh.node_names)}, pos0)
    rot_used[node_master_a[joint_nodes.ravel()]] = True  # a joint's coordinates involve both nodes' rotations
    master_mass = np.zeros(nm)
    master_inertia = np.zeros((nm, 3, 3))
    for i, b in enumerate(scene.bodies):
        master_mass[i] = b.mass
        master_inertia[i] = np.array(b.inertia, dtype=float)

    active = _active(scene, mesh, rot_used, carrier)
    drive_master, axis, drive_dof, basis, drive_kind = _drive(scene, mesh, active, rot_used)
    n_active = int(active.sum())
    if n_active > MAX_DOFS:
        raise ModelSizeError(
            "elements[].segments",
            f"the meshed model has {n_active} degrees of freedom, more than the limit of {MAX_DOFS}; "
            "use fewer segments per beam or model stiff parts as rigid bodies",
        )
    return Structure(
        scene=scene,
        length_scale=length_scale,
        node_names=tuple(mesh.node_names),
        node_master=node_master_a,
        node_offset=node_offset,
        master_names=tuple(mesh.master_names),
        master_pos=master_pos_a,
        active=active,
        **_element_tables(beam_rows, truss_rows),
        node_rot_inertia=node_rot,
        master_mass=master_mass,
        master_inertia=master_inertia,
        constraints=_constraints(beam_rows, truss_rows, joint_const),
        drive_master=drive_master,
        drive_kind=drive_kind,
        drive_axis=axis,
        drive_basis=basis,
        drive_dof=drive_dof,
        support_projector=_support_projector(scene),
        member_names=tuple(e.name for e in scene.elements),
        warping=tuple(warping),
        joint_nodes=joint_nodes,
        joint_const=joint_const,
        joint_names=tuple(j.name for j in scene.joints),
    )
