"""The names of the frequency-curve methods: the one list that the model's registry
(:mod:`flexopt.model.methods`), the wire schema (:mod:`flexopt.service.schemas`), the command line and, through
``GET /health``, the web page all read.

It lives in the root package because it must import nothing: the client reads it without loading CasADi
(``flexopt.model``'s ``__init__`` loads the whole model), and the model reads it without importing upward.
"""

from __future__ import annotations

from typing import Literal, get_args

__all__ = ["METHODS", "Method"]

#: A frequency-curve method: exact (continuation + eigen at every point), fd1/fd2 (Taylor), manifold, reduced,
#: hermite (exact samples + exact stroke derivatives, cubic Hermite) or auto.
Method = Literal["exact", "fd1", "fd2", "manifold", "reduced", "hermite", "auto"]
METHODS: tuple[str, ...] = get_args(Method)
