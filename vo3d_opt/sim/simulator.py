"""Decentralised multi-UAV simulation (paper section 5).

"Each UAV independently produces avoiding velocity control based on its own detection of
obstacles ... moves at a constant time step ... the avoiding velocity control is updated at each
time step." Here, every ``dt`` each agent that has not arrived calls the selector with what it
senses in the *same snapshot* of the previous step (so the order of the calls does not matter):

* the other vehicles within ``sensing.vehicle_range`` (centre distance), as ``Neighbor`` with
  their current velocity and ``r_pz = max(own r_pz, their r_pz)`` (so each side keeps the larger
  zone, which is what the metrics count); arrived ones as ``cooperative=False`` (they hover and
  no longer avoid, so a ``reciprocal`` selector takes all of the avoidance, not half);
* the obstacles within ``sensing.obstacle_range`` of their nearest point (those with
  ``sensed: false`` are never seen), and the scenario's static spheres within that range as
  zero-velocity, non-cooperative neighbours;
* a preferred velocity pointing at its goal with speed ``min(v_max, distance / dt)`` (full speed,
  slowing only to land on the goal in the last step);
* its limits: speed ``(limits.speed[0], min(limits.speed[1], max_speed))`` and the altitude range.

The position is integrated kinematically, ``p += v dt``, with ``v`` the command, or with a
first-order response ``v += (v_cmd - v) min(1, dt / tau)`` when ``velocity_response_tau`` is
set. An agent within ``goal_tolerance`` of its goal has arrived: it stops (velocity 0 from that
sample on, which is what the others sense next), hovers there for the rest of the run, still
seen by the others, and no longer decides. The run stops
when all agents have arrived or after ``max_time``. The simulator never clips the selector's
answer: the metrics report any limit it breaks.
"""
from __future__ import annotations

import csv
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from tqdm import tqdm

from vo3d_opt.sim.scenario import Scenario, load_scenario, sphere_surface_distance
from vo3d_opt.types import AgentState, Limits, Neighbor

#: Default formulation when neither the caller nor the scenario names one (contract §1).
DEFAULT_FORMULATION = "plane_qp"


class Decision(Protocol):
    velocity: Any
    status: str
    solve_time: float


class SelectorLike(Protocol):
    """Anything with ``VelocitySelector.select``'s signature (contract §1)."""

    def select(self, *, own: AgentState, preferred_velocity: Any, neighbors: list[Neighbor],
               obstacles: list[Any], limits: Limits, dt: float) -> Decision: ...


@dataclass
class RunRecord:
    """Everything a run produced; arrays indexed [step, agent, ...] in the scenario's agent order.

    ``positions[k]`` is the state at ``times[k]`` (k = 0..T); ``commands[k]`` the decision taken
    at ``times[k]`` and ``velocities[k]`` the velocity flown over [t_k, t_k+1] (equal to the
    command without a velocity response; 0 for arrived agents). ``decided[k, i]`` says whether
    agent i called the selector at step k; ``statuses``, ``decision_times`` (wall time of the
    ``select()`` call, s) and ``solve_times`` (the decision's own ``solve_time``) are "" / NaN
    where it did not.
    """

    scenario: Scenario
    formulation: str
    solver: str
    times: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    commands: np.ndarray
    preferred: np.ndarray
    decided: np.ndarray
    statuses: np.ndarray
    decision_times: np.ndarray
    solve_times: np.ndarray
    arrived: np.ndarray
    wall_time: float = 0.0
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def dt(self) -> float:
        return float(self.scenario.dt)

    @property
    def steps(self) -> int:
        """Control steps simulated (the decisions of the agent that decided longest)."""
        return int(self.commands.shape[0])

    @property
    def n_agents(self) -> int:
        return int(self.positions.shape[1])

    @property
    def ids(self) -> list[str]:
        return self.scenario.ids

    def arrival_times(self) -> np.ndarray:
        """Time (s) each agent first arrived, NaN when it never did."""
        out = np.full(self.n_agents, np.nan)
        first = np.argmax(self.arrived, axis=0)
        hit = self.arrived.any(axis=0)
        out[hit] = self.times[first[hit]]
        return out

    def same_trajectory(self, other: "RunRecord") -> bool:
        """Bitwise-equal positions, velocities, commands and statuses (timing excluded)."""
        return (
            np.array_equal(self.positions, other.positions)
            and np.array_equal(self.velocities, other.velocities)
            and np.array_equal(self.commands, other.commands)
            and np.array_equal(self.statuses, other.statuses)
            and np.array_equal(self.arrived, other.arrived)
        )


