"""vo3d-opt: safe velocities for multi-UAV systems by optimisation over the improved 3D velocity
obstacle (VO cones, VO pyramids, avoidance planes)."""

from .selector import FAST_OPTIONS, Decision, VelocitySelector, swarm_options
from .types import AgentState, Box, Cylinder, Limits, Neighbor

__all__ = [
    "VelocitySelector",
    "FAST_OPTIONS",
    "swarm_options",
    "Decision",
    "AgentState",
    "Neighbor",
    "Cylinder",
    "Box",
    "Limits",
]
__version__ = "0.1.0"
