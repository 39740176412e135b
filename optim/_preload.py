"""What the local process pool's fork server imports once (:func:`optim.batch.process_pool`), so that each worker
forked from it starts with CasADi, scipy and the case functions loaded instead of importing them itself
(measured: 2-4 s per worker on the shared 2-core machine, paid again by every pool of a topology search).
One BLAS thread is set first (model.threads), before numpy loads its BLAS."""

from ..model.threads import limit_process

limit_process()

from . import search  # noqa: E402, F401  (imported for its side effect: loaded in the fork server)
from .topology import rank, screen  # noqa: E402, F401
