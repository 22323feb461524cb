"""The decision steps of the simulation loop (``simulator.fly``) that run a selector.

* :class:`SwarmSelect`: ``VelocitySelector.select_many`` decides for every deciding agent (not
  arrived, or keeping watch) in one call per step (compiled for the default formulation and
  backend; a loop of ``select`` otherwise, inside the selector);
* :class:`PerAgentSelect`: any ``SelectorLike`` called once per agent per step, in id order,
  with ``Neighbor`` objects built here (stand-ins, other libraries' selectors).

Both apply the same sensing rules (``vo3d_opt.swarm``; ``simulator``'s docstring), so for a
``VelocitySelector`` they give the same trajectory (tests/test_sim_loop.py).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from vo3d_opt.formulations.common import Options
from vo3d_opt.geometry.pyramid import prism_rows
from vo3d_opt.sim.landing import Landing
from vo3d_opt.sim.record import SelectorLike, Snapshot, StepDecision
from vo3d_opt.sim.safety import (
    derive_margins,
    planning_bodies,
    planning_limits,
    planning_speeds,
)
from vo3d_opt.sim.scenario import Scenario, sphere_surface_distance
from vo3d_opt.sim.sensed_batch import (
    STATUS_NAMES,
    Fleet,
    Observer,
    bounds_rows,
    decide_sensed,
)
from vo3d_opt.sim.sensing import Sensor
from vo3d_opt.types import AgentState, Limits, Neighbor


def sphere_table(sc: Scenario) -> np.ndarray:
    """The scenario's static spheres as (S, 5): x, y, z, radius, r_pz (``select_many``'s
    ``spheres``)."""
    return np.array([[*s.center, s.radius, s.r_pz] for s in sc.spheres], dtype=float).reshape(-1, 5)


class _SelectorStep:
    """A decision step that runs ``selector`` on scenario ``sc``; ``formulation`` and
    ``solver`` name it in the record. The selector plans in the world of
    ``vo3d_opt.sim.safety``: the altitude range shrunk by the altitude margin, the derived
    acceleration bound, every sensed obstacle's prism inflated by the obstacle margin and its
    top raised by the prism rise. An agent waiting at its goal's door is landed when the step
    is clear (``sim.landing``)."""

    def __init__(
        self, sc: Scenario, selector: Any, *, formulation: str = "custom", solver: str = "custom"
    ) -> None:
        self.scenario, self.selector = sc, selector
        self.formulation, self.solver = formulation, solver
        config = getattr(selector, "config", None)  # a VelocitySelector's: its buffer in steps
        steps = config.vo.buffer_steps if config is not None else 2.0
        self.margins = derive_margins(sc, steps)
        self.limits = planning_limits(sc.limits, self.margins)
        self.top_speeds = planning_speeds(sc, self.margins)
        self.bodies = planning_bodies(sc, self.margins)
        self.landing = Landing.for_scenario(sc, self.limits, self.bodies, self.margins.pz_buffer)
        self.landings = 0

    def _land(self, snap: Snapshot, out: StepDecision) -> StepDecision:
        """``out`` with the landing steps of the waiting agents (``sim.landing``); the others'
        commands as the simulator will fly them: 0 when hovering, the preferred velocity for
        agents that do not avoid."""
        if snap.waiting is None or not snap.waiting.any():
            return out
        u = np.array(out.commands, dtype=float).reshape(-1, 3)
        u[~snap.deciding] = snap.preferred[~snap.deciding]
        landed = self.landing.apply(
            positions=snap.positions,
            velocities=snap.velocities,
            preferred=snap.preferred,
            commands=u,
            waiting=snap.waiting,
            deciding=snap.deciding,
        )
        self.landings += int(landed.sum())
        out.commands = u
        return out

    def agent_limits(self, i: int) -> Limits:
        """Agent ``i``'s planning limits (its own top speed, ``planning_speeds``)."""
        v_min = self.scenario.limits.v_min
        return self.limits.model_copy(update={"speed": (v_min, float(self.top_speeds[i]))})

    def extra(self) -> dict[str, Any]:
        m = self.margins
        return {
            "landings": self.landings,
            "margins": {
                "acceleration": m.acceleration,
                "command_rate": m.command_rate,
                "pz_buffer": m.pz_buffer,
                "tracking": m.tracking,
                "obstacle_margin": m.obstacle_margin,
                "altitude_margin": m.altitude_margin,
                "prism_rise": m.prism_rise,
                "speed_margin": m.speed_margin,
            },
        }


