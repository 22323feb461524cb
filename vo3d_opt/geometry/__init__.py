"""The paper's geometry: VO cones (eqs 1–6), VO pyramids (section 4), avoidance planes (eq. 8),
conic sections with the corrections of section 3.1, and exact 3D membership."""
from .cone import TAU_MIN, VOCones, vo_cones
from .frames import AvoidancePlanes, avoidance_frame, avoidance_planes, default_phis
from .membership import cone_penetration, in_vo_cones, in_vo_pyramids, in_vos, pyramid_entry_time
from .pyramid import VOPyramids, vo_pyramids
from .sections import CORRECTIONS, KINDS, Sections, cone_sections, pyramid_sections

__all__ = [
    "TAU_MIN", "VOCones", "vo_cones", "AvoidancePlanes", "avoidance_frame", "avoidance_planes",
    "default_phis", "cone_penetration", "in_vo_cones", "in_vo_pyramids", "in_vos", "pyramid_entry_time",
    "VOPyramids", "vo_pyramids", "CORRECTIONS", "KINDS", "Sections", "cone_sections",
    "pyramid_sections",
]
