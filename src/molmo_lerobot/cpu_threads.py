"""CPU thread budget of a process that runs a policy (a worker, or the run's policy server)."""

from __future__ import annotations

import os
import sys


def cap_threads(n: int | None) -> None:
    """Give this process ``n`` CPU threads for torch and BLAS (None: leave their default).

    Every library otherwise starts one thread per core in every process, so W workers run
    W × cores threads: with a learned policy on CPU that oversubscription costs more than
    the workers gain. The same count everywhere also keeps CPU kernels' rounding the same
    for any worker count, in process or served.
    """
    if n is None:
        return
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        os.environ[var] = str(n)
    if "torch" in sys.modules:  # already imported (a policy plugin's import): set it directly
        sys.modules["torch"].set_num_threads(n)
