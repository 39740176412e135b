"""flexopt.service: command line now; HTTP service and client later. Imports nothing heavy at import time."""

__all__: list[str] = []
