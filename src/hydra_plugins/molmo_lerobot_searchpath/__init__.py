"""molmo_lerobot's Hydra search-path plugin, found by Hydra's plugin discovery (the ``hydra_plugins`` namespace)."""
