"""The avoidance planes of one decision and the sections of every VO on them."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..geometry import CORRECTIONS, AvoidancePlanes, Sections, avoidance_planes, cone_sections, default_phis, pyramid_sections
from .common import Encounter


@dataclass
class PlaneSections:
    """The planes P_phi (common axis along the preferred velocity) and the sections on them."""

    planes: AvoidancePlanes
    cones: Sections
    pyramids: Sections
    w_pref: np.ndarray  # (2,) the preferred velocity in plane coordinates (the same on every plane)

    def contains(self, xy: np.ndarray) -> np.ndarray:
        """(P, M) whether in-plane points lie inside any section on their plane."""
        out = np.zeros(xy.shape[:2], dtype=bool)
        for sec in (self.cones, self.pyramids):
            if sec.kind.shape[0]:
                out |= np.any(sec.contains(xy), axis=0)
        return out


def decision_planes(enc: Encounter) -> AvoidancePlanes:
    """Planes every ``plane_step_deg`` about the preferred direction (or the current heading, or
    world x when both are zero)."""
    direction = enc.v_pref
    if math.hypot(*direction.tolist()) < 1e-9:
        direction = enc.v_now if math.hypot(*enc.v_now.tolist()) > 1e-9 else np.array([1.0, 0.0, 0.0])
    return avoidance_planes(direction, default_phis(enc.options.plane_step_deg))


def plane_sections(enc: Encounter, n_samples: int | None = None,
                   planes: AvoidancePlanes | None = None) -> PlaneSections:
    """The decision's planes (or ``planes``) and the conic sections of all VOs on them."""
    planes = decision_planes(enc) if planes is None else planes
    corrections = enc.options.corrections if enc.options.corrections is not None else CORRECTIONS
    return PlaneSections(
        planes=planes,
        cones=cone_sections(enc.cones, planes, corrections=corrections, n_samples=n_samples or enc.options.n_samples),
        pyramids=pyramid_sections(enc.pyramids, planes),
        w_pref=np.array([planes.e1 @ enc.v_pref, 0.0]),
    )
