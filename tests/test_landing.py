"""The simulator's landing step for an agent waiting at its goal's door (sim/landing.py)."""

from __future__ import annotations

import numpy as np
import pytest

from vo3d_opt.sim.landing import CLEARANCE, Landing
from vo3d_opt.types import Box, Cylinder, Limits

DT = 0.2
P0 = np.array([0.0, 0.0, 10.0])
# 4 m/s straight at a goal 1.5 m away: the step ends 0.8 m on, 0.7 m from the goal.
W0 = np.array([4.0, 0.0, 0.0])
FAR = np.array([1.5, 8.0, 10.0])  # a vehicle clear of the step whatever it does


def landing(
    *,
    pz_buffer: float = 1.6,
    acceleration: float | None = None,
    bodies: tuple[Cylinder | Box, ...] = (),
    altitude: tuple[float, float] = (1.0, 39.0),
    spheres: np.ndarray | None = None,
) -> Landing:
    return Landing(
        dt=DT,
        r_pz=np.array([6.0, 6.0]),
        pz_buffer=pz_buffer,
        still_pad=max(pz_buffer - 2 * 4.0 * DT, 0.0) + CLEARANCE,
        limits=Limits(speed=(0.0, 4.0), altitude=altitude, acceleration=acceleration),
        bodies=bodies,
        spheres=np.zeros((0, 4)) if spheres is None else spheres,
    )


def land(
    rule: Landing,
    other: np.ndarray,
    *,
    other_decides: bool,
    v0: np.ndarray | None = None,
    other_command: np.ndarray | None = None,
) -> np.ndarray:
    """Agent 0 waiting (its selector answered 0), the other vehicle at ``other`` with
    ``other_command`` (default: hovering); agent 0's command afterwards."""
    u = np.zeros((2, 3))
    if other_command is not None:
        u[1] = other_command
    rule.apply(
        positions=np.array([P0, other]),
        velocities=np.array([np.zeros(3) if v0 is None else v0, np.zeros(3)]),
        preferred=np.array([W0, np.zeros(3)]),
        commands=u,
        waiting=np.array([True, False]),
        deciding=np.array([True, other_decides]),
    )
    return u[0]


def test_a_waiting_agent_takes_a_clear_straight_step_to_its_goal():
    np.testing.assert_array_equal(land(landing(), FAR, other_decides=False), W0)


def test_a_vehicle_that_decides_keeps_its_whole_planning_sphere_one_that_hovers_its_zone():
    """7.03 m from the step's end: outside a hovering vehicle's r_pz + clearance (6.05 m), inside
    the planning sphere of one that may manoeuvre (6 + min(1.6, 0.9 gap) = 7.04 m)."""
    other = np.array([1.5, 7.0, 10.0])
    np.testing.assert_array_equal(land(landing(), other, other_decides=False), W0)
    np.testing.assert_array_equal(land(landing(), other, other_decides=True), np.zeros(3))


def test_the_other_vehicles_command_is_flown_over_the_period():
    """Coming at the step at 4 m/s from 6.5 m away it ends 5.7 m off: too close; at rest, clear;
    a non-finite command counts as the 0 the simulator flies instead (not as no vehicle)."""
    other = np.array([0.8, 6.5, 10.0])
    towards = np.array([0.0, -4.0, 0.0])
    assert np.array_equal(land(landing(), other, other_decides=False), W0)
    stepped = land(landing(), other, other_decides=False, other_command=towards)
    np.testing.assert_array_equal(stepped, np.zeros(3))
    close = np.array([0.8, 6.0, 10.0])  # at rest 6.0 m from the step's end: too close
    nan = land(landing(), close, other_decides=False, other_command=np.full(3, np.nan))
    np.testing.assert_array_equal(nan, np.zeros(3))


def test_no_landing_step_through_an_obstacles_prism_a_sphere_or_out_of_the_altitude_band():
    post = Cylinder(center=(0.4, 1.0), radius=0.3, height=30.0, margin=0.8)  # L_pz / 2 = 1.1 m
    assert np.array_equal(land(landing(bodies=(post,)), FAR, other_decides=False), np.zeros(3))
    ball = np.array([[0.8, 3.0, 10.0, 3.1]])  # its zone reaches within 3.0 m of the step's end
    assert np.array_equal(land(landing(spheres=ball), FAR, other_decides=False), np.zeros(3))
    low = landing(altitude=(10.5, 39.0))
    assert np.array_equal(land(low, FAR, other_decides=False), np.zeros(3))


@pytest.mark.parametrize("v0", [np.zeros(3), np.array([0.0, 1.0, 0.0])])
def test_the_landing_step_keeps_the_acceleration_bound(v0):
    u = land(landing(acceleration=2.0), FAR, other_decides=False, v0=v0)
    assert np.max(np.abs(u - v0)) <= 2.0 * DT + 1e-12
    # on the way from the current velocity to the preferred one
    np.testing.assert_allclose(np.cross(u - v0, W0 - v0), 0.0, atol=1e-12)
    assert np.dot(u - v0, W0 - v0) > 0
