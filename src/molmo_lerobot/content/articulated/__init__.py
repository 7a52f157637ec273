"""The ``articulated`` scene plugin (:mod:`.scene`) and the open / close benchmark generator (:mod:`.generate`)."""
