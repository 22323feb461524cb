"""RVO2-3D (van den Berg et al., reciprocal velocity obstacles in 3D) flown on our scenarios.

The runner mirrors :class:`vo3d_opt.sim.simulator.Simulator` step for step, so that a
:class:`~vo3d_opt.sim.simulator.RunRecord` comes out and the very same metrics
(:func:`vo3d_opt.sim.metrics.summarize`) judge both methods:

* every ``dt`` each agent gets our simulator's preferred velocity (towards its goal at
  ``min(v_max, distance / dt)``, :meth:`Simulator.preferred_velocity`), then one
  ``doStep()`` computes every new velocity from the same snapshot and integrates
  ``p += v dt`` (RVO2's own update, the same as ours without a velocity response);
* an agent within ``goal_tolerance`` of its goal has arrived: its RVO2 max speed is set to 0
  so it hovers there, still seen by the others (as in our simulator); the run stops when all
  arrived or after ``max_time``.

Parameter choices (the honest comparison gives both methods the same protected distance):

* **radius** ``r_pz / 2`` per agent. RVO2 keeps two agents ``radius_i + radius_j`` apart
  (centre to centre), so a pair keeps ``r_pz`` apart, which is what our ``pz_intrusions``
  counts (``distance < max(r_pz_i, r_pz_j)``; with unequal zones RVO2's pair distance
  ``(r_i + r_j) / 2`` is the smaller one: use equal r_pz for comparisons);
* **neighborDist** ``sensing.vehicle_range`` (RVO2 measures it centre to centre, as we do);
* **maxNeighbors** every other agent (our selector considers every vehicle in range);
* **maxSpeed** the agent's speed bound (``Scenario.max_speed``), **timeStep** ``dt``;
* **timeHorizon** ``vehicle_range / (2 v_max)`` by default: the time in which two vehicles
  closing head-on at full speed cover the sensing range, so every sensed vehicle can matter
  (our VO has no horizon at all). Override with ``time_horizon=``.

Limits RVO2-3D does not have: no altitude range (it flies freely in 3D: the metrics count any
``altitude_violations``), no minimum speed, no velocity response, no static obstacles (scenarios
with ``obstacles`` or ``spheres`` are refused). RVO2-3D works in single precision (float):
positions and velocities come back as float32 values.

Compute time: ``doStep()`` (neighbour search and every agent's 3D linear program) is timed per
step and shared equally among the agents that decided in that step, giving
``decision_times`` comparable with our per-``select()`` times. RVO2 reports no
infeasibility, so its decisions carry the status ``"rvo2"`` and :func:`summarize_rvo2` reports
``fallbacks`` as ``None`` (unknown), not 0.
"""
from __future__ import annotations

import math
import sys
import time
from importlib import metadata
from typing import Any

import numpy as np

from vo3d_opt.sim import metrics
from vo3d_opt.sim.scenario import Scenario, load_scenario, scenario_from_dict
from vo3d_opt.sim.simulator import RunBuffers, RunRecord, Simulator

FORMULATION = "rvo2-3d"
STATUS = "rvo2"


def available() -> bool:
    """Whether the ``rvo23d`` module (package jt-pyrvo23d, extra ``baselines``) is importable."""
    try:
        import rvo23d  # noqa: F401
    except ImportError:
        return False
    return True


def _rvo23d():
    try:
        import rvo23d
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError("RVO2-3D baseline needs the 'rvo23d' module: "
                          "pip install 'vo3d-opt[baselines]' (package jt-pyrvo23d)") from exc
    return rvo23d


def version() -> str:
    """The installed jt-pyrvo23d version ("unknown" when its metadata is missing)."""
    try:
        return metadata.version("jt-pyrvo23d")
    except metadata.PackageNotFoundError:  # pragma: no cover
        return "unknown"


def default_time_horizon(scenario: Scenario) -> float:
    """``vehicle_range / (2 v_max)``, s (see the module docstring)."""
    return float(scenario.sensing.vehicle_range / (2.0 * float(np.max(scenario.max_speed))))


