"""LIBERO's assets as a plugin: the ``libero`` asset library over the installed LIBERO asset
distributions (used in place), grasps computed from their meshes, the ``libero_rooms`` scene
dataset, and the generator of the v2 benchmarks over them."""
