"""One exception tree for the flexure model.

::

    FlexoptError                      base: every error flexopt raises on purpose
    ├── SceneError                    the scene is malformed or non-physical (names a field and a fix)
    │   └── MassUnderflowError        masses too small for double precision (e.g. density 1e-300)
    ├── ModelSizeError                the meshed model exceeds the documented size limit
    ├── EquilibriumError              no converged equilibrium at a requested stroke (limit point,
    │                                 bifurcation, divergence); carries the last converged stroke
    └── KernelBuildError              a compiled CasADi kernel could not be built or loaded

Every message says what is wrong *and* how to fix it.
"""

from __future__ import annotations

__all__ = [
    "FlexoptError",
    "SceneError",
    "ModelSizeError",
    "MassUnderflowError",
    "EquilibriumError",
    "KernelBuildError",
]


class FlexoptError(Exception):
    """Base class of every error flexopt raises on purpose."""


class SceneError(FlexoptError, ValueError):
    """A scene is malformed or non-physical.

    Parameters
    ----------
    field
        Dotted location of the offending field, e.g. ``elements[2].nodes``.
    message
        What is wrong and how to fix it.
    """

    def __init__(self, field: str, message: str) -> None:
        self.field = field
        self.message = message
        super().__init__(f"{field}: {message}" if field else message)


class ModelSizeError(SceneError):
    """The meshed model is larger than the documented limit (see ``model.structure.MAX_DOFS``)."""


class MassUnderflowError(SceneError):
    """The scene's masses are too small for double precision (e.g. a density of 1e-300): the mass matrix
    underflows and omega^2 overflows (see ``model.causes.check_mass``)."""


class EquilibriumError(FlexoptError):
    """No converged equilibrium could be found at a requested stroke value.

    Attributes
    ----------
    stroke
        The stroke value at which equilibrium was lost (in the stroke's unit).
    last_converged
        The last stroke value with a converged, stable equilibrium.
    reason
        ``"divergence"`` (Newton failed at the minimum step: limit point or snap-through)
        or ``"unstable"`` (tangent stiffness lost positive definiteness: bifurcation or buckling).
    """

    def __init__(self, message: str, *, stroke: float, last_converged: float, reason: str) -> None:
        self.stroke = stroke
        self.last_converged = last_converged
        self.reason = reason
        super().__init__(message)


class KernelBuildError(FlexoptError):
    """A compiled kernel could not be generated, compiled or loaded."""