@dataclass
class RunBuffers:
    """The arrays a run fills step by step, [step, agent, ...] as in :class:`RunRecord`, for
    ``total`` steps of ``n`` agents; ``record`` cuts them to the steps actually simulated."""

    pos: np.ndarray
    vel: np.ndarray
    cmd: np.ndarray
    pref: np.ndarray
    decided: np.ndarray
    statuses: np.ndarray
    dtimes: np.ndarray
    stimes: np.ndarray
    arrived: np.ndarray

    @classmethod
    def empty(cls, total: int, n: int) -> "RunBuffers":
        return cls(pos=np.empty((total + 1, n, 3)), vel=np.zeros((total, n, 3)),
                   cmd=np.zeros((total, n, 3)), pref=np.zeros((total, n, 3)),
                   decided=np.zeros((total, n), dtype=bool),
                   statuses=np.full((total, n), "", dtype=object),
                   dtimes=np.full((total, n), np.nan), stimes=np.full((total, n), np.nan),
                   arrived=np.zeros((total + 1, n), dtype=bool))

    def record(self, sc: Scenario, formulation: str, solver: str, steps: int, wall: float,
               extra: dict[str, Any] | None = None) -> RunRecord:
        s = steps
        return RunRecord(
            scenario=sc, formulation=formulation, solver=solver,
            times=np.arange(s + 1) * sc.dt, positions=self.pos[: s + 1], velocities=self.vel[:s],
            commands=self.cmd[:s], preferred=self.pref[:s], decided=self.decided[:s],
            statuses=self.statuses[:s], decision_times=self.dtimes[:s],
            solve_times=self.stimes[:s], arrived=self.arrived[: s + 1], wall_time=wall,
            extra=extra or {},
        )


def make_selector(formulation: str | None = None, solver: str | None = None,
                  options: dict[str, Any] | None = None) -> tuple[Any, str, str]:
    """Build ``vo3d_opt.selector.VelocitySelector``; returns (selector, formulation, solver).

    Unknown formulations or solvers raise ``ValueError`` (from the selector's constructor).
    """
    from vo3d_opt.selector import VelocitySelector  # late: the simulator works without it

    formulation = formulation or DEFAULT_FORMULATION
    kwargs: dict[str, Any] = dict(options or {})
    kwargs["formulation"] = formulation
    if solver is not None:
        kwargs["solver"] = solver
    sel = VelocitySelector(**kwargs)
    name = solver
    if name is None:  # the selector's choice; "none" when it uses no solver (sampled)
        value = getattr(sel, "solver", "default")
        name = value if isinstance(value, str) else "none"
    return sel, formulation, name


