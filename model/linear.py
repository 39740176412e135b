"""The linearised input-output model at a stroke point (issue 28, item 6; seed 002 sec. 2, its reference [5]:
Jonker, Aarts and van Dijk, Multibody System Dynamics 21(2), 2009).

At the equilibrium at stroke ``s`` the motion about it obeys ``M xi'' + C xi' + K xi = B_f u`` (``K`` the
tangent stiffness, the Hessian of the Lagrangian with the loads' stiffness, ``M`` the mass, both with the
drive locked or free as the scene says, rigid deformations and joints imposed through their null space by
:func:`model.modal.modes_at`). In the mass-normalised modes ``xi = Phi eta`` with modal damping ``zeta``:

    eta'' + 2 zeta Omega eta' + Omega^2 eta = Phi^T B_f u,     y = C_p Phi eta + C_v Phi eta',

so with the state ``x = [eta; eta']``: ``A = [[0, I], [-Omega^2, -2 zeta Omega]]``, ``B = [[0], [Phi^T B_f]]``,
``C = [[C_p Phi, C_v Phi]]``, ``D = 0`` (scipy.signal.StateSpace(A, B, C, D) ready). Inputs: a force or moment
on a node or body (``tip.fz``, ``stage.my``), in global axes; outputs: a position or rotation (``tip.z``,
``tip.ry``) or its rate (``tip.vz``, ``tip.wy``) of a node or body, in global axes, about the equilibrium.
The static gain ``-C A^-1 B`` is ``C_p Phi Omega^-2 Phi^T B_f``: with every mode kept, the compliance
``C_p K^-1 B_f``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .errors import EquilibriumError, SceneError
from .scene import Scene
from .threads import limited

__all__ = ["StateSpace", "frequency_response", "state_space"]

_FORCE = {"fx": (0, 0), "fy": (0, 1), "fz": (0, 2), "mx": (1, 0), "my": (1, 1), "mz": (1, 2)}
_OUTPUT = {
    "x": (0, 0, 0),
    "y": (0, 0, 1),
    "z": (0, 0, 2),
    "rx": (0, 1, 0),
    "ry": (0, 1, 1),
    "rz": (0, 1, 2),
    "vx": (1, 0, 0),
    "vy": (1, 0, 1),
    "vz": (1, 0, 2),
    "wx": (1, 1, 0),
    "wy": (1, 1, 1),
    "wz": (1, 1, 2),
}


@dataclass
class StateSpace:
    """``x' = A x + B u``, ``y = C x + D u`` about the equilibrium at ``stroke`` (modal coordinates)."""

    A: np.ndarray  # (2k, 2k)
    B: np.ndarray  # (2k, ni)
    C: np.ndarray  # (no, 2k)
    D: np.ndarray  # (no, ni)
    inputs: list[str]
    outputs: list[str]
    stroke: float  # stroke unit
    frequencies_hz: np.ndarray  # (k,) undamped natural frequencies of the modes kept
    damping: float
    units: dict[str, str] = field(default_factory=dict)

    def to_dict(self) -> dict:
        """JSON-ready: the matrices as nested lists, labels, the modes' frequencies and the conventions."""
        return {
            "A": self.A.tolist(),
            "B": self.B.tolist(),
            "C": self.C.tolist(),
            "D": self.D.tolist(),
            "inputs": self.inputs,
            "outputs": self.outputs,
            "stroke": self.stroke,
            "frequencies_hz": self.frequencies_hz.tolist(),
            "damping": self.damping,
            "units": self.units,
            "state": "modal displacements (first half) and velocities (second half), mass-normalised modes",
        }

    def static_gain(self) -> np.ndarray:
        """``D - C A^-1 B`` (no, ni): the response to a constant input."""
        return self.D - self.C @ np.linalg.solve(self.A, self.B)


def _point(s, name: str, what: str) -> tuple[int, np.ndarray]:
    """(master index, reference offset of the point from it) of a node or body name."""
    if name in s.node_names:
        i = s.node_names.index(name)
        return int(s.node_master[i]), s.node_offset[i]
    if name in s.master_names:
        return s.master_names.index(name), np.zeros(3)
    from .scene import did_you_mean

    raise SceneError(
        what, f"unknown node or body '{name}'{did_you_mean(name, list(s.node_names) + list(s.master_names))}"
    )


def _split(spec: str, table: dict, what: str) -> tuple[str, tuple]:
    name, _, comp = spec.rpartition(".")
    if not name or comp not in table:
        raise SceneError(
            what,
            f"'{spec}' is not NAME.COMPONENT with a component among {', '.join(table)}, e.g. 'tip.{next(iter(table))}'",
        )
    return name, table[comp]


