"""flexopt.service: the layers above the model and the optimiser, by role. Imports nothing heavy at import time.

==============  ============================================================================================
``api/``        the HTTP service: app factory, one routes module per resource, guards, middleware, errors,
                settings, runtime
``cli/``        the ``flexopt`` command line: the parser, shared scene arguments, one module per subcommand
``jobs/``       the job store, dispatcher and job process; the worker functions that compute
``schemas``     the wire models shared by the server and the client
``client``      the HTTP client (httpx and pydantic only)
``plots``       every figure (wire data only, no CasADi)
``logs``        JSON log lines
``web/``        the page at ``/`` and its vendored assets
==============  ============================================================================================

Direction: ``cli`` and ``api`` use ``jobs``; all use ``schemas``, ``plots`` and ``logs``; nothing here imports
``cli`` or ``api`` but ``cli.serve`` (which starts the app).
"""

__all__: list[str] = []
