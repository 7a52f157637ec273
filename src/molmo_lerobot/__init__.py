"""molmo_lerobot: evaluate manipulation policies on MuJoCo; every run is a LeRobot dataset."""

from molmo_lerobot.hookspecs import hookimpl

__version__ = "0.1.0"
__all__ = ["__version__", "hookimpl"]
