"""``horizon: "sensing"`` (the swarm preset) plans RVO2-3D's time horizon, the sensing range over
twice the top speed, only for a vehicle that can take any velocity within a step. Under an
acceleration limit that keeps it from that (a lagging vehicle) it plans without a horizon: the
conflicts a horizon leaves for later pile up in a crowd until no velocity in reach is safe."""

from __future__ import annotations

import numpy as np
import pytest

from vo3d_opt import AgentState, Limits, Neighbor, VelocitySelector
from vo3d_opt.config import SelectorConfig, turns_at_once
from vo3d_opt.generators.swarms import sphere_swap_scenario
from vo3d_opt.sim import run_scenario, summarize
from vo3d_opt.sim.scenario import scenario_variant

RANGE, V_MAX, DT = 15.0, 2.0, 0.125


@pytest.mark.parametrize(
    ("acceleration", "horizon"),
    [
        (None, RANGE / (2 * V_MAX)),
        (2 * V_MAX / DT, RANGE / (2 * V_MAX)),  # the bound spans the speed ball per step
        (2 * V_MAX / DT * 0.99, None),
        (2.0, None),
    ],
)
def test_sensing_horizon_by_acceleration(acceleration, horizon):
    config = SelectorConfig.of("swarm")
    resolved = config.resolve(V_MAX, DT, RANGE, acceleration)
    assert resolved["horizon"] == horizon
    assert turns_at_once(V_MAX, DT, acceleration) == (horizon is not None)
    # a number given as the horizon is the user's: kept whatever the acceleration
    fixed = SelectorConfig.of("swarm", horizon=3.0).resolve(V_MAX, DT, RANGE, acceleration)
    assert fixed["horizon"] == 3.0


def test_a_sensing_horizon_without_a_range_is_refused_with_or_without_acceleration():
    for acceleration in (None, 2.0):
        with pytest.raises(ValueError, match="sensing_range"):
            SelectorConfig.of("swarm").resolve(V_MAX, DT, None, acceleration)


def _crowd(rng: np.random.Generator) -> dict:
    """A vehicle at 2 m/s among six neighbours 4-12 m away, heading roughly at it."""
    p = np.array([0.0, 0.0, 50.0])
    neighbours = []
    for _ in range(6):
        u = rng.normal(size=3)
        q = p + u / np.linalg.norm(u) * rng.uniform(4.0, 12.0)
        v = (p - q) / np.linalg.norm(p - q) * rng.uniform(0.2, 2.0) + rng.normal(0, 0.3, 3)
        neighbours.append(Neighbor(position=q, velocity=v, r_pz=3.0))
    return dict(
        own=AgentState(position=p, velocity=rng.normal(0, 1.0, 3)),
        preferred_velocity=(1.0, 0.0, 0.0),
        neighbors=neighbours,
        dt=DT,
        sensing_range=RANGE,
    )


def test_select_under_an_acceleration_limit_plans_without_the_horizon():
    rng = np.random.default_rng(7)
    lagging = Limits(speed=(0.0, V_MAX), altitude=(0.0, 100.0), acceleration=2.0)
    swarm = VelocitySelector(preset="swarm")
    unbounded = VelocitySelector(preset="swarm", horizon=None)
    horizon = VelocitySelector(preset="swarm", horizon=RANGE / (2 * V_MAX))
    differ = 0
    for _ in range(200):
        call = {**_crowd(rng), "limits": lagging}
        d = swarm.select(**call)
        assert np.array_equal(d.velocity, unbounded.select(**call).velocity)
        assert d.status == unbounded.select(**call).status
        differ += not np.array_equal(d.velocity, horizon.select(**call).velocity)
    assert differ > 0  # the horizon would have decided some of them otherwise


def test_select_many_groups_vehicles_by_acceleration_as_select_does():
    rng = np.random.default_rng(3)
    n = 24
    P = rng.uniform(-12.0, 12.0, (n, 3)) + [0.0, 0.0, 50.0]
    V = rng.normal(0.0, 1.0, (n, 3))
    W = -P / np.linalg.norm(P, axis=1, keepdims=True)
    W[:, 2] = 0.0
    R = np.full(n, 3.0)
    top = np.where(np.arange(n) % 2 == 0, V_MAX, 1.5)  # two top speeds: two groups
    sel = VelocitySelector(preset="swarm")
    for acceleration in (None, 2.0):
        limits = Limits(speed=(0.0, V_MAX), altitude=(0.0, 100.0), acceleration=acceleration)
        many = sel.select_many(
            P, V, W, R, limits=limits, dt=DT, sensing_range=RANGE, max_speed=top, threads=1
        )
        for i in range(n):
            js = [j for j in range(n) if j != i and np.linalg.norm(P[j] - P[i]) <= RANGE]
            own = Limits(speed=(0.0, top[i]), altitude=(0.0, 100.0), acceleration=acceleration)
            d = sel.select(
                own=AgentState(position=P[i], velocity=V[i]),
                preferred_velocity=W[i],
                neighbors=[Neighbor(position=P[j], velocity=V[j], r_pz=3.0) for j in js],
                limits=own,
                dt=DT,
                sensing_range=RANGE,
            )
            assert np.array_equal(many.velocities[i], d.velocity), (acceleration, i)


def test_a_lagging_crowd_keeps_its_zones_with_the_swarm_preset():
    """120 vehicles swap ends of a sphere through its centre with a 1 s first-order lag: the
    swarm preset keeps every pair apart; with RVO2-3D's horizon kept, pairs meet."""
    sc = sphere_swap_scenario(
        120, r_pz=3.0, v_max=V_MAX, dt=DT, vehicle_range=RANGE, spacing=1.2, max_time=60.0
    )
    lag = {"model": "first_order", "tau": 1.0}

    def intrusions(**options):
        flown = scenario_variant(sc, selector_options=options, dynamics=lag)
        return summarize(run_scenario(flown, progress=False))["pz_intrusions"]

    assert intrusions(preset="swarm") == 0
    assert intrusions(preset="swarm", horizon=RANGE / (2 * V_MAX)) > 0
