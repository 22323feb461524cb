"""vo3d-opt: safe velocities for multi-UAV systems by optimisation over the improved 3D velocity
obstacle (VO cones, VO pyramids, avoidance planes)."""

from .config import PRESETS, SelectorConfig
from .selector import Decision, VelocitySelector
from .types import AgentState, Box, Cylinder, Limits, Neighbor

__all__ = [
    "VelocitySelector",
    "PRESETS",
    "SelectorConfig",
    "Decision",
    "AgentState",
    "Neighbor",
    "Cylinder",
    "Box",
    "Limits",
]
__version__ = "0.3.0.dev0"
