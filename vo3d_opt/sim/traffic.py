"""Non-cooperative traffic (a scenario agent's ``avoids: false``): agents that fly straight
to their goal and never avoid. Their command is the goal-seeking velocity every agent prefers;
the arrived agents they come near decide again (:func:`keep_watch`)."""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.spatial import cKDTree


def goal_velocity(positions: Any, goals: Any, max_speed: Any, dt: float) -> np.ndarray:
    """Velocities (N, 3) straight at each goal with speed ``min(max_speed, distance / dt)``: full
    speed, slowing only to land on the goal in the last period (0 on the goal).

    ``positions``, ``goals``: (N, 3); ``max_speed``: (N,) or one number, m/s; ``dt`` s."""
    p = np.asarray(positions, dtype=float)
    g = np.asarray(goals, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"positions: must have shape (N, 3), got {p.shape}")
    if g.shape != p.shape:
        raise ValueError(f"goals: must have shape {p.shape}, got {g.shape}")
    try:
        v_max = np.broadcast_to(np.asarray(max_speed, dtype=float), (p.shape[0],))
    except ValueError:
        raise ValueError(f"max_speed: must be one number or shape ({p.shape[0]},)") from None
    if np.any(~np.isfinite(v_max)) or np.any(v_max < 0):
        raise ValueError("max_speed: must be finite and >= 0")
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt: must be a positive finite number, got {dt!r}")
    to_goal = g - p
    dist = np.linalg.norm(to_goal, axis=1)
    speed = np.minimum(v_max, dist / dt)
    with np.errstate(invalid="ignore", divide="ignore"):
        unit = np.where(dist[:, None] > 0, to_goal / dist[:, None], 0.0)
    return unit * speed[:, None]


#: Runs flown side by side are told apart by one more coordinate, ``run * RUN_APART`` m, so that
#: a vehicle's nearest threat is one of its own run's whenever its run has any.
RUN_APART = 1e9


def keep_watch(
    positions: np.ndarray,
    goals: np.ndarray,
    *,
    done: np.ndarray,
    straight: np.ndarray,
    watching: np.ndarray,
    tolerance: np.ndarray,
    vehicle_range: np.ndarray,
    run: np.ndarray | None = None,
    stuck: np.ndarray | None = None,
) -> np.ndarray:
    """Which arrived agents decide again (N,): a vehicle that does not avoid (``straight``),
    or one on a detour from a stall (``stuck``), still flying, within their ``vehicle_range``
    of them, or one was (``watching``) and they are not back within ``tolerance`` of their goal.
    A hovering agent that nobody steers round would otherwise be hit where it waits, and
    hovering agents can wall a stalled one off from its goal: deciding again, they take their
    half of the avoidance and make room. ``run`` (N,): the run of each vehicle when runs are
    flown side by side (vehicles see only their own run's); all arrays (N,) but the (N, 3)
    ones."""
    moving = straight if stuck is None else straight | stuck
    kept, threat = done & ~straight, moving & ~done
    if not (kept.any() and (threat.any() or watching.any())):  # most steps of most runs
        return np.zeros(done.shape, dtype=bool)
    finite = np.isfinite(positions).all(axis=1)  # a vehicle gone astray threatens nobody
    kept, threat = kept & finite, threat & finite
    near = np.zeros(done.shape, dtype=bool)
    if threat.any():
        runs = np.zeros(len(positions)) if run is None else np.asarray(run, dtype=float)
        points = np.column_stack([positions, runs * RUN_APART])
        d, j = cKDTree(points[threat]).query(points[kept], k=1)
        same = runs[threat][j] == runs[kept]  # the nearest is another run's: none in this one
        near[kept] = same & (d <= vehicle_range[kept])
    away = np.linalg.norm(positions - goals, axis=1) > tolerance
    return kept & (near | (watching & away))


#: An agent is stalled when, over ``STALL_TIME`` s, it got closer to its goal by less than
#: ``STALL_PROGRESS`` of what its top speed would have flown, and moved less than
#: ``STALL_MOTION`` of it (one that circles its goal, overshooting it under a lag, is not
#: stalled: a detour would only send it further off).
STALL_TIME = 4.0
STALL_PROGRESS = 0.05
STALL_MOTION = 0.25
#: Detours in a row turn ``detour_deg`` times 1, 2, ..., DETOUR_TURNS, then 1 again (90°, 180°,
#: 270°: right, back, left): one side may be walled, where the right turn's nearest safe
#: velocity is hovering again.
DETOUR_TURNS = 3


