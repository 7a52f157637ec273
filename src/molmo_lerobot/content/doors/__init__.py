"""Rooms with hinged doors (the ``door_rooms`` scene plugin), the ``door_v1`` generator and the door expert."""
