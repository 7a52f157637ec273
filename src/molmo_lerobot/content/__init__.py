"""Built-in content: scenes, asset libraries, their benchmark generators and experts.

Plugin code, registered through the same entry points as a third-party plugin (``pyproject.toml``) and
placed above the core: ``sim``, ``tasks``, ``robots``, ``cameras`` and ``runner`` name no module of this
package (an import-linter contract checks it), so the core runs with any content a plugin brings.

- :mod:`.tabletop`: the ``tabletop`` procedural scenes and the v1 benchmark generator
- :mod:`.articulated`: the ``articulated`` scenes (cabinets, drawers) and the open / close generator
- :mod:`.libero`: LIBERO's assets (asset library, grasps, rooms, nav houses) and the v2 / nav generators
- :mod:`.doors`: the ``door_rooms`` houses, the ``door_v1`` generator and the door expert
"""
