"""``python -m flexopt.service.cli``: the ``flexopt`` command line."""

from .main import main

if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
