"""Compatibility module: the fast methods live in :mod:`model.methods` (taylor, manifold, hermite, auto).

Kept so that ``flexopt.model.derivatives`` keeps working for existing code; new code imports from
``flexopt.model.methods``.
"""

from __future__ import annotations

from .methods.auto import AUTO_ORDER, METHODS, curve_with_method, estimate_error, frequency_curve
from .methods.common import CLUSTER_GAP, _curve_from, _first_parasitic, _hz
from .methods.manifold import _manifold_state, _reduced_basis, eigen_curve
from .methods.taylor import (
    ModalDerivatives,
    _clusters,
    _eq_at,
    _prepare,
    _Prepared,
    _to_reference_chart,
    hessian_second_derivative,
    mass_derivatives,
    modal_derivatives,
    taylor_curve,
)

__all__ = [
    "METHODS",
    "AUTO_ORDER",
    "CLUSTER_GAP",
    "ModalDerivatives",
    "modal_derivatives",
    "hessian_second_derivative",
    "mass_derivatives",
    "frequency_curve",
    "curve_with_method",
    "estimate_error",
    "eigen_curve",
    "taylor_curve",
]
_PRIVATE = (
    _curve_from,
    _first_parasitic,
    _hz,
    _manifold_state,
    _reduced_basis,
    _clusters,
    _eq_at,
    _prepare,
    _Prepared,
    _to_reference_chart,
)  # re-exported for tests and older callers
