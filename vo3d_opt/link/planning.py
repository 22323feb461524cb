"""What one vehicle of a scenario plans with: the selector, its limits, the obstacles and its
preferred velocity, as the simulator gives them to that agent (``vo3d_opt.sim.deciders``), so
that a link decides on a snapshot what ``vo3d run`` would."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from vo3d_opt.sim.safety import derive_margins, planning_bodies, planning_limits, planning_speeds
from vo3d_opt.sim.scenario import Scenario, sphere_surface_distance
from vo3d_opt.sim.simulator import scenario_selector
from vo3d_opt.sim.traffic import GoalWithDetours
from vo3d_opt.types import AgentState, Box, Cylinder, Limits, Neighbor


@dataclass(frozen=True)
class LinkSelector:
    """A selector and the names of its formulation and solver (for the summaries)."""

    selector: Any
    formulation: str
    solver: str

    def warm_up(self) -> None:
        """One decision on a small encounter, so that a kernel compiled on first use is
        compiled now, not in flight."""
        self.selector.select(
            own=AgentState(position=(0.0, 0.0, 20.0), velocity=(1.0, 0.0, 0.0)),
            preferred_velocity=(1.0, 0.0, 0.0),
            neighbors=[Neighbor(position=(30.0, 0.0, 20.0), velocity=(-1.0, 0.0, 0.0), r_pz=10.0)],
            obstacles=[],
            limits=Limits(speed=(0.0, 2.0), altitude=(0.0, 40.0)),
            dt=0.1,
        )


def link_selector(sc: Scenario, agent: str) -> LinkSelector:
    """The selector that flies ``agent`` of ``sc`` through a link: the one place it is built.
    It is what the simulator flies for the scenario (``scenario_selector``: the scenario's
    preset, ``safe`` unless it names another, its ``selector_options``, and the buffer its
    physics need); its buffer in steps is resolved with the link's own period."""
    if agent not in sc.ids:
        raise ValueError(f"agent: {agent!r} is not in scenario {sc.name} ({', '.join(sc.ids)})")
    selector, formulation, solver = scenario_selector(sc)
    return LinkSelector(selector, formulation, solver)


class Plan:
    """Agent ``agent`` of ``sc`` deciding every ``period`` s: its planning limits (the
    simulator's altitude margin and acceleration bound, its own speed cap less the speed
    margin), the sensed obstacles inflated as the simulator plans with them, the static
    spheres, its goal and the simulator's preferred-velocity rule (towards the goal, with its
    detours out of deadlocks)."""

    def __init__(self, sc: Scenario, agent: str, period: float) -> None:
        i = sc.ids.index(agent)
        self.index, self.scenario = i, sc
        margins = derive_margins(sc)
        limits = planning_limits(sc.limits, margins)
        self.limits: Limits = limits.model_copy(
            update={"speed": (sc.limits.v_min, float(planning_speeds(sc, margins)[i]))}
        )
        bodies = planning_bodies(sc, margins)
        seen = np.flatnonzero(sc.sensed) if sc.obstacles else np.zeros(0, dtype=int)
        self.bodies: list[tuple[Cylinder | Box, Cylinder | Box]] = [
            (sc.bodies[k], bodies[k]) for k in seen
        ]
        self.spheres = list(zip(sc.spheres, sc.sphere_neighbors(), strict=True))
        self.goal = np.asarray(sc.goals[i], dtype=float)
        self.r_pz = float(sc.r_pz[i])
        self.top_speed = float(sc.max_speed[i])
        self._prefer = GoalWithDetours(
            sc.goals[i : i + 1], sc.cruise_speed[i : i + 1], period, near=sc.r_pz[i : i + 1]
        )

    def arrived(self, p: np.ndarray) -> bool:
        return float(np.linalg.norm(p - self.goal)) <= self.scenario.goal_tolerance

    def preferred(self, p: np.ndarray) -> np.ndarray:
        """The preferred velocity at ``p`` (call once per decision: the rule keeps time)."""
        return np.asarray(self._prefer(p[None, :]), dtype=float)[0]

    def obstacles(self, p: np.ndarray) -> list[Cylinder | Box]:
        """The planning obstacles whose real surface is within the obstacle sensing range."""
        reach = self.scenario.sensing.obstacle_range
        return [
            plan for body, plan in self.bodies if float(body.surface_distance(p[None])[0]) <= reach
        ]

    def sphere_neighbors(self, p: np.ndarray) -> list[Neighbor]:
        """The static spheres within the obstacle sensing range, as neighbours."""
        reach = self.scenario.sensing.obstacle_range
        return [
            n
            for s, n in self.spheres
            if float(sphere_surface_distance(np.asarray(s.center, float), s.radius, p[None])[0])
            <= reach
        ]
