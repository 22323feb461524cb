"""RVO2-3D (van den Berg et al., reciprocal velocity obstacles in 3D) flown on our scenarios.

:class:`RVO2Step` is a decision step of our one simulation loop
(:func:`vo3d_opt.sim.simulator.fly`), so both methods sense, get their preferred velocities
(:class:`vo3d_opt.sim.traffic.GoalWithDetours`) and are integrated by the same code, and the very
same metrics (:func:`vo3d_opt.sim.metrics.summarize`) judge both:

* every ``dt`` RVO2's agents are set to the loop's snapshot (positions, velocities) and
  preferred velocities, one ``doStep()`` computes every new velocity, and that velocity is the
  command the loop integrates (RVO2's own position update is overwritten at the next step: the
  loop's dynamics move the vehicles, ``p += v dt`` under the default kinematic model, or with
  the scenario's ``velocity_response_tau``);
* an arrived agent's RVO2 max speed is set to 0 so it hovers there, still seen by the others (as
  in our simulator; one keeping watch for an agent that does not avoid gets its max speed
  back); the run stops when all are home or after ``max_time``.

Parameter choices (the honest comparison gives both methods the same protected distance):

* **radius** ``r_pz / 2`` per agent. RVO2 keeps two agents ``radius_i + radius_j`` apart
  (centre to centre), so a pair keeps ``r_pz`` apart, which is what our ``pz_intrusions``
  counts (``distance < max(r_pz_i, r_pz_j)``; with unequal zones RVO2's pair distance
  ``(r_i + r_j) / 2`` is the smaller one: use equal r_pz for comparisons);
* **neighborDist** ``sensing.vehicle_range`` (RVO2 measures it centre to centre, as we do);
* **maxNeighbors** every other agent by default (our selector considers every vehicle in
  range), or ``max_neighbors``;
* **maxSpeed** the agent's speed bound (``Scenario.max_speed``), **timeStep** ``dt``;
* **timeHorizon** ``vehicle_range / (2 v_max)`` by default: the time in which two vehicles
  closing head-on at full speed cover the sensing range, so every sensed vehicle can matter
  (our VO has no horizon at all). Override with ``time_horizon=``.

Limits RVO2-3D does not have: no altitude range (it flies freely in 3D: the metrics count any
``altitude_violations``), no minimum speed, no static obstacles (scenarios with ``obstacles`` or
``spheres`` are refused). RVO2-3D works in single precision (float): the velocities it returns
are float32 values.

Compute time: ``doStep()`` (RVO2's neighbour search, every agent's 3D linear program and its own
position update) runs on one thread; it is timed per step and shared equally among the agents
that decided in that step, giving ``decision_times`` comparable with our per-agent times. RVO2
reports no infeasibility, so its decisions carry the status ``"rvo2"`` and
:func:`summarize_rvo2` reports ``fallbacks`` as ``None`` (unknown), not 0.
"""

from __future__ import annotations

import math
import time
from importlib import metadata
from typing import Any

import numpy as np

from vo3d_opt.extras import installed, needs
from vo3d_opt.sim import metrics
from vo3d_opt.sim.record import RunRecord, Snapshot, StepDecision
from vo3d_opt.sim.scenario import Scenario, load_scenario
from vo3d_opt.sim.simulator import fly

FORMULATION = "rvo2-3d"
STATUS = "rvo2"


def available() -> bool:
    """Whether the ``rvo23d`` module (package jt-pyrvo23d, extra ``baselines``) is installed."""
    return installed("rvo23d")


def _rvo23d():
    with needs("baselines", "the RVO2-3D baseline"):  # package jt-pyrvo23d
        import rvo23d
    return rvo23d


def version() -> str:
    """The installed jt-pyrvo23d version ("unknown" when its metadata is missing)."""
    try:
        return metadata.version("jt-pyrvo23d")
    except metadata.PackageNotFoundError:  # pragma: no cover
        return "unknown"


def default_time_horizon(scenario: Scenario) -> float:
    """``vehicle_range / (2 v_max)``, s (see the module docstring): ``Scenario.sensing_horizon``."""
    return scenario.sensing_horizon


