"""The simulator's landing step for an agent waiting at its goal's door (sim/landing.py)."""

from __future__ import annotations

import numpy as np
import pytest

from vo3d_opt.sim.landing import CLEARANCE, Landing
from vo3d_opt.types import Cylinder, Limits

DT = 0.2
GOAL = np.array([1.5, 0.0, 10.0])
P0 = np.array([0.0, 0.0, 10.0])
# 4 m/s straight at a goal 1.5 m away: the step ends 0.8 m on, 0.7 m from the goal.
W0 = np.array([4.0, 0.0, 0.0])


def landing(*, pz_buffer: float = 1.6, acceleration: float | None = None, bodies=()) -> Landing:
    return Landing(
        goals=np.array([GOAL, [50.0, 50.0, 10.0]]),
        tolerance=1.0,
        dt=DT,
        max_speed=np.array([4.0, 4.0]),
        r_pz=np.array([6.0, 6.0]),
        pz_buffer=pz_buffer,
        still_pad=max(pz_buffer - 2 * 4.0 * DT, 0.0) + CLEARANCE,
        limits=Limits(speed=(0.0, 4.0), altitude=(1.0, 39.0), acceleration=acceleration),
        bodies=tuple(bodies),
        spheres=np.zeros((0, 4)),
    )


def land(rule: Landing, other: np.ndarray, *, other_decides: bool, v0=np.zeros(3)) -> np.ndarray:
    """Agent 0 waiting, the other vehicle at ``other`` hovering (command 0); agent 0's command
    afterwards (the selector's was 0)."""
    p = np.array([P0, other])
    v = np.array([v0, np.zeros(3)])
    u = np.zeros((2, 3))
    rule.apply(
        p,
        v,
        np.array([W0, np.zeros(3)]),
        u,
        np.array([True, False]),
        np.array([True, other_decides]),
    )
    return u[0]


def test_a_waiting_agent_takes_a_clear_straight_step_to_its_goal():
    np.testing.assert_array_equal(
        land(landing(), np.array([1.5, 8.0, 10.0]), other_decides=False), W0
    )


def test_a_vehicle_that_decides_keeps_its_whole_planning_sphere_one_that_hovers_its_zone():
    """7.03 m from the step's end: outside a hovering vehicle's r_pz + clearance (6.05 m), inside
    the planning sphere of one that may manoeuvre (6 + min(1.6, 0.9 gap) = 7.04 m)."""
    other = np.array([1.5, 7.0, 10.0])
    np.testing.assert_array_equal(land(landing(), other, other_decides=False), W0)
    np.testing.assert_array_equal(land(landing(), other, other_decides=True), np.zeros(3))


def test_no_landing_step_through_an_obstacles_prism():
    post = Cylinder(center=(0.4, 1.0), radius=0.3, height=30.0, margin=0.8)  # L_pz / 2 = 1.1 m
    rule = landing(bodies=[post])
    np.testing.assert_array_equal(land(rule, np.array([1.5, 8.0, 10.0]), other_decides=False), 0.0)


@pytest.mark.parametrize("v0", [np.zeros(3), np.array([0.0, 1.0, 0.0])])
def test_the_landing_step_keeps_the_acceleration_bound(v0):
    u = land(landing(acceleration=2.0), np.array([1.5, 8.0, 10.0]), other_decides=False, v0=v0)
    assert np.max(np.abs(u - v0)) <= 2.0 * DT + 1e-12
    # on the way from the current velocity to the preferred one
    np.testing.assert_allclose(np.cross(u - v0, W0 - v0), 0.0, atol=1e-12)
    assert np.dot(u - v0, W0 - v0) > 0
