"""The ``tabletop`` scene plugin (:mod:`.scene`) and the v1 benchmark generator over it (:mod:`.generate`)."""
