"""flexopt.optim: optimisation of flexure designs (see the optimisation issue)."""

__all__: list[str] = []
