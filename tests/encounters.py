"""Random encounters for the selector's property tests (shared by test modules)."""
from __future__ import annotations

import numpy as np
from hypothesis import strategies as st

from vo3d_opt import AgentState, Box, Cylinder, Limits, Neighbor

#: The coarse planes, tangent samples and fallback grid of the ``fast`` preset.
COARSE = {"plane_step_deg": 45.0, "qp_samples": 12, "heading_step_deg": 45.0, "speed_levels": 3,
          "fine_planes": False}
#: The paper's avoidance planes and tangent samples, and one grid for the sampled selection and
#: the fallbacks: the safe preset's rules on the planes the scenarios were first flown on.
PAPER_GRID = {"plane_step_deg": 10.0, "qp_samples": 36, "fallback_heading_step_deg": None,
              "fallback_speed_levels": None}


@st.composite
def encounters(draw, max_neighbors: int = 12, max_obstacles: int = 6):
    """Keyword arguments of ``select``: 1–12 neighbours, 0–6 obstacles, random limits and dt,
    the own vehicle in bounds and outside every protected zone."""
    seed = draw(st.integers(0, 2**32 - 1))
    n = draw(st.integers(1, max_neighbors))
    m = draw(st.integers(0, max_obstacles))
    rng = np.random.default_rng(seed)
    v_max = float(rng.uniform(1.0, 6.0))
    z_min, z_max = 0.0, float(rng.uniform(15.0, 60.0))
    dt = float(rng.uniform(0.05, 0.5))
    p = np.array([0.0, 0.0, rng.uniform(z_min + 0.5, z_max - 0.5)])
    heading = rng.normal(size=3)
    heading[2] *= 0.3
    v_pref = heading / np.linalg.norm(heading) * rng.uniform(0.3, 1.0) * v_max
    neighbors = []
    for _ in range(n):
        r_pz = float(rng.uniform(2.0, 10.0))
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        dist = rng.uniform(r_pz * 1.05, 55.0)
        vb = rng.normal(size=3)
        vb *= rng.uniform(0.0, 4.0) / np.linalg.norm(vb)
        neighbors.append(Neighbor(position=p + dist * d, velocity=vb, r_pz=r_pz))
    obstacles = []
    while len(obstacles) < m:
        c = rng.uniform(-45.0, 45.0, 2)
        h = float(rng.uniform(5.0, 70.0))
        if rng.random() < 0.5:
            o = Cylinder(center=c, radius=float(rng.uniform(0.5, 5.0)), height=h)
        else:
            o = Box(center=c, size=rng.uniform(1.0, 8.0, 2), height=h, yaw=float(rng.uniform(-3.2, 3.2)))
        if np.linalg.norm(c - p[:2]) > o.side / 2 + 0.5:  # own vehicle outside the prism
            obstacles.append(o)
    return dict(
        own=AgentState(position=p, velocity=v_pref),
        preferred_velocity=v_pref,
        neighbors=neighbors,
        obstacles=obstacles,
        limits=Limits(speed=(0.0, v_max), altitude=(z_min, z_max)),
        dt=dt,
    )


def crowd(seed: int, n: int = 30, inside: bool = False, closing: float = 0.0):
    """A vehicle amid n neighbours 6–30 m away (r_pz 5) closing in from all sides: most of the
    grid lies in some VO, so the fallbacks' blocks decide most points. ``inside``: one
    neighbour's zone already holds the vehicle (its VO is then a half-space, no block's).
    ``closing``: each neighbour's least speed towards it (then, as in the sphere swap's
    centre, every velocity enters some zone and the least-bad search is by time)."""
    rng = np.random.default_rng(seed)
    p = np.array([0.0, 0.0, 30.0])
    nbs = []
    for k in range(n):
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        dist = 3.0 if (inside and k == 0) else rng.uniform(6.0, 30.0)
        vel = -d * rng.uniform(closing, 4.0) + rng.normal(size=3) * 0.5
        nbs.append(Neighbor(position=p + dist * d, velocity=vel, r_pz=5.0))
    v_pref = rng.normal(size=3)
    v_pref *= rng.uniform(1.0, 4.0) / np.linalg.norm(v_pref)
    return dict(own=AgentState(position=p, velocity=v_pref), preferred_velocity=v_pref,
                neighbors=nbs, obstacles=[], limits=Limits(speed=(0.0, 4.0), altitude=(0.0, 60.0)),
                dt=0.2)