class Simulator:
    """Runs one scenario with one selector object shared by every agent (it must be stateless
    between calls, or at least deterministic given the call order, which is agent order)."""

    def __init__(self, scenario: Scenario, selector: SelectorLike, *, formulation: str = "custom",
                 solver: str = "custom") -> None:
        self.scenario = scenario
        self.selector = selector
        self.formulation = formulation
        self.solver = solver
        sc = scenario
        self.limits = [sc.agent_limits(i) for i in range(sc.n_agents)]
        self.bodies = sc.bodies
        self.sensed_idx = np.flatnonzero(sc.sensed) if sc.obstacles else np.zeros(0, dtype=int)
        self.spheres = sc.sphere_neighbors()
        self.sphere_centers = np.array([s.center for s in sc.spheres], dtype=float).reshape(-1, 3)
        self.sphere_radii = np.array([s.radius for s in sc.spheres], dtype=float)

    def preferred_velocity(self, positions: np.ndarray) -> np.ndarray:
        """Goal-seeking velocities (N, 3): towards the goal at min(v_max, distance / dt)."""
        sc = self.scenario
        to_goal = sc.goals - positions
        dist = np.linalg.norm(to_goal, axis=1)
        speed = np.minimum(sc.max_speed, dist / sc.dt)
        with np.errstate(invalid="ignore", divide="ignore"):
            unit = np.where(dist[:, None] > 0, to_goal / dist[:, None], 0.0)
        return unit * speed[:, None]

    def run(self, *, progress: bool | None = None, max_steps: int | None = None) -> RunRecord:
        """Simulate until every agent arrived or ``max_time``; ``progress`` None = only on a TTY."""
        sc = self.scenario
        n, dt = sc.n_agents, sc.dt
        total = sc.n_steps if max_steps is None else min(max_steps, sc.n_steps)
        r_pz, goals, tol = sc.r_pz, sc.goals, sc.goal_tolerance
        vrange, orange = sc.sensing.vehicle_range, sc.sensing.obstacle_range
        alpha = None if sc.velocity_response_tau is None else min(1.0, dt / sc.velocity_response_tau)
        order = sorted(range(n), key=lambda i: sc.ids[i])

        buf = RunBuffers.empty(total, n)
        pos, vel, cmd, pref, arrived = buf.pos, buf.vel, buf.cmd, buf.pref, buf.arrived
        decided, statuses, dtimes, stimes = buf.decided, buf.statuses, buf.dtimes, buf.stimes

        p = sc.starts.copy()
        v = np.zeros((n, 3))
        done = np.linalg.norm(p - goals, axis=1) <= tol
        pos[0], arrived[0] = p, done
        steps = 0
        t_start = time.perf_counter()
        bar = tqdm(total=total, desc=sc.name, unit="step", file=sys.stderr, delay=1.0,
                   leave=False, disable=(None if progress is None else not progress))
        try:
            for k in range(total):
                if done.all():
                    break
                steps = k + 1
                v_pref = self.preferred_velocity(p)
                v_pref[done] = 0.0
                pref[k] = v_pref
                centre = np.linalg.norm(p[:, None, :] - p[None, :, :], axis=-1)
                obst = (np.stack([self.bodies[m].surface_distance(p) for m in self.sensed_idx],
                                 axis=1) if len(self.sensed_idx) else np.zeros((n, 0)))
                sph = (np.stack([sphere_surface_distance(c, r, p) for c, r in
                                 zip(self.sphere_centers, self.sphere_radii)], axis=1)
                       if len(self.spheres) else np.zeros((n, 0)))
                cache: dict[tuple[int, float], Neighbor] = {}
                u = np.zeros((n, 3))
                for i in order:
                    if done[i]:
                        continue
                    neighbors: list[Neighbor] = []
                    for j in np.flatnonzero(centre[i] <= vrange):
                        if j == i:
                            continue
                        key = (int(j), float(max(r_pz[i], r_pz[j])))
                        if key not in cache:  # an arrived agent hovers: it does not avoid
                            cache[key] = Neighbor(position=p[j], velocity=v[j], r_pz=key[1],
                                                  cooperative=not done[j])
                        neighbors.append(cache[key])
                    neighbors.extend(self.spheres[s] for s in np.flatnonzero(sph[i] <= orange))
                    obstacles = [self.bodies[self.sensed_idx[m]]
                                 for m in np.flatnonzero(obst[i] <= orange)]
                    own = AgentState(position=p[i], velocity=v[i])
                    t0 = time.perf_counter()
                    d = self.selector.select(own=own, preferred_velocity=v_pref[i],
                                             neighbors=neighbors, obstacles=obstacles,
                                             limits=self.limits[i], dt=dt)
                    dtimes[k, i] = time.perf_counter() - t0
                    out = np.asarray(d.velocity, dtype=float).reshape(-1)
                    status = str(d.status)
                    if out.shape != (3,) or not np.all(np.isfinite(out)):
                        out, status = np.zeros(3), f"invalid_velocity ({status})"
                    u[i], statuses[k, i], decided[k, i] = out, status, True
                    stimes[k, i] = float(getattr(d, "solve_time", np.nan))
                cmd[k] = u
                v = u.copy() if alpha is None else v + (u - v) * alpha
                v[done] = 0.0
                vel[k] = v
                p = p + v * dt
                done = done | (np.linalg.norm(p - goals, axis=1) <= tol)
                v[done] = 0.0  # an arrived agent hovers from now on: the others see it still
                pos[k + 1], arrived[k + 1] = p, done
                bar.update(1)
        finally:
            bar.close()
        return buf.record(sc, self.formulation, self.solver, steps, time.perf_counter() - t_start)


