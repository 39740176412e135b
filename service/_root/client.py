"""``flexopt.client``: the typed HTTP client (httpx and pydantic only; no CasADi, no FastAPI).

Re-exports :mod:`flexopt.service.client`; see its docstring for the classes and the error tree.
"""

from __future__ import annotations

from .service.client import *  # noqa: F401,F403
from .service.client import __all__  # noqa: F401
