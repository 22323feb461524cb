"""The sweep families: each draws one encounter from stated parameter distributions (written
out per family below and in ``scenarios/README.md``, "Sweep families") and registers itself
with :func:`~vo3d_opt.generators.encounter.register`."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from vo3d_opt.generators.encounter import (
    DT,
    PRISM_CLEARANCE,
    SEPARATION,
    SPEED_DECIMALS,
    TIME_FACTOR,
    TIME_SLACK,
    Draw,
    base_scenario,
    place_apart,
    register,
    to_mm,
    unit_perpendicular,
)

# ------------------------------------------------------------------------------- pair

PAIR_SPEED = (2.0, 6.0)  # m/s, each UAV's cruise (= max) speed, uniform
PAIR_CLIMB = (-1.5, 1.5)  # m/s, each UAV's climb rate, uniform
PAIR_R_PZ = (5.0, 12.0)  # m, each UAV's protected-zone radius, uniform
PAIR_MISS = (0.0, 1.2)  # planned miss distance / max(r_pz), uniform
PAIR_T_CPA = (20.0, 40.0)  # s from the start to the planned closest approach, uniform
PAIR_T_AFTER = (10.0, 30.0)  # s flown past it before the goal, uniform per UAV
PAIR_CPA_ALTITUDE = 100.0  # m; altitude range [0, 200] m


@register(
    "pair",
    "two UAVs on a random 3D crossing: headings, speeds 2-6 m/s, climb rates "
    "+-1.5 m/s, r_pz 5-12 m, planned miss distance 0-1.2 r_pz",
    obstacle_free=True,
)
def pair(rng: np.random.Generator) -> Draw:
    """Two UAVs flying straight at constant velocity would pass each other at a planned miss
    distance ``m`` at time ``t_cpa``: each UAV ``k`` has speed ``v_k``, climb rate ``c_k``,
    horizontal heading ``psi_k`` (``psi_1`` uniform, ``psi_2 = psi_1 + crossing angle``,
    uniform in [-180, 180] deg) and protected zone ``r_pz_k``; at ``t_cpa`` they are at ``C -+
    m/2 n`` (``C`` = (0, 0, 100 m), ``n`` perpendicular to their relative velocity at a uniform
    angle around it); start = that point - ``v t_cpa``, goal = that point + ``v t_after_k``.
    Without avoidance they fly exactly this (the preferred velocity points at the goal at the
    agent's max speed)."""
    v = rng.uniform(*PAIR_SPEED, 2)
    climb = rng.uniform(*PAIR_CLIMB, 2)
    r_pz = rng.uniform(*PAIR_R_PZ, 2)
    psi1 = rng.uniform(-math.pi, math.pi)
    crossing = rng.uniform(-math.pi, math.pi)
    miss_ratio = rng.uniform(*PAIR_MISS)
    miss_angle = rng.uniform(0.0, 2.0 * math.pi)
    t_cpa = rng.uniform(*PAIR_T_CPA)
    t_after = rng.uniform(*PAIR_T_AFTER, 2)

    horiz = np.sqrt(v**2 - climb**2)
    psi = np.array([psi1, psi1 + crossing])
    vel = np.stack([horiz * np.cos(psi), horiz * np.sin(psi), climb], axis=1)
    miss = miss_ratio * float(r_pz.max())
    n = unit_perpendicular(vel[0] - vel[1], miss_angle)
    cpa = np.array([0.0, 0.0, PAIR_CPA_ALTITUDE]) + np.outer([-0.5, 0.5], miss * n)
    starts = cpa - vel * t_cpa
    goals = cpa + vel * t_after[:, None]
    scenario = base_scenario(
        v_max=PAIR_SPEED[1],
        altitude=(0.0, 2.0 * PAIR_CPA_ALTITUDE),
        starts=starts,
        goals=goals,
        r_pz=r_pz,
        speeds=v,
    )
    params = {
        "speed_0": v[0],
        "speed_1": v[1],
        "climb_0": climb[0],
        "climb_1": climb[1],
        "r_pz_0": r_pz[0],
        "r_pz_1": r_pz[1],
        "crossing_deg": math.degrees(crossing),
        "miss_distance": miss,
        "miss_over_r_pz": miss_ratio,
        "t_cpa": t_cpa,
    }
    return Draw(params={k: float(x) for k, x in params.items()}, scenario=scenario)


# ------------------------------------------------------------------------------ group

GROUP_AGENTS = (3, 8)  # UAVs, uniform integer
GROUP_OBSTACLES = (0, 6)  # obstacles, uniform integer; half cylinders, half boxes
GROUP_RING = 60.0  # m: starts and goals on this circle around the origin
GROUP_FIELD = 35.0  # m: obstacle centres uniform in [-35, 35]^2
GROUP_CYLINDER_RADIUS = (1.0, 5.0)
GROUP_BOX_SIDE = (2.0, 10.0)  # each side, uniform; yaw uniform
GROUP_HEIGHT = (20.0, 80.0)  # m; the ceiling is 40 m, so about 2/3 cannot be overflown
GROUP_GAP = 10.0  # m, at least, between two obstacles' protected prisms
GROUP_R_PZ = (5.0, 10.0)
GROUP_SPEED = (2.0, 5.0)
GROUP_ALTITUDE = (0.0, 40.0)
GROUP_Z = (5.0, 35.0)  # start and goal altitudes, uniform
GROUP_TURN = math.radians(60.0)  # goal heading = start heading + 180 deg +- this, uniform


def _obstacle(rng: np.random.Generator) -> dict[str, Any]:
    centre = rng.uniform(-GROUP_FIELD, GROUP_FIELD, 2)
    height = rng.uniform(*GROUP_HEIGHT)
    if rng.random() < 0.5:
        return {
            "type": "cylinder",
            "center": to_mm(centre),
            "radius": to_mm(rng.uniform(*GROUP_CYLINDER_RADIUS)),
            "height": to_mm(height),
        }
    return {
        "type": "box",
        "center": to_mm(centre),
        "size": to_mm(rng.uniform(*GROUP_BOX_SIDE, 2)),
        "height": to_mm(height),
        "yaw": to_mm(rng.uniform(-math.pi, math.pi)),
    }


def _prism_half_side(ob: dict[str, Any], margin: float = 2.0) -> float:
    """L_pz / 2 as the loader derives it (the obstacle's largest extent plus the margin)."""
    extent = 2.0 * ob["radius"] if ob["type"] == "cylinder" else math.hypot(*ob["size"])
    return extent / 2.0 + margin


def _obstacles(rng: np.random.Generator, count: int) -> list[dict[str, Any]] | None:
    out: list[dict[str, Any]] = []
    for _ in range(count):
        for _ in range(200):
            ob = _obstacle(rng)
            c = np.asarray(ob["center"])
            if all(
                np.linalg.norm(c - np.asarray(o["center"]))
                >= _prism_half_side(ob) + _prism_half_side(o) + GROUP_GAP
                for o in out
            ):
                out.append(ob)
                break
        else:
            return None
    return out


def _ring_trip(
    rng: np.random.Generator, taken: list[np.ndarray], need: float
) -> tuple[np.ndarray, np.ndarray] | None:
    """A start on the ring at a uniform heading and a goal across it (heading + 180 deg +-
    GROUP_TURN), altitudes uniform in GROUP_Z, ``need`` from each other and from ``taken``."""

    def at(heading: float) -> np.ndarray:
        return np.array(
            [GROUP_RING * math.cos(heading), GROUP_RING * math.sin(heading), rng.uniform(*GROUP_Z)]
        )

    s = place_apart(lambda: at(rng.uniform(-math.pi, math.pi)), taken, need)
    if s is None:
        return None
    heading = math.atan2(s[1], s[0])
    g = place_apart(
        lambda: at(heading + math.pi + rng.uniform(-GROUP_TURN, GROUP_TURN)), [*taken, s], need
    )
    return None if g is None else (s, g)


def _ring_points(
    rng: np.random.Generator, n: int, r_pz: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """Starts on the ring at uniform headings, goals across it, all SEPARATION * r_pz apart."""
    taken: list[np.ndarray] = []
    starts, goals = np.zeros((n, 3)), np.zeros((n, 3))
    need = SEPARATION * float(r_pz.max())
    for i in range(n):
        trip = _ring_trip(rng, taken, need)
        if trip is None:
            return None
        starts[i], goals[i] = trip
        taken += list(trip)
    return starts, goals


@register(
    "group",
    "3-8 UAVs crossing a 60 m circle among 0-6 tall cylinders and boxes "
    "(r_pz 5-10 m, 2-5 m/s, ceiling 40 m)",
    obstacle_free=False,
)
def group(rng: np.random.Generator) -> Draw | None:
    """``n`` UAVs (uniform 3-8) start on a circle of radius 60 m at uniform headings and
    altitudes 5-35 m and fly to the far side (heading + 180 deg +- 60 deg, altitude 5-35 m),
    each with its own r_pz (5-10 m) and speed (2-5 m/s), among ``m`` obstacles (uniform 0-6)
    centred in [-35, 35]^2 m: cylinders (radius 1-5 m) or yawed boxes (sides 2-10 m), height
    20-80 m under a 40 m ceiling, their protected prisms at least 10 m apart."""
    n = int(rng.integers(GROUP_AGENTS[0], GROUP_AGENTS[1] + 1))
    m = int(rng.integers(GROUP_OBSTACLES[0], GROUP_OBSTACLES[1] + 1))
    r_pz = rng.uniform(*GROUP_R_PZ, n)
    speeds = rng.uniform(*GROUP_SPEED, n)
    obstacles = _obstacles(rng, m)
    points = _ring_points(rng, n, r_pz)
    if obstacles is None or points is None:
        return None
    starts, goals = points
    scenario = base_scenario(
        v_max=GROUP_SPEED[1],
        altitude=GROUP_ALTITUDE,
        starts=starts,
        goals=goals,
        r_pz=r_pz,
        speeds=speeds,
    )
    scenario["obstacles"] = obstacles
    # protected prism (height + 2 m margin) up to the ceiling: it cannot be overflown
    tall = sum(o["height"] + 2.0 >= GROUP_ALTITUDE[1] for o in obstacles)
    params = {
        "agents": n,
        "obstacles": m,
        "cylinders": sum(o["type"] == "cylinder" for o in obstacles),
        "boxes": sum(o["type"] == "box" for o in obstacles),
        "obstacles_above_ceiling": int(tall),
        "r_pz_min": float(r_pz.min()),
        "r_pz_max": float(r_pz.max()),
        "speed_min": float(speeds.min()),
        "speed_max": float(speeds.max()),
    }
    return Draw(params=params, scenario=scenario)


# ------------------------------------------------------------------------------ dense

DENSE_AGENTS = (10, 24)  # UAVs, uniform integer
DENSE_BOX = (60.0, 60.0, 30.0)  # m: starts and goals uniform in [-30, 30]^2 x [5, 35]
DENSE_FLOOR = 5.0
DENSE_R_PZ = (3.0, 6.0)  # m, one value for the whole encounter, uniform
DENSE_SPEED = (2.0, 4.0)  # m/s per UAV, uniform
DENSE_MIN_TRIP = 20.0  # m, least start-goal distance


@register(
    "dense",
    "10-24 UAVs swapping places inside a 60 x 60 x 30 m box (r_pz 3-6 m, 2-4 m/s)",
    obstacle_free=True,
)
def dense(rng: np.random.Generator) -> Draw | None:
    """``n`` UAVs (uniform 10-24), one r_pz for all (3-6 m), speeds 2-4 m/s each: starts and
    goals uniform in the box [-30, 30]^2 x [5, 35] m (altitude range 0-40 m), every start and
    goal of different UAVs 1.25 r_pz apart, each goal at least 20 m from its own start."""
    n = int(rng.integers(DENSE_AGENTS[0], DENSE_AGENTS[1] + 1))
    r = float(rng.uniform(*DENSE_R_PZ))
    speeds = rng.uniform(*DENSE_SPEED, n)
    lo = np.array([-DENSE_BOX[0] / 2, -DENSE_BOX[1] / 2, DENSE_FLOOR])
    hi = lo + np.asarray(DENSE_BOX)
    taken: list[np.ndarray] = []
    starts, goals = np.zeros((n, 3)), np.zeros((n, 3))
    for i in range(n):
        s = place_apart(lambda: rng.uniform(lo, hi), taken, SEPARATION * r)
        if s is None:
            return None
        start: np.ndarray = s  # bound now: the lambda below runs inside this iteration

        def far_enough(p: np.ndarray, start: np.ndarray = start) -> bool:
            return bool(np.linalg.norm(p - start) >= DENSE_MIN_TRIP)

        g = place_apart(lambda: rng.uniform(lo, hi), taken, SEPARATION * r, accept=far_enough)
        if g is None:
            return None
        starts[i], goals[i] = s, g
        taken += [s, g]
    r_pz = np.full(n, r)
    scenario = base_scenario(
        v_max=DENSE_SPEED[1],
        altitude=(0.0, DENSE_FLOOR + DENSE_BOX[2] + 5.0),
        starts=starts,
        goals=goals,
        r_pz=r_pz,
        speeds=speeds,
    )
    volume = float(np.prod(DENSE_BOX))
    params: dict[str, float | int | str] = {
        "agents": n,
        "r_pz": r,
        "speed_min": float(speeds.min()),
        "speed_max": float(speeds.max()),
        "agents_per_1000m3": 1000.0 * n / volume,
    }
    return Draw(params=params, scenario=scenario)


# ---------------------------------------------------- group variants (real-world keys)
#
# Each draws a ``group`` encounter from the same stream and then the variant's own parameters,
# so encounter i of ``lagged`` is encounter i of ``group`` (same agents and obstacles) plus a
# time constant. ``needs`` of a family: the real-world scenario keys its draws use
# (the sweep refuses the family, naming them, when this build's scenario loader does not
# accept them).


def _group_variant(rng: np.random.Generator) -> Draw | None:
    """A ``group`` draw whose dicts the caller may edit (copies, not shared with anyone)."""
    base = group(rng)
    if base is None:
        return None
    return Draw(params=dict(base.params), scenario=dict(base.scenario))


LAGGED_TAU = (0.1, 1.0)  # s, first-order velocity time constant, uniform


@register(
    "lagged",
    "a group encounter under first-order velocity dynamics, tau 0.1-1 s",
    obstacle_free=False,
    warm_keys={"dynamics": {"model": "first_order", "tau": 0.5}},
)
def lagged(rng: np.random.Generator) -> Draw | None:
    """A ``group`` draw flown under first-order velocity dynamics: every vehicle's velocity
    follows its command as ``v += (v_cmd - v) min(1, dt / tau)``, with one time constant
    ``tau`` for the encounter, uniform 0.1-1 s, written as the scenario key
    ``dynamics: {model: first_order, tau}``."""
    draw = _group_variant(rng)
    if draw is None:
        return None
    tau = float(rng.uniform(*LAGGED_TAU))
    draw.scenario["dynamics"] = {"model": "first_order", "tau": to_mm(tau)}
    draw.params["tau"] = to_mm(tau)
    return draw


INTRUDER_SPEED = (1.0, 4.0)  # m/s, the non-cooperative UAV's speed, uniform
INTRUDER_R_PZ = GROUP_R_PZ


def _segment_clear_of_prisms(
    start: np.ndarray, goal: np.ndarray, obstacles: list[dict[str, Any]]
) -> bool:
    """Whether the straight horizontal track start -> goal keeps PRISM_CLEARANCE from every
    obstacle's protected prism (conservative: as if every prism reached the ceiling)."""
    a, b = start[:2], goal[:2]
    ab = b - a
    for ob in obstacles:
        c = np.asarray(ob["center"], dtype=float)
        t = float(np.clip((c - a) @ ab / (ab @ ab), 0.0, 1.0))
        if np.linalg.norm(a + t * ab - c) < _prism_half_side(ob) + PRISM_CLEARANCE:
            return False
    return True


@register(
    "intruder",
    "a group encounter plus one non-cooperative UAV (avoids: false) "
    "crossing it straight at 1-4 m/s",
    obstacle_free=False,
    needs=("agents.avoids",),
)
def intruder(rng: np.random.Generator) -> Draw | None:
    """A ``group`` draw plus one more UAV, ``x0``, that flies straight to its goal and never
    avoids (``avoids: false``; the others see it and must keep clear). Its start is on the
    same 60 m circle at a uniform heading, its goal across it (heading + 180 deg +- 60 deg),
    altitudes 5-35 m, at the others' separation from their starts and goals; speed uniform
    1-4 m/s, r_pz uniform 5-10 m. Its straight track keeps 2 m from every obstacle's protected
    prism (else the draw is rejected: it would hit the obstacle, which is not what is tested)."""
    draw = _group_variant(rng)
    if draw is None:
        return None
    speed = float(rng.uniform(*INTRUDER_SPEED))
    r_pz = float(rng.uniform(*INTRUDER_R_PZ))
    agents = draw.scenario["agents"]
    points = [np.asarray(a[k], dtype=float) for a in agents for k in ("start", "goal")]
    need = SEPARATION * max(r_pz, max(a["r_pz"] for a in agents))
    trip = _ring_trip(rng, points, need)
    if trip is None or not _segment_clear_of_prisms(*trip, draw.scenario["obstacles"]):
        return None
    start, goal = trip
    agents = agents + [
        {
            "id": "x0",
            "start": to_mm(start),
            "goal": to_mm(goal),
            "r_pz": to_mm(r_pz),
            "max_speed": to_mm(speed, SPEED_DECIMALS),
            "avoids": False,
        }
    ]
    flight = float(np.linalg.norm(goal - start)) / speed
    draw.scenario["agents"] = agents
    draw.scenario["max_time"] = max(
        draw.scenario["max_time"], float(math.ceil(TIME_FACTOR * flight + TIME_SLACK))
    )
    draw.params.update({"intruder_speed": speed, "intruder_r_pz": r_pz})
    return draw


ROTORPY_VEHICLE = "hummingbird"
#: The family's vehicles: RotorPy's batched ones, so that a sweep task flies the vehicles of
#: all of its encounters in one ``RotorPyFleet`` (``vo3d_opt.sim.rotorpy_fleet``).
ROTORPY_DYNAMICS = {"model": "rotorpy", "vehicle": ROTORPY_VEHICLE, "batched": True}
ROTORPY_WIND_TYPES = ("constant", "dryden")  # even odds
ROTORPY_WIND_SPEED = (0.0, 3.0)  # m/s, horizontal (mean) wind, uniform; direction uniform


@register(
    "rotorpy",
    "a group encounter flown by RotorPy quadrotors (hummingbird) in constant "
    "or Dryden wind, 0-3 m/s",
    obstacle_free=False,
    warm_keys={
        "dynamics": ROTORPY_DYNAMICS,
        "wind": {"type": "dryden", "velocity": [1.0, 0.0, 0.0]},
    },
    needs=("dynamics", "wind"),
    extras=("rotorpy", "batched"),
)
def rotorpy(rng: np.random.Generator) -> Draw | None:
    """A ``group`` draw flown by RotorPy's ``hummingbird`` quadrotors, batched (``dynamics:
    {model: rotorpy, vehicle: hummingbird, batched: true}``), in wind: ``constant`` or
    ``dryden`` (turbulence about a mean) with even odds, the (mean) wind horizontal, its speed
    uniform 0-3 m/s, its direction uniform."""
    draw = _group_variant(rng)
    if draw is None:
        return None
    kind = ROTORPY_WIND_TYPES[int(rng.integers(len(ROTORPY_WIND_TYPES)))]
    speed = float(rng.uniform(*ROTORPY_WIND_SPEED))
    direction = float(rng.uniform(-math.pi, math.pi))
    wind = [speed * math.cos(direction), speed * math.sin(direction), 0.0]
    draw.scenario["dynamics"] = dict(ROTORPY_DYNAMICS)
    draw.scenario["wind"] = {"type": kind, "velocity": to_mm(wind)}
    draw.params.update(
        {"wind_type": kind, "wind_speed": speed, "wind_direction_deg": math.degrees(direction)}
    )
    return draw


NOISY_POSITION = (0.0, 0.5)  # m, 1-sigma per axis, uniform
NOISY_VELOCITY = (0.0, 0.3)  # m/s, 1-sigma per axis, uniform
NOISY_LATENCY_STEPS = (0, 2)  # latency = k dt, k uniform integer: 0, 0.2 or 0.4 s
NOISY_SEEDS = 2**31  # the sensing seed, uniform in [0, 2^31)


@register(
    "noisy",
    "a group encounter with Gaussian sensing noise (position 0-0.5 m, "
    "velocity 0-0.3 m/s) and latency 0-0.4 s",
    obstacle_free=False,
    warm_keys={
        "sensing": {
            "vehicle_range": 55.0,
            "obstacle_range": 55.0,
            "position_noise": 0.3,
            "velocity_noise": 0.2,
            "latency": 0.2,
            "seed": 1,
        }
    },
    needs=("sensing.position_noise", "sensing.velocity_noise", "sensing.latency", "sensing.seed"),
)
def noisy(rng: np.random.Generator) -> Draw | None:
    """A ``group`` draw in which every sensed position and velocity carries Gaussian noise
    (1-sigma per axis: position uniform 0-0.5 m, velocity uniform 0-0.3 m/s) and is
    ``latency`` old, ``latency = k dt`` with k uniform in {0, 1, 2} (0-0.4 s); the noise's
    ``seed`` is drawn too, so the encounter is reproducible."""
    draw = _group_variant(rng)
    if draw is None:
        return None
    sensing = {
        **draw.scenario["sensing"],
        "position_noise": to_mm(rng.uniform(*NOISY_POSITION)),
        "velocity_noise": to_mm(rng.uniform(*NOISY_VELOCITY)),
        "latency": to_mm(
            DT * int(rng.integers(NOISY_LATENCY_STEPS[0], NOISY_LATENCY_STEPS[1] + 1))
        ),
        "seed": int(rng.integers(NOISY_SEEDS)),
    }
    draw.scenario["sensing"] = sensing
    draw.params.update({k: sensing[k] for k in ("position_noise", "velocity_noise", "latency")})
    draw.params["sensing_seed"] = sensing["seed"]
    return draw
