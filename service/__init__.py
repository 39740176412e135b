"""flexopt.service: command line, HTTP service (app.py), client (client.py). Imports nothing heavy at import time."""

__all__: list[str] = []
