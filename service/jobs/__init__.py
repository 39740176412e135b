"""Jobs: work that outlives a request, and the functions that compute in worker processes.

======================  ==================================================================================
``store``               the ``jobs`` table (SQLAlchemy): owners, idempotency keys, leases, fencing tokens
``dispatch``            the dispatcher thread: starts job processes, requeues lost runs
``run``                 the job process (``python -m flexopt.service.jobs run ID ATTEMPT``): an
                        optimisation, a topology search or a costly frequency curve
``worker``              the heavy work as plain functions of a JSON spec (the server's worker pool and the
                        job processes), the one JSON sanitiser, errors that cross process boundaries as data
======================  ==================================================================================

Imports nothing here, so a worker process that needs only :mod:`.worker` does not load SQLAlchemy.
"""

__all__: list[str] = []
