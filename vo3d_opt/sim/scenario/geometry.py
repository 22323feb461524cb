"""Point geometry a scenario's checks and the metrics share: nearby pairs through a k-d tree,
inside an obstacle's protected prism, the distance to a sphere."""

from __future__ import annotations

import numpy as np

from vo3d_opt.types import Box, Cylinder


def nearby_pairs(
    points: np.ndarray, reach: np.ndarray, most: float
) -> list[tuple[int, int, float]]:
    """Point pairs (i, j, distance), i > j, in order of i then j, closer than ``reach[i] +
    reach[j]`` or so (a k-d tree proposes those within 2 × ``most`` ≥ any reach sum; the
    caller applies its own test): no loop over every pair, for scenarios of thousands of
    agents."""
    from scipy.spatial import cKDTree

    if len(points) < 2:
        return []
    within = 2.0 * float(most) * (1 + 1e-9) + 1e-9
    found = cKDTree(points).query_pairs(within, output_type="ndarray")
    i, j = found.max(axis=1), found.min(axis=1)
    order = np.lexsort((j, i))
    i, j = i[order], j[order]
    d = np.linalg.norm(points[i] - points[j], axis=-1)
    keep = d < reach[i] + reach[j]
    return [(int(a), int(b), float(c)) for a, b, c in zip(i[keep], j[keep], d[keep], strict=True)]


def prism_contains(body: Cylinder | Box, points: np.ndarray) -> np.ndarray:
    """Whether points (..., 3) lie inside the obstacle's protected prism C_pz.

    Section 4.1: the square prism turns so that a side faces the vehicle, so in the horizontal
    plane the vehicle is inside exactly when its distance to the obstacle's axis is below
    L_pz / 2; vertically the prism spans [0, h_pz].
    """
    p = np.asarray(points, dtype=float)
    horizontal = np.linalg.norm(p[..., :2] - np.asarray(body.center), axis=-1)
    return (horizontal < body.side / 2.0) & (p[..., 2] < body.prism_height) & (p[..., 2] >= 0.0)


def sphere_surface_distance(center: np.ndarray, radius: float, points: np.ndarray) -> np.ndarray:
    """Distance (m) from points (..., 3) to a sphere's surface (0 inside)."""
    p = np.asarray(points, dtype=float)
    return np.maximum(np.linalg.norm(p - np.asarray(center, dtype=float), axis=-1) - radius, 0.0)
