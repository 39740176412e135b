"""flexopt.optim: maximise the worst-case first parasitic frequency over the stroke, across hinge families.

``optimise(problem)`` runs every start of every family as a batch (a local process pool, or a Dask cluster)
and returns the verified optimum of each family and their ranking; ``Problem`` is the JSON problem.
"""

from .optimise import cases, optimise, run_case, summarise
from .problem import Family, Problem

__all__ = ["optimise", "run_case", "cases", "summarise", "Problem", "Family"]