class SwarmSelect(_SelectorStep):
    """Every deciding agent by one ``select_many`` call per step. ``max_neighbors``: each agent
    considers only its k nearest vehicles in range; ``threads``: ``select_many``'s."""

    def __init__(
        self,
        sc: Scenario,
        selector: Any,
        *,
        formulation: str = "custom",
        solver: str = "custom",
        max_neighbors: int | None = None,
        threads: int | None = None,
    ) -> None:
        super().__init__(sc, selector, formulation=formulation, solver=solver)
        self.max_neighbors, self.threads = max_neighbors, threads
        self.obstacles = [b for b, seen in zip(self.bodies, sc.sensed, strict=True) if seen]
        self.spheres = sphere_table(sc)
        self.compiled = bool(getattr(selector, "compiled", False))

    def decide(self, snap: Snapshot) -> StepDecision:
        sc = self.scenario
        out = self.selector.select_many(
            snap.positions,
            snap.velocities,
            snap.preferred,
            sc.r_pz,
            self.obstacles,
            self.limits,
            sc.dt,
            sc.sensing.vehicle_range,
            self.max_neighbors,
            snap.deciding,
            obstacle_range=sc.sensing.obstacle_range,
            spheres=self.spheres,
            max_speed=self.top_speeds,
            threads=self.threads,
        )
        return self._land(
            snap,
            StepDecision(
                commands=out.velocities,
                statuses=out.statuses,
                decision_times=out.times,
                solve_times=out.times,
            ),
        )

    def extra(self) -> dict[str, Any]:
        return {
            **super().extra(),
            "decision_step": "select_many",
            "compiled": self.compiled,
            "max_neighbors": self.max_neighbors,
        }


#: (observers x vehicles) entries of the sensed views ``PerAgentSelect.observers`` reads at once.
VIEW_ENTRIES = 1 << 16


