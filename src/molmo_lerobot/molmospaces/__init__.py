"""MolmoSpaces' own data, used unchanged: its assets dir (scenes, thor/objaverse objects, DROID
grasps), its scene datasets (iTHOR, ProcTHOR, Holodeck, user scenes) and the run settings that
point at them (``molmospaces.*``, ``scene_xml_paths``, ``asset_libraries``, ``grasp_libraries``).
"""

from molmo_lerobot.molmospaces.settings import MolmoSpacesSettings

__all__ = ["MolmoSpacesSettings"]
