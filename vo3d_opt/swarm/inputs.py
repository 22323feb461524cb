"""One ``select_many`` call's arguments checked and turned into the compiled call's arrays
(``SwarmInputs``), and its answer (``SwarmDecision``)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..formulations.swarm import AGENT_COLUMNS, Swarm
from ..geometry.pyramid import prism_rows
from ..types import Box, Cylinder, Limits, positive_seconds
from .checks import count, distance, mask, obstacle_list, points, radii, sphere_rows, vehicle_limits
from .sensing import obstacle_links, sphere_links, vehicle_links


@dataclass
class SwarmDecision:
    """What ``select_many`` returns, per vehicle in the order given.

    ``velocities`` (N, 3) m/s: the decision, or the current velocity of a vehicle that does not
    decide; ``statuses`` (N,) str: the status of ``select``, "" for a vehicle that does not
    decide; ``solve_time`` s: the whole call. Also: ``decided`` (N,) bool;
    ``rounds`` (N,) str: how each velocity was found (``Decision.info["round"]``: "preferred", a
    QP round, "sampled", "least_bad"); ``planes`` (N,) rad: the avoidance plane chosen (NaN: none);
    ``neighbors`` (N,) int: the vehicles each took into account; ``obstacles`` (N,) int: the
    obstacles and spheres it took into account; ``solved`` (N,) int: plane QPs solved; ``times``
    (N,) s: each vehicle's share of the time (its own ``select`` call when looping, the call's
    time shared equally among the deciding vehicles when compiled; NaN when not deciding);
    ``compiled``: whether the one compiled call ran (else a loop of ``select``); ``threads``:
    threads used."""

    velocities: np.ndarray
    statuses: np.ndarray
    solve_time: float
    decided: np.ndarray
    rounds: np.ndarray
    planes: np.ndarray
    neighbors: np.ndarray
    obstacles: np.ndarray
    solved: np.ndarray
    times: np.ndarray
    compiled: bool = False
    threads: int = 1
    info: dict[str, Any] = field(default_factory=dict)


@dataclass
class SwarmInputs:
    """One ``select_many`` call's arguments, checked (``SwarmInputs.checked``): P, V, W (N, 3),
    R (N,), the obstacles, ``bounds`` (N, 6) (``bounds_array`` per vehicle), the deciding
    vehicles (``deciding`` (N,) bool, ``who`` their indices), the sensing parameters and the
    static spheres (S, 5)."""

    P: np.ndarray
    V: np.ndarray
    W: np.ndarray
    R: np.ndarray
    obstacles: list[Cylinder | Box]
    limits: Limits
    dt: float
    bounds: np.ndarray
    deciding: np.ndarray
    sensing_range: float
    max_neighbors: int | None
    obstacle_range: float | None
    spheres: np.ndarray

    @property
    def who(self) -> np.ndarray:
        return np.flatnonzero(self.deciding).astype(np.int64)

    @classmethod
    def checked(
        cls,
        positions: Any,
        velocities: Any,
        preferred_velocities: Any,
        r_pz: Any,
        obstacles: Any,
        limits: Any,
        dt: Any,
        sensing_range: Any,
        max_neighbors: Any,
        decide: Any,
        *,
        obstacle_range: Any = None,
        spheres: Any = None,
        max_speed: Any = None,
    ) -> SwarmInputs:
        """The arguments of ``select_many``, checked: ``ValueError`` naming a bad one."""
        P = points(positions, "positions")
        n = P.shape[0]
        limits = Limits() if limits is None else limits
        if not isinstance(limits, Limits):
            raise ValueError(f"limits: expected Limits, got {type(limits).__name__}")
        dt = positive_seconds(dt, "dt")
        return cls(
            P=P,
            V=points(velocities, "velocities", n),
            W=points(preferred_velocities, "preferred_velocities", n),
            R=radii(r_pz, "r_pz", n),
            obstacles=obstacle_list(obstacles),
            limits=limits,
            dt=float(dt),
            bounds=vehicle_limits(limits, float(dt), n, max_speed),
            deciding=mask(decide, "decide", n),
            sensing_range=distance(sensing_range, "sensing_range", allow_inf=True),
            max_neighbors=count(max_neighbors, "max_neighbors"),
            obstacle_range=None
            if obstacle_range is None
            else distance(obstacle_range, "obstacle_range", allow_inf=True),
            spheres=sphere_rows(spheres),
        )

    def links(self, threads: int = 1) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
        """(span, idx) of the deciding vehicles' neighbours, spheres and obstacles (``threads``:
        see ``vehicle_links``)."""
        who = self.who
        Pd = np.ascontiguousarray(self.P[who])
        return (
            vehicle_links(self.P, who, self.sensing_range, self.max_neighbors, threads),
            sphere_links(Pd, self.spheres, self.obstacle_range),
            obstacle_links(Pd, self.obstacles, self.obstacle_range),
        )

    def arrays(self, threads: int = 1) -> Swarm:
        """The ``Swarm`` arrays of the compiled call (``threads``: see ``vehicle_links``)."""
        agents = np.empty((self.P.shape[0], AGENT_COLUMNS))
        agents[:, 0:3], agents[:, 3:6], agents[:, 6:9] = self.P, self.V, self.W
        agents[:, 9], agents[:, 10] = self.R, self.deciding
        (nb_span, nb_idx), (sp_span, sp_idx), (ob_span, ob_idx) = self.links(threads)
        return Swarm(
            agents,
            self.bounds,
            self.who,
            nb_span,
            nb_idx,
            np.ascontiguousarray(self.spheres[:, [0, 1, 2, 4]]),
            sp_span,
            sp_idx,
            prism_rows(self.obstacles),
            ob_span,
            ob_idx,
        )

    def vehicle_limits(self, i: int) -> Limits:
        """Vehicle i's ``Limits`` (its own v_max under ``max_speed``)."""
        if self.bounds[i, 1] == self.limits.v_max:
            return self.limits
        return self.limits.model_copy(
            update={"speed": (self.limits.v_min, float(self.bounds[i, 1]))}
        )
