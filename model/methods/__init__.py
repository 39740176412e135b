"""Frequency-curve methods: one registry (:data:`METHODS`) and one entry point, :func:`curve_with_method`.

``taylor`` (fd1, fd2 and the modal derivatives at stroke 0), ``manifold`` (manifold, reduced), ``accuracy``
(the error estimate of those expansions about stroke 0 and the one rule that limits their curves), ``hermite``
(exact samples with exact stroke derivatives, cubic Hermite along tracked branches) and ``auto`` (the
dispatcher and the automatic choice).
"""

from __future__ import annotations

from .auto import AUTO_ORDER, METHODS, curve_with_method, estimate_error, expansion_curve, frequency_curve
from .taylor import ModalDerivatives, hessian_second_derivative, mass_derivatives, modal_derivatives

__all__ = [
    "METHODS",
    "AUTO_ORDER",
    "curve_with_method",
    "estimate_error",
    "expansion_curve",
    "frequency_curve",
    "ModalDerivatives",
    "hessian_second_derivative",
    "mass_derivatives",
    "modal_derivatives",
]
