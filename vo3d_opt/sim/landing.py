"""The last step onto a goal that the VO cannot see into.

A velocity obstacle forbids every velocity whose ray meets a zone at any time, even after the
goal, where the agent stops. A goal in a nook between vehicles that arrived before (say 7.7 m
and 7.8 m from two hovering ones whose planning spheres are 7.6 m) is then out of reach: every
ray into the nook runs on into a sphere, the selector answers a crawl, and the agent creeps
to just outside its goal's tolerance and no further.

Yet the agent stops on arrival: the selector's infinite rays ask too much of its last metres.
An agent that stalled at its goal's door (``GoalWithDetours.waiting``: within ``r_pz`` of its
goal, no progress over a stall window) flies its preferred velocity, straight at the goal,
instead of the selector's answer whenever that step keeps clear, over the whole period, of:

* every vehicle that decides, moving at its command, by the selector's planning radius
  ``r_pz + min(pz_buffer, 0.9 gap)`` (``formulations.common.cone_rows``): it may manoeuvre;
* every vehicle that does not decide (hovering at its goal, or flying straight) and every
  static sphere, moving at its known command, by ``r_pz`` plus what the buffer holds beyond
  the two vehicles' motion in one step, ``pz_buffer - 2 v_max dt`` (tracking, noise,
  latency), plus :data:`CLEARANCE`: the step itself is checked over the period (encounter
  6534: the goal lies 6.63 m from a hovering vehicle, r_pz 5.56 m, its planning sphere
  6.52 m there);
* every sensed obstacle's inflated protected prism, and the planning altitude range;

and within the acceleration bound (scaled back along the way to the preferred velocity if
not). Steps that are not clear are the selector's. The check reads the snapshot's true
states (under noisy or late sensing every radius keeps the buffer's noise and latency share);
the simulator's rate limit (RotorPy) still applies to the step afterwards. Only waiting
agents are affected: every run in which no agent stalls at its goal's door flies exactly as
before.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vo3d_opt.formulations.common import BUFFER_GAP_SHARE
from vo3d_opt.sim.metrics import segment_min
from vo3d_opt.sim.scenario import Scenario, prism_contains
from vo3d_opt.types import Box, Cylinder, Limits

#: Least clearance (m) a landing step keeps beyond a still vehicle's protected zone.
CLEARANCE = 0.05
#: Points checked along a landing step against the obstacles' prisms (the step is at most
#: ``v_max dt`` long: 0.8 m at 4 m/s and 0.2 s, one point every 5 cm).
PRISM_SAMPLES = 17


@dataclass(frozen=True)
class Landing:
    """What a landing step must keep clear of, fixed for a run (see the module docstring)."""

    dt: float
    r_pz: np.ndarray  # (N,)
    pz_buffer: float
    still_pad: float  # m beyond r_pz for vehicles that do not decide (module docstring)
    limits: Limits  # the planning limits (altitude range, acceleration)
    bodies: tuple[Cylinder | Box, ...]  # sensed, inflated
    spheres: np.ndarray  # (S, 4): centre, r_pz

    @classmethod
    def for_scenario(
        cls, sc: Scenario, limits: Limits, bodies: list[Cylinder | Box], pz_buffer: float
    ) -> Landing:
        return cls(
            dt=float(sc.dt),
            r_pz=sc.r_pz,
            pz_buffer=float(pz_buffer),
            still_pad=max(float(pz_buffer) - 2.0 * float(np.max(sc.max_speed)) * float(sc.dt), 0.0)
            + CLEARANCE,
            limits=limits,
            bodies=tuple(b for b, seen in zip(bodies, sc.sensed, strict=True) if seen),
            spheres=np.array([[*s.center, s.r_pz] for s in sc.spheres], dtype=float).reshape(-1, 4),
        )

    def apply(
        self,
        *,
        positions: np.ndarray,
        velocities: np.ndarray,
        preferred: np.ndarray,
        commands: np.ndarray,
        waiting: np.ndarray,
        deciding: np.ndarray,
    ) -> np.ndarray:
        """The agents (bool (N,)) whose command became their landing step; ``commands`` (N, 3)
        is changed in place. Agents are taken in index order, each checked against the others'
        commands as they stand (an earlier landing included; a non-finite one as 0, which the
        simulator flies instead)."""
        p = positions
        moves = np.where(np.isfinite(commands).all(axis=1)[:, None], commands, 0.0)
        landed = np.zeros(p.shape[0], dtype=bool)
        for i in np.flatnonzero(waiting):
            u = self._within_acceleration(preferred[i], velocities[i])
            if self._clear(int(i), p, u, moves, deciding):
                commands[i], moves[i], landed[i] = u, u, True
        return landed

    def _within_acceleration(self, w: np.ndarray, v: np.ndarray) -> np.ndarray:
        """``w``, or the point on the way from ``v`` to it where the per-axis acceleration
        bound stops (the same box the selector plans in)."""
        a = self.limits.acceleration
        gap = float(np.max(np.abs(w - v)))
        if a is None or gap <= a * self.dt:
            return w
        return v + (w - v) * (a * self.dt / gap)

    def _clear(
        self, i: int, p: np.ndarray, u: np.ndarray, commands: np.ndarray, deciding: np.ndarray
    ) -> bool:
        end = p[i] + u * self.dt
        lo, hi = self.limits.altitude
        if not (lo <= end[2] <= hi):
            return False
        others = np.flatnonzero(np.arange(p.shape[0]) != i)
        centres = np.concatenate([p[others], self.spheres[:, :3]])
        moves = np.concatenate([commands[others], np.zeros((len(self.spheres), 3))])
        r_pz = np.concatenate([np.maximum(self.r_pz[i], self.r_pz[others]), self.spheres[:, 3]])
        moving = np.concatenate([deciding[others], np.zeros(len(self.spheres), dtype=bool)])
        gap = np.maximum(np.linalg.norm(centres - p[i], axis=1) - r_pz, 0.0)
        need = r_pz + np.where(
            moving, np.minimum(self.pz_buffer, BUFFER_GAP_SHARE * gap), self.still_pad
        )
        r0 = p[i] - centres
        if np.any(segment_min(r0, r0 + (u - moves) * self.dt) < need):
            return False
        path = p[i] + np.linspace(0.0, 1.0, PRISM_SAMPLES)[:, None] * (u * self.dt)
        return not any(prism_contains(b, path).any() for b in self.bodies)
