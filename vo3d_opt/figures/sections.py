"""What a side view (x-z, seen along y) may draw of the obstacles at one moment, so that no
vehicle looks inside an obstacle it is beside.

Drawn whole, a pillar's side view covers every vehicle at the same x and z, whatever its y: a
vehicle passing beside it looks inside. So an obstacle is drawn cut at the depth y of a vehicle
abreast of it (its section there: the chord of its footprint, the protected prism's disc of
radius L_pz/2, a sphere's circle), and only when no vehicle that is outside it would then lie in
the drawn section; among the vehicles abreast, the section nearest the obstacle's middle (the
widest) that passes is drawn. A vehicle inside an obstacle lies in its section at its own depth,
so what the view shows inside an obstacle is inside it, and what it shows outside is outside.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vo3d_opt.sim.record import RunRecord
from vo3d_opt.sim.scenario import prism_contains
from vo3d_opt.types import Box, Cylinder

from .scene import box_corners, obstacle_names


@dataclass(frozen=True)
class SideSection:
    """A shape a side view draws: ``kind`` "body" or "prism" (a rectangle [x0, x1] × [z0, z1]),
    or "sphere" (the circle of ``radius`` about (``cx``, ``cz``)); ``depth`` the y it is cut
    at."""

    name: str
    kind: str
    depth: float
    x0: float = 0.0
    x1: float = 0.0
    z0: float = 0.0
    z1: float = 0.0
    cx: float = 0.0
    cz: float = 0.0
    radius: float = 0.0

    def covers(self, x: np.ndarray, z: np.ndarray) -> np.ndarray:
        """Whether points (x, z) of the view lie in the drawn shape."""
        if self.kind == "sphere":
            return np.hypot(x - self.cx, z - self.cz) < self.radius
        return (x > self.x0) & (x < self.x1) & (z >= self.z0) & (z < self.z1)


def footprint_chord(body: Cylinder | Box, y: float) -> tuple[float, float] | None:
    """The x-interval the body's footprint spans at depth y, or None."""
    if isinstance(body, Cylinder):
        dy = y - float(body.center[1])
        if abs(dy) >= body.radius:
            return None
        half = math.sqrt(body.radius**2 - dy**2)
        return float(body.center[0]) - half, float(body.center[0]) + half
    corners = box_corners(body)
    xs = []
    for a in range(4):
        (xa, ya), (xb, yb) = corners[a], corners[(a + 1) % 4]
        if (ya - y) * (yb - y) <= 0 and ya != yb:
            xs.append(xa + (y - ya) / (yb - ya) * (xb - xa))
    return (min(xs), max(xs)) if len(xs) >= 2 and max(xs) > min(xs) else None


def disc_chord(cx: float, cy: float, radius: float, y: float) -> tuple[float, float] | None:
    """The x-interval a disc spans at depth y, or None."""
    dy = y - cy
    if abs(dy) >= radius:
        return None
    half = math.sqrt(radius**2 - dy**2)
    return cx - half, cx + half


def _inside(record: RunRecord, kind: str, k: int, p: np.ndarray) -> np.ndarray:
    """Whether the vehicles at p (N, 3) are inside part ``kind`` of obstacle k (3D)."""
    sc = record.scenario
    if kind == "sphere":
        sphere = sc.spheres[k]
        return np.linalg.norm(p - np.asarray(sphere.center), axis=-1) < sphere.radius
    body = sc.bodies[k]
    if kind == "prism":
        return prism_contains(body, p)
    d = p[:, :2] - np.asarray(body.center)
    if isinstance(body, Cylinder):
        over = np.hypot(d[:, 0], d[:, 1]) < body.radius
    else:
        c, s = math.cos(body.yaw), math.sin(body.yaw)
        local = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]])
        over = np.all(np.abs(local) < body.size / 2.0, axis=1)
    return over & (p[:, 2] >= 0.0) & (p[:, 2] < body.height)


def _section(
    record: RunRecord, kind: str, k: int, y: float, name: str, top: float
) -> SideSection | None:
    """Part ``kind`` of obstacle k cut at depth y (heights drawn up to ``top``), or None."""
    sc = record.scenario
    if kind == "sphere":
        s = sc.spheres[k]
        c = np.asarray(s.center, dtype=float)
        dy = y - c[1]
        if abs(dy) >= s.radius:
            return None
        r = math.sqrt(s.radius**2 - dy**2)
        return SideSection(name, kind, y, cx=float(c[0]), cz=float(c[2]), radius=r)
    body = sc.bodies[k]
    if kind == "prism":
        chord = disc_chord(float(body.center[0]), float(body.center[1]), body.side / 2.0, y)
        height = body.prism_height
    else:
        chord = footprint_chord(body, y)
        height = body.height
    if chord is None:
        return None
    return SideSection(name, kind, y, x0=chord[0], x1=chord[1], z0=0.0, z1=min(height, top))


def side_sections(record: RunRecord, p: np.ndarray, top: float = math.inf) -> list[SideSection]:
    """What a side view draws of the obstacles when the vehicles are at p (N, 3) (module
    docstring): at most one section of each body, of each sensed body's protected prism and of
    each sphere. ``top``: heights drawn up to it (the view's upper edge)."""
    sc = record.scenario
    bodies, spheres = obstacle_names(record)
    parts = [
        ("body", k, b.center[1], n) for k, (b, n) in enumerate(zip(sc.bodies, bodies, strict=True))
    ]
    parts += [
        ("prism", k, b.center[1], n)
        for k, (b, n, sensed) in enumerate(zip(sc.bodies, bodies, sc.sensed, strict=True))
        if sensed
    ]
    parts += [
        ("sphere", k, s.center[1], n)
        for k, (s, n) in enumerate(zip(sc.spheres, spheres, strict=True))
    ]
    out = []
    for kind, k, cy, name in parts:
        outside = ~_inside(record, kind, k, p)
        for i in np.argsort(np.abs(p[:, 1] - cy), kind="stable"):
            cut = _section(record, kind, k, float(p[i, 1]), name, top)
            if cut is None:
                break  # the others are further from the middle: no section either
            if not np.any(cut.covers(p[outside, 0], p[outside, 2])):
                out.append(cut)
                break
    return out