def run_rvo2(scenario: Scenario | str, *, time_horizon: float | None = None,
             max_neighbors: int | None = None, radius_factor: float = 0.5,
             max_steps: int | None = None, progress: bool | None = None) -> RunRecord:
    """Fly an agent-only scenario with RVO2-3D; returns a :class:`RunRecord` (formulation
    ``"rvo2-3d"``). ``radius_factor`` scales r_pz into RVO2's agent radius (0.5: pairs keep
    r_pz apart). ``max_steps`` caps the control steps like ``Simulator.run``."""
    rvo23d = _rvo23d()
    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    if sc.obstacles or sc.spheres:
        raise ValueError(f"{sc.name}: the RVO2-3D baseline runs agent-only scenarios "
                         "(no obstacles, no spheres)")
    if sc.velocity_response_tau is not None:
        raise ValueError(f"{sc.name}: velocity_response_tau is not supported by the RVO2-3D baseline")
    n, dt = sc.n_agents, float(sc.dt)
    horizon = default_time_horizon(sc) if time_horizon is None else float(time_horizon)
    if not (math.isfinite(horizon) and horizon > 0):
        raise ValueError("time_horizon: must be a positive number of seconds")
    if not (radius_factor > 0):
        raise ValueError("radius_factor: must be positive")
    neighbours = max(1, n - 1) if max_neighbors is None else int(max_neighbors)
    vrange = float(sc.sensing.vehicle_range)
    r_pz, vmax, goals, tol = sc.r_pz, sc.max_speed, sc.goals, sc.goal_tolerance
    radii = r_pz * radius_factor

    sim = rvo23d.PyRVOSimulator(dt, vrange, neighbours, horizon, float(radii.max()),
                                float(vmax.max()))
    for i in range(n):
        sim.addAgent(tuple(float(c) for c in sc.starts[i]), vrange, neighbours, horizon,
                     float(radii[i]), float(vmax[i]), (0.0, 0.0, 0.0))
    rule = Simulator(sc, selector=None)  # only for its preferred-velocity rule

    total = sc.n_steps if max_steps is None else min(int(max_steps), sc.n_steps)
    buf = RunBuffers.empty(total, n)
    pos, vel, pref, arrived = buf.pos, buf.vel, buf.pref, buf.arrived
    decided, statuses, dtimes = buf.decided, buf.statuses, buf.dtimes
    step_times = np.zeros(total)

    p = np.array([sim.getAgentPosition(i) for i in range(n)], dtype=float)
    done = np.linalg.norm(p - goals, axis=1) <= tol
    frozen = np.zeros(n, dtype=bool)
    pos[0], arrived[0] = p, done
    steps = 0
    bar = _progress(total, sc.name, progress)
    t_start = time.perf_counter()
    try:
        for k in range(total):
            if done.all():
                break
            steps = k + 1
            for i in np.flatnonzero(done & ~frozen):  # arrived: hover, still seen by the others
                sim.setAgentMaxSpeed(int(i), 0.0)
                sim.setAgentVelocity(int(i), (0.0, 0.0, 0.0))
                frozen[i] = True
            v_pref = rule.preferred_velocity(p)
            v_pref[done] = 0.0
            pref[k] = v_pref
            for i in range(n):
                sim.setAgentPrefVelocity(i, (float(v_pref[i, 0]), float(v_pref[i, 1]),
                                             float(v_pref[i, 2])))
            t0 = time.perf_counter()
            sim.doStep()
            step_times[k] = time.perf_counter() - t0
            active = ~done
            decided[k] = active
            statuses[k, active] = STATUS
            dtimes[k, active] = step_times[k] / max(1, int(active.sum()))
            vel[k] = [sim.getAgentVelocity(i) for i in range(n)]
            vel[k, done] = 0.0
            p = np.array([sim.getAgentPosition(i) for i in range(n)], dtype=float)
            done = done | (np.linalg.norm(p - goals, axis=1) <= tol)
            pos[k + 1], arrived[k + 1] = p, done
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    wall = time.perf_counter() - t_start
    buf.cmd[:], buf.stimes[:] = vel, dtimes  # RVO2's command is its velocity; no solve time apart
    return buf.record(
        sc, FORMULATION, f"rvo23d {version()}", steps, wall,
        extra={"time_horizon": horizon, "max_neighbors": neighbours,
               "radius": radii.tolist() if len(np.unique(radii)) > 1 else float(radii[0]),
               "neighbor_dist": vrange, "step_times": step_times[:steps]},
    )


