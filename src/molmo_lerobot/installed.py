"""Are installed distributions whole? For files read in place, checked before any worker starts.

Files a run reads in place from an installed distribution (the LIBERO asset library's meshes and textures, read
by our LIBERO rooms and by LIBERO's own env) that were deleted, truncated, made unreadable or replaced by a
symbolic link after installing would fail episodes one by one, as if the policy had. :func:`files_problem` walks
each distribution's ``RECORD`` (the files pip installed, with their sizes): existence, a regular file (not a
link: lookups resolve paths inside the package), the recorded size, readable; no parse. About 900 files for the
LIBERO asset library, a fraction of a second.
"""

from __future__ import annotations

import csv
import importlib.metadata as md
import os
from collections.abc import Iterable
from pathlib import Path


def distributions(prefix: str) -> list[md.Distribution]:
    """The installed distributions whose name starts with ``prefix``."""
    return [d for d in md.distributions() if (d.metadata["Name"] or "").lower().startswith(prefix)]


def files_problem(dists: Iterable[md.Distribution], package: str, what: str) -> str | None:
    """One line naming the first broken file of ``package`` (a top-level directory) in ``dists``, the distribution
    to reinstall and how many more files are broken, or ``None`` when every recorded file is whole (or none is
    installed). ``what``: what the files are, to open the line (``installed LIBERO assets``)."""
    faults: list[tuple[str, str]] = []  # (what is wrong, distribution)
    for dist in dists:
        name = dist.metadata["Name"]
        # RECORD itself: ``Distribution.files`` leaves out the files that are missing
        for row in csv.reader((dist.read_text("RECORD") or "").splitlines()):
            if not row or not row[0].startswith(f"{package}/"):
                continue
            size = int(row[2]) if len(row) > 2 and row[2].isdigit() else None
            why = _fault(Path(str(dist.locate_file(row[0]))), size)
            if why:
                faults.append((why, name))
    if not faults:
        return None
    (why, name), more = faults[0], len(faults) - 1
    names = sorted({n for _, n in faults})
    return (f"{what} are broken: {why} (distribution {name}); reinstall: pip install --force-reinstall --no-deps "
            f"{' '.join(names)}" + (f" ({more} more broken file{'s' * (more != 1)})" if more else ""))


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
