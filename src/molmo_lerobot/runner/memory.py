"""What one worker holds in memory, by benchmark family, and the warning when a run's workers would not fit.

The figures are the peak resident memory of one worker (with its LIBERO env server), in GB of 2^30 bytes, as the
README's "Memory per worker" table states and says how each was measured (``tests/perf/test_worker_memory.py``
for the long runs): a worker bounds its allocator (:mod:`molmo_lerobot.allocator`), so it levels off at these
whatever the run's length.
"""

from __future__ import annotations

import re
from pathlib import Path

#: peak resident GB of one worker, (not recorded, recorded), by benchmark family (:func:`benchmark_family`)
WORKER_GB: dict[str, tuple[float, float]] = {
    "v1": (1.2, 1.7),
    "v2/v3": (2.9, 3.1),
    "nav/door": (1.7, 2.1),
    "libero": (3.8, 3.8),  # the worker and its LIBERO env server; not recorded is not measured apart
    "pusht": (0.2, 0.6),
}


def benchmark_family(benchmark: str, suite: str | None) -> str:
    """The :data:`WORKER_GB` family of a run's benchmark: its env suite, else read from its name; a benchmark
    named otherwise counts as the largest of ours."""
    if suite is not None and suite in WORKER_GB:
        return suite
    if re.match(r"(nav|door)_", benchmark):
        return "nav/door"
    return "v1" if benchmark.endswith("_v1") else "v2/v3"


def available_gb() -> float | None:
    """The memory this machine can give new processes (``MemAvailable``), or None where it does not say."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) / 2**20
    except OSError:
        return None
    return None


def memory_warning(workers: int, family: str, record: bool, available: float | None) -> str | None:
    """One line when ``workers`` workers of ``family`` would need more than ``available`` GB, else None."""
    need = workers * WORKER_GB[family][record]
    if available is None or need <= available:
        return None
    fit = int(available // WORKER_GB[family][record])
    return (f"molmo-eval: warning: {workers} workers x {WORKER_GB[family][record]:g} GB ({family}"
            f"{', recorded' if record else ''}) = {need:.1f} GB, more than the {available:.1f} GB this machine has "
            f"available; workers={max(fit, 1)} fits")