def default_selector_options(sc: Scenario) -> dict[str, Any]:
    """What every agent of a simulation runs with unless ``selector_options`` says otherwise.

    All agents run the same selector, so each may assume the other takes half of a pairwise
    avoidance (``reciprocal``); and since each decides from a snapshot that the others change
    within the next step, every neighbour's sphere is planned ``pz_buffer`` larger: twice the
    distance a vehicle covers in one step at full speed. Without these the paper's
    non-reciprocal selection lets vehicles slide along each other's zones and dip into them
    (see README, "Safety in simulation")."""
    v_max = max(sc.agent_limits(i).v_max for i in range(sc.n_agents))
    return {"reciprocal": True, "pz_buffer": 2.0 * v_max * sc.dt}


def scenario_selector(sc: Scenario, formulation: str | None = None, solver: str | None = None
                      ) -> tuple[Any, str, str]:
    """The selector a scenario runs with: the given or the scenario's formulation and solver,
    and ``default_selector_options`` overridden by the scenario's ``selector_options``."""
    return make_selector(formulation or sc.formulation, solver or sc.solver,
                         {**default_selector_options(sc), **sc.selector_options})


def run_scenario(scenario: Scenario | str | Path, selector: SelectorLike | None = None, *,
                 formulation: str | None = None, solver: str | None = None,
                 progress: bool | None = None, max_steps: int | None = None) -> RunRecord:
    """Load (if a path) and run a scenario. Without ``selector``, build a ``VelocitySelector``
    from ``formulation``/``solver`` (falling back to the scenario's, then to plane_qp and the
    selector's default solver); ``ValueError`` for unknown names."""
    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    if selector is None:
        selector, formulation, solver = scenario_selector(sc, formulation, solver)
    sim = Simulator(sc, selector, formulation=formulation or "custom", solver=solver or "custom")
    return sim.run(progress=progress, max_steps=max_steps)


CSV_COLUMNS = ["step", "time", "agent", "x", "y", "z", "vx", "vy", "vz", "cmd_vx", "cmd_vy",
               "cmd_vz", "status", "decision_time_us", "arrived"]


def write_csv(record: RunRecord, path: str | Path) -> Path:
    """Trajectories as CSV, one row per (sample, agent); the velocity columns hold the velocity
    flown from that sample to the next (empty on the last sample)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    ids, steps = record.ids, record.steps
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(CSV_COLUMNS)
        for k in range(steps + 1):
            t = f"{record.times[k]:.6g}"
            for i, name in enumerate(ids):
                x, y, z = (f"{c:.6f}" for c in record.positions[k, i])
                if k < steps:
                    v = [f"{c:.6f}" for c in record.velocities[k, i]]
                    c = [f"{c:.6f}" for c in record.commands[k, i]]
                    st = record.statuses[k, i]
                    dtu = record.decision_times[k, i]
                    dtu = "" if np.isnan(dtu) else f"{dtu * 1e6:.1f}"
                else:
                    v, c, st, dtu = ["", "", ""], ["", "", ""], "", ""
                w.writerow([k, t, name, x, y, z, *v, *c, st, dtu, int(record.arrived[k, i])])
    return path
