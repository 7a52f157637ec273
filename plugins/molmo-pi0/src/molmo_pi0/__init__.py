"""pi0 for molmo_lerobot: a remote openpi policy server (DROID keys) or LeRobot's PI0 in process."""

__version__ = "0.1.0"