class GoalWithDetours:
    """:func:`goal_velocity`, with a way out of the VO method's deadlocks (a local rule cannot
    see round a wall of hovering or waiting vehicles): an agent that has stalled
    (``STALL_PROGRESS``) over ``stall_time`` s prefers, for the next ``stall_time`` s, its goal
    direction turned ``detour_deg`` to the right about the vertical, at full speed (all turn the
    same way, as traffic keeps right); then the goal again. An agent stalled again right after a
    detour turns further each time (``DETOUR_TURNS``: 90°, 180°, 270°, then 90° again), until a
    window without a stall starts the count afresh. The selector still keeps every zone clear: a
    detour changes only what the agent would like. Within ``near`` (m, per agent; the simulator
    passes its r_pz) of its goal an agent never detours: what blocks it is at the goal, and a
    detour there would only send it off again and again, and it would never arrive. Such an
    agent is ``waiting`` (N,) from then on while it stays within ``near``: the simulator may
    land it (``vo3d_opt.sim.landing``).

    Called once per control step with the positions (N, 3), as the simulator does; stateful
    (one instance per run)."""

    def __init__(
        self,
        goals: Any,
        max_speed: Any,
        dt: float,
        *,
        stall_time: float = STALL_TIME,
        detour_deg: float = 90.0,
        near: Any = 0.0,
    ) -> None:
        if not (np.isfinite(stall_time) and stall_time > 0):
            raise ValueError(
                f"stall_time: must be a positive number of seconds, got {stall_time!r}"
            )
        if not np.isfinite(detour_deg):
            raise ValueError(f"detour_deg: must be a finite angle, got {detour_deg!r}")
        self.goals = np.asarray(goals, dtype=float)
        n = self.goals.shape[0]
        self.v_max = np.broadcast_to(np.asarray(max_speed, dtype=float), (n,)).copy()
        self.near = np.broadcast_to(np.asarray(near, dtype=float), (n,)).copy()
        self.dt, self.stall_time = float(dt), float(stall_time)
        turn = np.deg2rad(detour_deg)
        # the k-th detour in a row turns k * detour_deg (one scalar cos and sin per k)
        self.cos_k = np.array([np.cos(turn * k) for k in range(DETOUR_TURNS + 1)])
        self.sin_k = np.array([np.sin(turn * k) for k in range(DETOUR_TURNS + 1)])
        self.t = 0.0
        self.ref_dist = np.full(n, np.inf)  # distance to goal at the last check
        self.ref_pos = np.zeros((n, 3))  # and position
        self.ref_t = np.zeros(n)
        self.detour_until = np.full(n, -np.inf)
        self.in_row = np.zeros(n, dtype=np.int64)  # detours in a row: the last one's turn
        self.waiting = np.zeros(n, dtype=bool)

    @property
    def stuck(self) -> np.ndarray:
        """(N,) the agents on a detour from a stall at the next call (``keep_watch``'s)."""
        return self.t < self.detour_until

    def __call__(self, positions: Any) -> np.ndarray:
        p = np.asarray(positions, dtype=float)
        w = goal_velocity(p, self.goals, self.v_max, self.dt)
        dist = np.linalg.norm(self.goals - p, axis=1)
        on = self.t < self.detour_until
        fresh = np.isinf(self.ref_dist) & ~on  # start, or a detour just ended: judge afresh
        self._mark(fresh, p, dist)
        check = ~on & (self.t - self.ref_t >= self.stall_time - 1e-9)
        reach = self.v_max * self.stall_time
        gained = self.ref_dist - dist
        moved = np.linalg.norm(p - self.ref_pos, axis=1)
        stalled = check & (gained < STALL_PROGRESS * reach) & (moved < STALL_MOTION * reach)
        # at its goal's door and stalled: waiting, until it arrives or is pushed off again
        self.waiting = (self.waiting | stalled) & (dist <= self.near)
        stalled &= dist > self.near  # at its goal's door, waiting is the way in
        self.detour_until[stalled] = self.t + self.stall_time
        self.ref_dist[stalled] = np.inf
        self.in_row[stalled] = self.in_row[stalled] % DETOUR_TURNS + 1
        self.in_row[check & ~stalled] = 0  # it moved on (or waits at its goal): count afresh
        self._mark(check & ~stalled, p, dist)
        on |= stalled
        if on.any():
            w[on] = self._detour(w[on], self.v_max[on], self.in_row[on])
        self.t += self.dt
        return w

    def _mark(self, which: np.ndarray, p: np.ndarray, dist: np.ndarray) -> None:
        """Start the next window of the agents ``which`` here and now."""
        self.ref_dist[which], self.ref_pos[which], self.ref_t[which] = dist[which], p[which], self.t

    def _detour(self, w: np.ndarray, v_max: np.ndarray, in_row: np.ndarray) -> np.ndarray:
        """The goal directions of ``w`` turned right about the vertical by ``in_row`` times the
        detour angle, at ``v_max``."""
        c, s = self.cos_k[in_row], self.sin_k[in_row]
        x, y = w[:, 0], w[:, 1]
        turned = np.stack([c * x + s * y, -s * x + c * y, w[:, 2]], axis=1)
        norm = np.linalg.norm(turned, axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(norm[:, None] > 0, turned * (v_max / norm)[:, None], 0.0)
