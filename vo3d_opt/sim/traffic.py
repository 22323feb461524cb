"""Non-cooperative traffic (contract §5 ``avoids: false``): agents that fly straight to their goal
and never avoid. Their command is the goal-seeking velocity every agent prefers."""

from __future__ import annotations

from typing import Any

import numpy as np


def goal_velocity(positions: Any, goals: Any, max_speed: Any, dt: float) -> np.ndarray:
    """Velocities (N, 3) straight at each goal with speed ``min(max_speed, distance / dt)``: full
    speed, slowing only to land on the goal in the last period (0 on the goal).

    ``positions``, ``goals``: (N, 3); ``max_speed``: (N,) or one number, m/s; ``dt`` s."""
    p = np.asarray(positions, dtype=float)
    g = np.asarray(goals, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"positions: must have shape (N, 3), got {p.shape}")
    if g.shape != p.shape:
        raise ValueError(f"goals: must have shape {p.shape}, got {g.shape}")
    try:
        v_max = np.broadcast_to(np.asarray(max_speed, dtype=float), (p.shape[0],))
    except ValueError:
        raise ValueError(f"max_speed: must be one number or shape ({p.shape[0]},)") from None
    if np.any(~np.isfinite(v_max)) or np.any(v_max < 0):
        raise ValueError("max_speed: must be finite and >= 0")
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt: must be a positive finite number, got {dt!r}")
    to_goal = g - p
    dist = np.linalg.norm(to_goal, axis=1)
    speed = np.minimum(v_max, dist / dt)
    with np.errstate(invalid="ignore", divide="ignore"):
        unit = np.where(dist[:, None] > 0, to_goal / dist[:, None], 0.0)
    return unit * speed[:, None]
