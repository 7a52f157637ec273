"""The ``articulated`` scene plugin (:mod:`.scene`), its kitchen objects and their grasps (:mod:`.objects`) and
the open / close benchmark generator (:mod:`.generate`)."""