def _progress(total: int, name: str, progress: bool | None):
    try:
        from tqdm import tqdm
    except ImportError:  # pragma: no cover
        return None
    return tqdm(total=total, desc=f"{name} (rvo2)", unit="step", file=sys.stderr, delay=1.0,
                leave=False, disable=(None if progress is None else not progress))


def summarize_record(record: RunRecord) -> dict[str, Any]:
    """:func:`vo3d_opt.sim.metrics.summarize` plus ``compute_time_per_agent_step_us`` (total
    decision time / decisions) and ``steps_capped`` (the run stopped at a step cap before
    max_time and before all arrived)."""
    out = metrics.summarize(record)
    t = record.decision_times[record.decided]
    t = t[np.isfinite(t)]
    out["compute_time_per_agent_step_us"] = float(t.sum() / t.size * 1e6) if t.size else None
    out["steps_capped"] = bool(record.steps < record.scenario.n_steps and not record.arrived[-1].all())
    return out


def summarize_rvo2(record: RunRecord) -> dict[str, Any]:
    """The metrics summary of an RVO2-3D run (same keys as ``metrics.summarize``); ``fallbacks``
    is ``None`` because RVO2 does not say when its linear program was infeasible."""
    out = summarize_record(record)
    out["fallbacks"] = None
    out["time_horizon"] = record.extra.get("time_horizon")
    return out


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


def sphere_swap_scenario(n: int, *, r_pz: float = 8.0, spacing: float = 2.0, dt: float = 0.2,
                         v_max: float = 4.0, vehicle_range: float = 55.0, radius: float = 0.5,
                         floor: float = 5.0, max_time: float | None = None) -> Scenario:
    """An antipodal swap of ``n`` agents on a Fibonacci sphere (a 3D circle swap).

    The sphere's radius grows with n so that neighbouring starts (and goals) are at least
    ``spacing * r_pz`` apart (and never below ``2 r_pz`` for tiny n): nobody starts inside a
    protected zone. Every agent flies to the antipode of its start, so every path passes
    through the centre. The altitude range [0, 2 R + 2 floor] contains the sphere with
    ``floor`` metres to spare; ``max_time`` defaults to twice the straight flight time + 30 s.
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
        max_time = math.ceil(2.0 * (2.0 * R / v_max) + 30.0)
    data = {
        "name": f"sphere-swap-{n}",
        "description": f"{n} agents on a sphere of radius {R:g} m swap to their antipodes "
                       f"(generated by vo3d_opt.baselines.rvo2.sphere_swap_scenario).",
        "dt": float(dt),
        "max_time": float(max_time),
        "goal_tolerance": 1.0,
        "limits": {"speed": [0.0, float(v_max)], "altitude": [0.0, float(2 * R + 2 * floor)]},
        "sensing": {"vehicle_range": float(vehicle_range), "obstacle_range": float(vehicle_range)},
        "defaults": {"r_pz": float(r_pz), "radius": float(radius), "max_speed": float(v_max)},
        "agents": [{"id": f"u{i:0{width}d}", "start": [float(c) for c in starts[i]],
                    "goal": [float(c) for c in goals[i]]} for i in range(n)],
    }
    return scenario_from_dict(data, source=f"<sphere_swap_scenario({n})>")
