"""Swarm scenarios made by a rule, for any number of agents (the bundled
``random-crossing-1000`` and ``sphere-swap-16`` are two of them written out, and
``benchmarks/bench_swarm.py`` flies them at 100 to 10,000 agents).

:func:`sphere_swap_scenario`: an antipodal swap on a Fibonacci sphere, every path through the
centre (a 3D circle swap).

:func:`random_crossing_scenario`: a constant-density random crossing. The agents start at
random in a horizontal slab of airspace whose area grows with their number (one agent per
``volume_per_agent`` m³), at least ``spacing`` apart, and each flies ``distance`` metres in a
random horizontal direction (climbing or descending a little) to a goal that is also at least
``spacing`` from every other goal. So the density, the flight length and what each agent meets
on its way do not depend on N: the cost per agent-step of a method that scales should not
either.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from vo3d_opt.sim.scenario import Scenario, scenario_from_dict

#: Tries per agent before the sampler gives up (the default density leaves plenty of room).
_TRIES = 200


class _Grid:
    """Points kept at least ``spacing`` apart, found through cells of side ``spacing``."""

    def __init__(self, spacing: float) -> None:
        self.spacing = spacing
        self.cells: dict[tuple[int, int, int], list[np.ndarray]] = {}

    def _key(self, p: np.ndarray) -> tuple[int, int, int]:
        k = np.floor(p / self.spacing).astype(int)
        return int(k[0]), int(k[1]), int(k[2])

    def clear(self, p: np.ndarray) -> bool:
        """Whether p is at least ``spacing`` from every point added."""
        x, y, z = self._key(p)
        return all(
            np.sum((p - q) ** 2) >= self.spacing**2
            for dx in (-1, 0, 1)
            for dy in (-1, 0, 1)
            for dz in (-1, 0, 1)
            for q in self.cells.get((x + dx, y + dy, z + dz), ())
        )

    def add(self, p: np.ndarray) -> None:
        self.cells.setdefault(self._key(p), []).append(p)


def _place(n: int, spacing: float, propose: Any, what: str) -> np.ndarray:
    """n points, point i the first of ``propose(i)``'s proposals at least ``spacing`` from the
    points placed before it (random sequential addition)."""
    grid, out = _Grid(spacing), np.empty((n, 3))
    for i in range(n):
        for _ in range(_TRIES):
            p = propose(i)
            if p is not None and grid.clear(p):
                break
        else:
            raise ValueError(f"spacing: cannot place {what} {i} {spacing:g} m from the others")
        out[i] = p
        grid.add(p)
    return out


def random_crossing_scenario(
    n: int,
    *,
    seed: int = 0,
    volume_per_agent: float = 40.0**3,
    distance: float = 200.0,
    slab: tuple[float, float] = (10.0, 90.0),
    spacing: float = 25.0,
    r_pz: float = 10.0,
    v_max: float = 4.0,
    dt: float = 0.2,
    vehicle_range: float = 55.0,
    radius: float = 0.5,
    decimals: int | None = 2,
    name: str | None = None,
) -> Scenario:
    """The constant-density random crossing of ``n`` agents (module docstring), seeded.

    The slab spans altitudes ``slab`` (the altitude limits are 10 m wider on each side) and a
    square of side ``sqrt(n * volume_per_agent / thickness)``; each goal is ``distance`` m from
    its start at a uniform heading and a climb angle within ±10°, inside the altitude band.
    ``decimals``: coordinates rounded as a file would store them (None: not rounded).
    ``max_time``: twice the straight flight time plus 30 s."""
    if n < 1:
        raise ValueError("n: at least one agent")
    rng = np.random.default_rng(seed)
    z_lo, z_hi = slab
    side = math.sqrt(n * volume_per_agent / (z_hi - z_lo))

    def start(_: int) -> np.ndarray:
        return np.array([rng.uniform(0.0, side), rng.uniform(0.0, side), rng.uniform(z_lo, z_hi)])

    P = _place(n, spacing, start, "start")

    def goal(i: int) -> np.ndarray | None:
        heading, climb = rng.uniform(0.0, 2 * math.pi), math.radians(rng.uniform(-10.0, 10.0))
        g = P[i] + distance * np.array(
            [
                math.cos(heading) * math.cos(climb),
                math.sin(heading) * math.cos(climb),
                math.sin(climb),
            ]
        )
        return g if z_lo <= g[2] <= z_hi else None

    G = _place(n, spacing, goal, "goal")
    if decimals is not None:
        P, G = np.round(P, decimals), np.round(G, decimals)
    width = len(str(n - 1))
    data = {
        "name": name or f"random-crossing-{n}",
        "description": (
            f"{n} UAVs start at random in a {side:.0f} m square slab of airspace, "
            f"{z_lo:g}-{z_hi:g} m high (one UAV per {volume_per_agent:,.0f} m3, at least "
            f"{spacing:g} m apart), and each flies {distance:g} m in a random direction "
            f"to a goal at least {spacing:g} m from the others, all at once. Generated "
            f"by vo3d_opt.generators.random_crossing_scenario({n}, seed={seed})."
        ),
        "dt": float(dt),
        "max_time": float(math.ceil(2.0 * distance / v_max + 30.0)),
        "goal_tolerance": 1.0,
        "limits": {"speed": [0.0, float(v_max)], "altitude": [z_lo - 10.0, z_hi + 10.0]},
        "sensing": {"vehicle_range": float(vehicle_range), "obstacle_range": float(vehicle_range)},
        "defaults": {"r_pz": float(r_pz), "radius": float(radius), "max_speed": float(v_max)},
        "agents": [
            {"id": f"u{i:0{width}d}", "start": P[i].tolist(), "goal": G[i].tolist()}
            for i in range(n)
        ],
    }
    return scenario_from_dict(data, source=f"<random_crossing_scenario({n})>")


__all__ = ["random_crossing_scenario"]


# ------------------------------------------------------------------------ swap scenarios


def fibonacci_sphere(n: int) -> np.ndarray:
    """n nearly evenly spread unit vectors (n, 3), the first near the north pole."""
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    theta = np.pi * (3.0 - math.sqrt(5.0)) * k
    return np.stack([r * np.cos(theta), r * np.sin(theta), z], axis=1)


def _min_spacing(points: np.ndarray) -> float:
    from scipy.spatial import cKDTree

    d, _ = cKDTree(points).query(points, k=2)
    return float(d[:, 1].min())


def sphere_swap_scenario(
    n: int,
    *,
    r_pz: float = 8.0,
    spacing: float = 2.0,
    dt: float = 0.2,
    v_max: float = 4.0,
    vehicle_range: float = 55.0,
    radius: float = 0.5,
    floor: float = 5.0,
    max_time: float | None = None,
) -> Scenario:
    """An antipodal swap of ``n`` agents on a Fibonacci sphere (a 3D circle swap).

    The sphere's radius grows with n so that neighbouring starts (and goals) are at least
    ``spacing * r_pz`` apart (and never below ``2 r_pz`` for tiny n): nobody starts inside a
    protected zone. Every agent flies to the antipode of its start, so every path passes
    through the centre. The altitude range [0, 2 R + 2 floor] contains the sphere with
    ``floor`` metres to spare; ``max_time`` defaults to three times the straight flight time
    + 30 s (with the closing guard, the last agents of the N = 10,000 swap wait about 4 minutes
    in the jam at the centre, then fly out at full speed: twice was too short for them).
    Same parameters as scenarios/sphere-swap-16.yaml by default (r_pz 8 m, 4 m/s, dt 0.2 s).
    """
    if n < 2:
        raise ValueError("n: a swap needs at least 2 agents")
    unit = fibonacci_sphere(n)
    d1 = _min_spacing(unit) if n > 2 else 2.0
    R = max(spacing * r_pz / d1, 2.0 * r_pz)
    R = math.ceil(R * 100.0) / 100.0
    centre = np.array([0.0, 0.0, R + floor])
    starts = centre + R * unit
    goals = centre - R * unit
    width = len(str(n - 1))
    if max_time is None:
        max_time = math.ceil(3.0 * (2.0 * R / v_max) + 30.0)
    data = {
        "name": f"sphere-swap-{n}",
        "description": f"{n} agents on a sphere of radius {R:g} m swap to their antipodes "
        f"(generated by vo3d_opt.generators.sphere_swap_scenario).",
        "dt": float(dt),
        "max_time": float(max_time),
        "goal_tolerance": 1.0,
        "limits": {"speed": [0.0, float(v_max)], "altitude": [0.0, float(2 * R + 2 * floor)]},
        "sensing": {"vehicle_range": float(vehicle_range), "obstacle_range": float(vehicle_range)},
        "defaults": {"r_pz": float(r_pz), "radius": float(radius), "max_speed": float(v_max)},
        "agents": [
            {
                "id": f"u{i:0{width}d}",
                "start": [float(c) for c in starts[i]],
                "goal": [float(c) for c in goals[i]],
            }
            for i in range(n)
        ],
    }
    return scenario_from_dict(data, source=f"<sphere_swap_scenario({n})>")


#: RVO2-3D's ``examples/Sphere.cc`` as its authors wrote it: time step, neighbour distance,
#: maximum neighbours, time horizon (s), agent radius (m), maximum speed (m/s); the preferred
#: velocity is a unit vector towards the goal, and the run ends when every agent is within two
#: radii of its goal.
RVO2_SPHERE = {
    "dt": 0.125,
    "neighbor_dist": 15.0,
    "max_neighbors": 10,
    "time_horizon": 10.0,
    "radius": 1.5,
    "max_speed": 2.0,
    "preferred_speed": 1.0,
}
#: RVO2-3D's agent radius is what keeps two agents apart: here the protected zone, r_pz = two
#: radii. Three pairs of the example's agents start closer than that (0.29 m the closest), so
#: the body counted for collisions is this small (m); those pairs start inside each other's
#: zones (the summary's ``starts_inside_pz``).
RVO2_SPHERE_BODY = 0.1
#: The sphere's centre is raised this high (m) so that every altitude is positive; nothing else
#: depends on it (no obstacle, no ground).
RVO2_SPHERE_LIFT = 110.0


def rvo2_sphere_points() -> np.ndarray:
    """The starts of RVO2-3D's Sphere example, (812, 3), in its own float32 arithmetic: rings
    ``i`` of a sphere of radius 100 (z = 100 cos(i / 10)), agents 2.5 m apart along each."""
    two_pi = np.float32(6.28318530717958647692)
    out = []
    i = 0
    while np.float32(i) < np.float32(5.0) * two_pi:
        z = np.float32(100.0) * np.cos(np.float32(i) / np.float32(10.0), dtype=np.float32)
        r = np.float32(100.0) * np.sin(np.float32(i) / np.float32(10.0), dtype=np.float32)
        j = 0
        while np.float32(j) < r / np.float32(2.5):
            angle = np.float32(j) * two_pi / (r / np.float32(2.5))
            x = r * np.cos(angle, dtype=np.float32)
            y = r * np.sin(angle, dtype=np.float32)
            out.append((float(x), float(y), float(z)))
            j += 1
        i += 1
    return np.array(out, dtype=float)


def rvo2_sphere_scenario() -> Scenario:
    """:func:`rvo2_sphere_data` as a :class:`Scenario`."""
    return scenario_from_dict(rvo2_sphere_data(), source="<rvo2_sphere_scenario()>")


def rvo2_sphere_data() -> dict[str, Any]:
    """RVO2-3D's Sphere benchmark as a scenario: 812 agents on a sphere of radius 100 m fly to
    their antipodes at a preferred 1 m/s (at most 2 m/s), time step 0.125 s, sensing range
    15 m; protected zones of 3 m (two RVO radii: a pair closer than that overlaps in RVO2-3D's
    terms; bodies of ``RVO2_SPHERE_BODY``), goal tolerance 3 m (two radii). Fly it with at
    most 10 neighbours per agent (``vo3d run --max-neighbors 10``), RVO2-3D's
    ``maxNeighbors``."""
    p = RVO2_SPHERE
    starts = rvo2_sphere_points()
    centre = np.array([0.0, 0.0, RVO2_SPHERE_LIFT])
    width = len(str(len(starts) - 1))
    span = 100.0 + RVO2_SPHERE_LIFT - 100.0
    data = {
        "name": "rvo2-sphere-812",
        "description": "RVO2-3D's own Sphere benchmark (examples/Sphere.cc): 812 agents on a "
        "sphere of radius 100 m fly to their antipodes at 1 m/s preferred, 2 m/s at most, "
        "dt 0.125 s, neighbour distance 15 m, radius 1.5 m (generated by "
        "vo3d_opt.generators.rvo2_sphere_scenario).",
        "dt": p["dt"],
        "max_time": 1000.0,
        "goal_tolerance": 2.0 * p["radius"],
        "limits": {"speed": [0.0, p["max_speed"]], "altitude": [0.0, 2.0 * span + 10.0]},
        "sensing": {"vehicle_range": p["neighbor_dist"], "obstacle_range": p["neighbor_dist"]},
        "defaults": {
            "r_pz": 2.0 * p["radius"],
            "radius": RVO2_SPHERE_BODY,
            "max_speed": p["max_speed"],
            "cruise_speed": p["preferred_speed"],
        },
        "agents": [
            {
                "id": f"s{k:0{width}d}",
                "start": [float(c) for c in centre + s],
                "goal": [float(c) for c in centre - s],
            }
            for k, s in enumerate(starts)
        ],
    }
    return data
