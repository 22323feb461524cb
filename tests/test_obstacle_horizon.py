"""An obstacle's VO pyramid plans with its own horizon (``obstacle_horizon``, RVO2-3D's
``timeHorizonObst``): none unless given, whatever the neighbours' ``horizon``. A prism does
not turn away as a neighbour does, and a turn left late under actuator lag sinks into it."""
from __future__ import annotations

import numpy as np
import pytest

from vo3d_opt import AgentState, Box, Limits, Neighbor, VelocitySelector
from vo3d_opt.geometry import VOCones, build_pyramids, in_vos, prism_rows


def _towards_a_box(distance: float) -> dict:
    """A vehicle flying at 4 m/s straight at a tall box ``distance`` m ahead."""
    return dict(
        own=AgentState(position=(0.0, 0.0, 20.0), velocity=(4.0, 0.0, 0.0)),
        preferred_velocity=(4.0, 0.0, 0.0),
        obstacles=[Box(center=(distance, 0.0), size=(4.0, 4.0), height=60.0)],
        limits=Limits(speed=(0.0, 4.0), altitude=(0.0, 80.0)),
        dt=0.2,
    )


@pytest.mark.parametrize("formulation", ["plane_qp", "sampled"])
def test_a_short_horizon_does_not_reach_the_obstacles(formulation):
    call = _towards_a_box(60.0)  # 15 s away at 4 m/s
    short = VelocitySelector(formulation, horizon=2.0).select(**call)
    both = VelocitySelector(formulation, horizon=2.0, obstacle_horizon=2.0).select(**call)
    # the box beyond the obstacle horizon leaves the preferred velocity in place ...
    assert np.array_equal(both.velocity, [4.0, 0.0, 0.0])
    # ... while without one its VO holds it, and the answer turns away
    assert not np.array_equal(short.velocity, [4.0, 0.0, 0.0])
    options = VelocitySelector(formulation, horizon=2.0).options_for(4.0, 0.2)
    assert options.obstacle_horizon is None and options.horizon == 2.0


def test_the_exact_check_takes_the_obstacle_horizon():
    call = _towards_a_box(60.0)
    d = VelocitySelector(horizon=2.0).select(**call)
    pyramids = build_pyramids(np.array([0.0, 0.0, 20.0]), prism_rows(call["obstacles"]))
    straight = np.array([[4.0, 0.0, 0.0]])
    assert in_vos(VOCones.empty(), pyramids, straight, horizon=2.0, obstacle_horizon=None).all()
    assert not in_vos(VOCones.empty(), pyramids, straight, horizon=2.0).any()  # "same"
    assert not in_vos(VOCones.empty(), pyramids, d.velocity[None], obstacle_horizon=None).any()


def test_swarm_preset_neighbours_keep_their_horizon():
    """Only the obstacles lose the horizon: a neighbour meeting the vehicle beyond it is still
    ignored by the swarm preset, as RVO2-3D ignores it."""
    sel = VelocitySelector(preset="swarm", sensing_range=55.0)
    far = Neighbor(position=(54.0, 0.0, 20.0), velocity=(0.0, 0.0, 0.0), r_pz=5.0)
    d = sel.select(
        own=AgentState(position=(0.0, 0.0, 20.0), velocity=(4.0, 0.0, 0.0)),
        preferred_velocity=(4.0, 0.0, 0.0),
        neighbors=[far],
        limits=Limits(speed=(0.0, 4.0), altitude=(0.0, 80.0)),
        dt=0.2,
    )
    assert np.array_equal(d.velocity, [4.0, 0.0, 0.0])  # 12 s away, beyond 55 / 8 s