@limited()  # one BLAS thread while it computes (model.threads)
def state_space(
    scene: Scene,
    at_stroke: float,
    inputs: list[str],
    outputs: list[str],
    damping: float = 0.01,
    modes: int | None = None,
) -> StateSpace:
    """The linearised model of ``scene`` at ``at_stroke`` (stroke unit; see the module docstring).

    ``modes``: how many of the lowest modes to keep (default all: the static gain is then the compliance).
    Raises SceneError for an unknown name or component, EquilibriumError when no equilibrium is found.
    """
    from .curve import Analysis
    from .modal import modes_at
    from .statics import walk

    if scene.stroke is None:
        raise SceneError("stroke", "a state-space model is taken at a stroke point: add a 'stroke'")
    if not (0 <= damping < 1):
        raise SceneError("damping", f"modal damping ratio {damping} must be in [0, 1)")
    if not inputs or not outputs:
        raise SceneError("inputs", "give at least one input and one output")
    an = Analysis(scene)
    s, sys = an.structure, an.system
    if sys.loads is not None and sys.loads.nonconservative:
        raise SceneError(
            "loads",
            "the state-space model is built from the mass-normalised modes of a symmetric stiffness; the "
            f"non-conservative load(s) {', '.join(sys.loads.nonconservative_names())} make it unsymmetric: remove "
            "them (dead forces and gravity are supported)",
        )
    target = float(scene.stroke.to_internal(at_stroke))
    got: list = []
    targets = np.linspace(0.0, target, 9)[1:] if target != 0 else np.array([0.0])
    fail = walk(sys, targets, an.options, lambda eq: got.append(eq))
    if fail is not None or not got:
        raise EquilibriumError(
            f"no equilibrium at stroke {at_stroke:g}: {fail.message if fail else ''}",
            stroke=at_stroke,
            last_converged=float("nan"),
            reason=fail.reason if fail else "divergence",
        )
    eq = got[-1]
    locked = scene.stroke.drive == "locked"
    available = (len(sys.free) if locked else sys.n) - sys.n_con
    k = available if modes is None else min(int(modes), available)
    md = modes_at(sys, eq, k, scene.stroke.drive)
    if np.any(md.omega2 <= 0):
        raise EquilibriumError(
            f"the equilibrium at stroke {at_stroke:g} is not stable (lowest omega^2 "
            f"{md.omega2.min():.3g}): a linearised model about it does not settle",
            stroke=at_stroke,
            last_converged=float("nan"),
            reason="unstable",
        )
    Phi, w = md.phi, np.sqrt(md.omega2)
    R = eq.state.R

    def covector(spec: str, table: dict, what: str) -> tuple[np.ndarray, int]:
        """The row (active numbering) of a point's translation or rotation along an axis, and its rate flag."""
        name, code = _split(spec, table, what)
        rate, kind, axis = code if len(code) == 3 else (0, *code)
        m, r0 = _point(s, name, what)
        r = R[m] @ r0
        d = np.eye(3)[axis]
        g = np.zeros(sys.n_full)
        if kind == 0:  # a translation of (a force at) the point: u + psi x r (its work conjugate: f, r x f)
            g[6 * m : 6 * m + 3] = d
            g[6 * m + 3 : 6 * m + 6] = np.cross(r, d)
        else:  # a rotation (a moment): psi
            g[6 * m + 3 : 6 * m + 6] = d
        return sys.from_global(g), rate

    Bf = np.column_stack([covector(u, _FORCE, "inputs")[0] for u in inputs])
    rows = [covector(y, _OUTPUT, "outputs") for y in outputs]
    nk = len(w)
    A = np.block([[np.zeros((nk, nk)), np.eye(nk)], [-np.diag(w**2), -2 * damping * np.diag(w)]])
    B = np.vstack([np.zeros((nk, len(inputs))), Phi.T @ Bf])
    C = np.vstack(
        [
            np.concatenate([c @ Phi, np.zeros(nk)]) if rate == 0 else np.concatenate([np.zeros(nk), c @ Phi])
            for c, rate in rows
        ]
    )
    units = {
        "inputs": "N (forces), N m (moments), global axes",
        "outputs": "m, rad, m/s, rad/s (global axes, about the equilibrium)",
        "time": "s",
    }
    return StateSpace(
        A,
        B,
        C,
        np.zeros((len(outputs), len(inputs))),
        list(inputs),
        list(outputs),
        float(at_stroke),
        w / (2 * np.pi),
        float(damping),
        units,
    )


@limited()  # one BLAS thread while it computes (model.threads)
def frequency_response(ss: StateSpace, frequencies_hz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Magnitude and phase [deg] of ``C (j w I - A)^-1 B + D`` at ``frequencies_hz``: (nf, no, ni) each."""
    f = np.asarray(frequencies_hz, dtype=float)
    n = ss.A.shape[0]
    H = np.array([ss.C @ np.linalg.solve(2j * np.pi * fk * np.eye(n) - ss.A, ss.B) + ss.D for fk in f])
    return np.abs(H), np.degrees(np.angle(H))
