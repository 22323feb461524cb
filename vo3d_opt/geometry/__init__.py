"""The paper's geometry: VO cones (eqs 1–6), VO pyramids (section 4), avoidance planes (eq. 8),
conic sections with the corrections of section 3.1, and exact 3D membership. The shapes are
NamedTuples of arrays, read by name in Python and by position in compiled code
(``vo3d_opt/algorithm/convert.hpp``): their fields' order is part of the core's interface."""

from .cone import TAU_MIN, VOCones, build_cones, vo_cones
from .frames import AvoidancePlanes, avoidance_frame, avoidance_planes, build_planes, default_phis
from .membership import (
    clearance_floors,
    clearances,
    cone_penetration,
    in_vo_cones,
    in_vo_pyramids,
    in_vos,
    pyramid_entry_time,
)
from .pyramid import VOPyramids, build_pyramids, prism_rows, vo_pyramids
from .sections import (
    CORRECTIONS,
    KINDS,
    Corrections,
    Section,
    Sections,
    cone_sections,
    pyramid_sections,
)

__all__ = [
    "TAU_MIN",
    "VOCones",
    "build_cones",
    "vo_cones",
    "AvoidancePlanes",
    "avoidance_frame",
    "avoidance_planes",
    "build_planes",
    "default_phis",
    "clearance_floors",
    "clearances",
    "cone_penetration",
    "in_vo_cones",
    "in_vo_pyramids",
    "in_vos",
    "pyramid_entry_time",
    "VOPyramids",
    "build_pyramids",
    "prism_rows",
    "vo_pyramids",
    "CORRECTIONS",
    "KINDS",
    "Corrections",
    "Section",
    "Sections",
    "cone_sections",
    "pyramid_sections",
]