class RVO2Step:
    """RVO2-3D as a decision step of :func:`vo3d_opt.sim.simulator.fly` (the module docstring
    gives the parameters)."""

    formulation = FORMULATION

    def __init__(
        self,
        sc: Scenario,
        *,
        time_horizon: float | None = None,
        max_neighbors: int | None = None,
        radius_factor: float = 0.5,
    ) -> None:
        rvo23d = _rvo23d()
        if sc.obstacles or sc.spheres:
            raise ValueError(
                f"{sc.name}: the RVO2-3D baseline runs agent-only scenarios "
                "(no obstacles, no spheres)"
            )
        n, dt = sc.n_agents, float(sc.dt)
        horizon = default_time_horizon(sc) if time_horizon is None else float(time_horizon)
        if not (math.isfinite(horizon) and horizon > 0):
            raise ValueError("time_horizon: must be a positive number of seconds")
        if not (radius_factor > 0):
            raise ValueError("radius_factor: must be positive")
        self.neighbours = max(1, n - 1) if max_neighbors is None else int(max_neighbors)
        self.vrange = float(sc.sensing.vehicle_range)
        self.horizon, self.radii, self.vmax = horizon, sc.r_pz * radius_factor, sc.max_speed
        self.solver = f"rvo23d {version()}"
        self.sim = rvo23d.PyRVOSimulator(
            dt,
            self.vrange,
            self.neighbours,
            horizon,
            float(self.radii.max()),
            float(self.vmax.max()),
        )
        for i in range(n):
            self.sim.addAgent(
                tuple(float(c) for c in sc.starts[i]),
                self.vrange,
                self.neighbours,
                horizon,
                float(self.radii[i]),
                float(self.vmax[i]),
                (0.0, 0.0, 0.0),
            )
        self.frozen = np.zeros(n, dtype=bool)
        self.step_times: list[float] = []

    def decide(self, snap: Snapshot) -> StepDecision:
        sim, n = self.sim, snap.positions.shape[0]
        for a in np.flatnonzero(~snap.deciding & ~self.frozen):  # arrived: hover, still seen
            sim.setAgentMaxSpeed(int(a), 0.0)
            self.frozen[a] = True
        for a in np.flatnonzero(snap.deciding & self.frozen):  # arrived, keeping watch again
            sim.setAgentMaxSpeed(int(a), float(self.vmax[a]))
            self.frozen[a] = False
        p, v, w = snap.positions.tolist(), snap.velocities.tolist(), snap.preferred.tolist()
        for i in range(n):
            sim.setAgentPosition(i, tuple(p[i]))
            sim.setAgentVelocity(i, tuple(v[i]))
            sim.setAgentPrefVelocity(i, tuple(w[i]))
        t0 = time.perf_counter()
        sim.doStep()
        elapsed = time.perf_counter() - t0
        self.step_times.append(elapsed)
        u = np.array([sim.getAgentVelocity(i) for i in range(n)], dtype=float)
        share = np.where(snap.deciding, elapsed / max(1, int(snap.deciding.sum())), np.nan)
        return StepDecision(
            commands=u,
            statuses=np.where(snap.deciding, STATUS, ""),
            decision_times=share,
            solve_times=share,
        )

    def extra(self) -> dict[str, Any]:
        radius = self.radii.tolist() if len(np.unique(self.radii)) > 1 else float(self.radii[0])
        return {
            "time_horizon": self.horizon,
            "max_neighbors": self.neighbours,
            "radius": radius,
            "neighbor_dist": self.vrange,
            "step_times": np.array(self.step_times),
        }


def run_rvo2(
    scenario: Scenario | str,
    *,
    time_horizon: float | None = None,
    max_neighbors: int | None = None,
    radius_factor: float = 0.5,
    max_steps: int | None = None,
    progress: bool | None = None,
) -> RunRecord:
    """Fly an agent-only scenario with RVO2-3D in our simulation loop; returns a
    :class:`RunRecord` (formulation ``"rvo2-3d"``). ``radius_factor`` scales r_pz into RVO2's
    agent radius (0.5: pairs keep r_pz apart). ``max_steps`` caps the control steps like
    ``Simulator.run``."""
    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    step = RVO2Step(
        sc, time_horizon=time_horizon, max_neighbors=max_neighbors, radius_factor=radius_factor
    )
    return fly(sc, step, progress=progress, max_steps=max_steps)


def summarize_record(record: RunRecord) -> dict[str, Any]:
    """:func:`vo3d_opt.sim.metrics.summarize` plus ``compute_time_per_agent_step_us`` (total
    decision time / decisions) and ``steps_capped`` (the run stopped at a step cap before
    max_time and before all arrived)."""
    out = metrics.summarize(record)
    t = metrics.decision_times_us(record)
    out["compute_time_per_agent_step_us"] = float(t.sum() / t.size) if t.size else None
    out["steps_capped"] = bool(
        record.steps < record.scenario.n_steps and not record.arrived[-1].all()
    )
    return out


def summarize_rvo2(record: RunRecord) -> dict[str, Any]:
    """The metrics summary of an RVO2-3D run (same keys as ``metrics.summarize``); ``fallbacks``
    is ``None`` because RVO2 does not say when its linear program was infeasible."""
    out = summarize_record(record)
    out["fallbacks"] = None
    out["time_horizon"] = record.extra.get("time_horizon")
    return out