class PerAgentSelect(_SelectorStep):
    """Each deciding agent by its own ``select`` call, in id order, with the neighbours (in
    index order, then the spheres) and the obstacles it senses. With a ``sensor``
    (``vo3d_opt.sim.sensing.Sensor``; what :func:`decision_step` gives a scenario with sensing
    noise or latency), each agent sees the others as the sensor reports them to it (late,
    noisy; range by the sensed centre distance) and itself exactly."""

    def __init__(
        self,
        sc: Scenario,
        selector: SelectorLike,
        *,
        formulation: str = "custom",
        solver: str = "custom",
        sensor: Sensor | None = None,
    ) -> None:
        super().__init__(sc, selector, formulation=formulation, solver=solver)
        self.sensor = sensor
        self.own_limits = [self.agent_limits(i) for i in range(sc.n_agents)]
        self.sensed_idx = np.flatnonzero(sc.sensed) if sc.obstacles else np.zeros(0, dtype=int)
        self.spheres = sc.sphere_neighbors()
        self.order = sorted(range(sc.n_agents), key=lambda i: sc.ids[i])
        #: With a sensor and a compiled decision, every vehicle in one call (_decide_sensed).
        self.one_call = sensor is not None and bool(getattr(selector, "compiled", False))
        self.sphere_rows = np.array(
            [[*s.position, s.r_pz] for s in self.spheres], dtype=float
        ).reshape(-1, 4)
        self.prism_rows = prism_rows([self.bodies[m] for m in self.sensed_idx])
        self.own_bounds = bounds_rows(self.own_limits, sc.dt)

    def _sensed(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Centre distances (N, N), obstacle surface distances (N, M), sphere surface distances
        (N, S)."""
        centre = np.linalg.norm(p[:, None, :] - p[None, :, :], axis=-1)
        return (centre, *self.surfaces(p))

    def surfaces(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Obstacle surface distances (N, M) and sphere surface distances (N, S)."""
        sc, n = self.scenario, p.shape[0]
        bodies = sc.bodies
        obst = (
            np.stack([bodies[m].surface_distance(p) for m in self.sensed_idx], axis=1)
            if len(self.sensed_idx)
            else np.zeros((n, 0))
        )
        sph = (
            np.stack(
                [
                    sphere_surface_distance(np.asarray(s.center, dtype=float), s.radius, p)
                    for s in sc.spheres
                ],
                axis=1,
            )
            if sc.spheres
            else np.zeros((n, 0))
        )
        return obst, sph

    def decide(self, snap: Snapshot) -> StepDecision:
        p, v = snap.positions, snap.velocities
        n = p.shape[0]
        if self.sensor is not None:
            self.sensor.push(p, v)
        step = StepDecision(
            commands=np.zeros((n, 3)),
            statuses=np.full(n, "", dtype=object),
            decision_times=np.full(n, np.nan),
            solve_times=np.full(n, np.nan),
        )
        if self.one_call:  # the sensed distances are the sensor's: no (N, N) true ones
            self._decide_at_once(snap, *self.surfaces(p), step)
        else:
            self._decide_each(snap, self._sensed(p), step)
        return self._land(snap, step)

    def _decide_at_once(
        self, snap: Snapshot, obst: np.ndarray, sph: np.ndarray, step: StepDecision
    ) -> None:
        """Every deciding vehicle in one compiled call (``_decide_sensed``) into ``step``; each
        one's decision and solve time is the call's time over the vehicles it decided."""
        who = np.array([i for i in self.order if snap.deciding[i]], dtype=np.int64)
        if not who.size:
            return
        t0 = time.perf_counter()
        step.commands[who], step.statuses[who] = self._decide_sensed(snap, who, obst, sph)
        step.decision_times[who] = step.solve_times[who] = (time.perf_counter() - t0) / who.size

    def _decide_each(
        self, snap: Snapshot, sensed: tuple[np.ndarray, np.ndarray, np.ndarray], step: StepDecision
    ) -> None:
        """Each deciding vehicle by its own ``select`` call, in id order, into ``step``."""
        sc = self.scenario
        p, v, done = snap.positions, snap.velocities, ~snap.deciding
        r_pz, vrange, orange = sc.r_pz, sc.sensing.vehicle_range, sc.sensing.obstacle_range
        centre, obst, sph = sensed
        u, statuses = step.commands, step.statuses
        dtimes, stimes = step.decision_times, step.solve_times
        for i in self.order:
            if done[i]:
                continue
            seen_p, seen_v, near = p, v, centre[i]
            if self.sensor is not None:
                seen_p, seen_v = self.sensor.sensed(i)
                near = np.linalg.norm(seen_p - p[i], axis=1)
            neighbors = [
                Neighbor(
                    position=seen_p[j],
                    velocity=seen_v[j],
                    r_pz=float(max(r_pz[i], r_pz[j])),
                    cooperative=not done[j],
                )  # one that does not decide (hovering, or avoids: false) does not avoid
                for j in np.flatnonzero(near <= vrange)
                if j != i
            ]
            neighbors += [self.spheres[s] for s in np.flatnonzero(sph[i] <= orange)]
            obstacles = [self.bodies[self.sensed_idx[m]] for m in np.flatnonzero(obst[i] <= orange)]
            t0 = time.perf_counter()
            d = self.selector.select(
                own=AgentState(position=p[i], velocity=v[i]),
                preferred_velocity=snap.preferred[i],
                neighbors=neighbors,
                obstacles=obstacles,
                limits=self.own_limits[i],
                dt=sc.dt,
            )
            dtimes[i] = time.perf_counter() - t0
            out = np.asarray(d.velocity, dtype=float).reshape(-1)
            u[i] = out if out.shape == (3,) else np.nan
            statuses[i] = str(d.status)
            stimes[i] = float(getattr(d, "solve_time", np.nan))

    def _decide_sensed(
        self, snap: Snapshot, who: np.ndarray, obst: np.ndarray, sph: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The compiled decisions of the vehicles ``who``, each from the others as its sensor
        reports them (``sim.sensed_batch``): what ``_decide_each`` decides, in one call."""
        observers = self.observers(snap.positions, who, obst, sph)
        fleet = Fleet(
            positions=snap.positions,
            velocities=snap.velocities,
            preferred=snap.preferred,
            r_pz=np.asarray(self.scenario.r_pz, dtype=float),
            deciding=snap.deciding,
            bounds=self.own_bounds,
            options=self.own_options(),
        )
        velocities, codes = decide_sensed(fleet, observers, self.sphere_rows, self.prism_rows)
        return velocities, STATUS_NAMES[codes]

    def observers(
        self,
        p: np.ndarray,
        who: Sequence[int] | np.ndarray,
        obst: np.ndarray,
        sph: np.ndarray,
        *,
        at: tuple[int, int, int] = (0, 0, 0),
    ) -> list[Observer]:
        """What each of the vehicles ``who`` senses now (the sensor's view; ``push`` this
        step's state first), given the true positions ``p`` and the surface distances
        ``surfaces`` gives: the vehicles within its range by the sensed centre distance, the
        spheres and obstacles within its obstacle range. ``at``: offsets added to the vehicle,
        sphere and obstacle indices (where the run's rows start in a batch's arrays)."""
        who = np.asarray(who, dtype=np.int64).reshape(-1)
        # the views of a chunk of observers at a time: (D, N, 3) arrays stay small
        chunk = max(1, VIEW_ENTRIES // max(1, p.shape[0]))
        observers: list[Observer] = []
        for c in range(0, who.shape[0], chunk):
            observers += self._views(p, who[c : c + chunk], obst, sph, at)
        return observers

    def _views(
        self,
        p: np.ndarray,
        who: np.ndarray,
        obst: np.ndarray,
        sph: np.ndarray,
        at: tuple[int, int, int],
    ) -> list[Observer]:
        assert self.sensor is not None
        sc = self.scenario
        vrange, orange = sc.sensing.vehicle_range, sc.sensing.obstacle_range
        seen_p, seen_v = self.sensor.sensed_many(who)
        near = np.linalg.norm(seen_p - p[who][:, None, :], axis=-1) <= vrange
        near[np.arange(who.shape[0]), who] = False  # not itself
        in_sph, in_obst = sph[who] <= orange, obst[who] <= orange
        lo, at_sph, at_obst = at
        observers = []
        for d, i in enumerate(who.tolist()):
            js = np.flatnonzero(near[d])
            observers.append(
                Observer(
                    index=i + lo,
                    sensed=js + lo,
                    positions=seen_p[d, js],
                    velocities=seen_v[d, js],
                    spheres=np.flatnonzero(in_sph[d]) + at_sph,
                    obstacles=np.flatnonzero(in_obst[d]) + at_obst,
                )
            )
        return observers

    def own_options(self) -> list[Options]:
        """Each vehicle's planning options (``VelocitySelector.options_for``)."""
        dt = self.scenario.dt
        return [
            self.selector.options_for(lim.speed[1], dt, None, lim.acceleration)
            for lim in self.own_limits
        ]

    def extra(self) -> dict[str, Any]:
        return {
            **super().extra(),
            "decision_step": "select",
            "sensing": "perfect" if self.sensor is None else "noisy/late",
        }


class NoAvoidance:
    """The decision step of a run without avoidance, for scenarios in which no agent avoids
    (every one ``avoids: false``: each flies its preferred velocity straight to its goal, the
    simulator's own rule, and none ever decides). Asked anyway, it keeps every velocity."""

    formulation = "none"
    solver = "none"

    def decide(self, snap: Snapshot) -> StepDecision:
        n = snap.positions.shape[0]
        times = np.full(n, np.nan)
        return StepDecision(
            commands=np.array(snap.velocities, dtype=float),
            statuses=np.full(n, "", dtype=object),
            decision_times=times,
            solve_times=times,
        )

    def extra(self) -> dict[str, Any]:
        return {"decision_step": "none"}


def decision_step(
    sc: Scenario,
    selector: Any,
    *,
    formulation: str = "custom",
    solver: str = "custom",
    max_neighbors: int | None = None,
    threads: int | None = None,
) -> SwarmSelect | PerAgentSelect:
    """``SwarmSelect`` for a selector with ``select_many`` (a ``VelocitySelector``) when every
    vehicle senses the same true snapshot, else ``PerAgentSelect`` (with a ``Sensor`` when the
    scenario's sensing has noise or latency: each vehicle then sees the others differently,
    which one ``select_many`` call cannot express)."""
    if not sc.sensing.perfect:
        if max_neighbors is not None:
            raise ValueError("max_neighbors: only with noiseless, immediate sensing")
        s = sc.sensing
        sensor = Sensor(
            sc.n_agents,
            sc.dt,
            position_noise=s.position_noise,
            velocity_noise=s.velocity_noise,
            latency=s.latency,
            seed=s.seed,
        )
        return PerAgentSelect(sc, selector, formulation=formulation, solver=solver, sensor=sensor)
    if callable(getattr(selector, "select_many", None)):
        return SwarmSelect(
            sc,
            selector,
            formulation=formulation,
            solver=solver,
            max_neighbors=max_neighbors,
            threads=threads,
        )
    if max_neighbors is not None:
        raise ValueError("max_neighbors: only for selectors with select_many")
    return PerAgentSelect(sc, selector, formulation=formulation, solver=solver)
