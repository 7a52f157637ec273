"""Rooms with hinged doors (the ``door_rooms`` scene plugin) and the ``door_v1`` generator."""
