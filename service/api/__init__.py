"""The HTTP service: ``app`` (``create_app``, health, the OpenAPI document), ``routes/`` (one module per
resource under ``/v1``), ``guards`` (API key, scene validation, model-size and cost limits), ``middleware``
(request log, body limit, JSON only), ``errors`` (problem details), ``settings`` and ``runtime`` (the worker
pool, slots, cache and jobs of one application). Imports nothing here: ``from flexopt.service.api.app import
create_app``."""

__all__: list[str] = []
