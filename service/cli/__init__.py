"""The ``flexopt`` command line: :mod:`.main` (the parser and ``main``), :mod:`.scene_args` (the scene
arguments every analysing command shares) and one module per subcommand (``template``, ``curve``,
``diagnose``, ``modes``, ``serve``, ``optimise``, ``topology``). Run it as ``flexopt`` or
``python -m flexopt.service.cli``."""

__all__: list[str] = []
