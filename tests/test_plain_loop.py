"""A user's own control loop around ``VelocitySelector().select()``: the default is what the
simulator flies.

Two checks: on the simulator's own snapshots, a plain ``select()`` per agent (neighbours built
the way a user builds them) makes the decisions ``vo3d run`` made, bit for bit; and a loop of
one's own, with a plain goal-seeking preferred velocity and kinematic vehicles, flies the
paper's ten-UAV crossing and the 16-UAV swap without a protected-zone intrusion.
"""

from __future__ import annotations

import numpy as np
import pytest

from vo3d_opt import AgentState, Limits, Neighbor, VelocitySelector
from vo3d_opt.sim.scenario import Scenario, load_scenario
from vo3d_opt.sim.simulator import run_scenario

SCENARIOS = ("paper-case1-ten-uav-crossing", "sphere-swap-16")


def neighbours(sc: Scenario, i: int, p: np.ndarray, v: np.ndarray, deciding: np.ndarray):
    """What agent i senses: every other vehicle within the sensing range, with the larger of
    the two protected-zone radii, cooperative when it decides too."""
    near = np.linalg.norm(p - p[i], axis=1) <= sc.sensing.vehicle_range
    return [
        Neighbor(
            position=p[j],
            velocity=v[j],
            r_pz=max(sc.r_pz[i], sc.r_pz[j]),
            cooperative=bool(deciding[j]),
        )
        for j in np.flatnonzero(near)
        if j != i
    ]


def limits(sc: Scenario, i: int) -> Limits:
    return Limits(speed=(sc.limits.v_min, float(sc.max_speed[i])), altitude=sc.limits.altitude)


@pytest.mark.parametrize("name", SCENARIOS)
def test_a_plain_select_per_agent_decides_as_the_simulator(name: str) -> None:
    sc = load_scenario(name)
    record = run_scenario(sc, progress=False)
    assert record.extra["landings"] == 0  # no step of the simulator's own to skip
    selector = VelocitySelector()
    decisions = 0
    for k in range(record.commands.shape[0]):
        p = record.positions[k]
        v = record.velocities[k - 1].copy() if k else np.zeros_like(p)
        deciding = record.decided[k]
        # a vehicle hovers from the step it arrives (whether it then keeps watch or not)
        just_arrived = record.arrived[k] & ~record.arrived[k - 1] if k else record.arrived[k]
        v[(record.arrived[k] & ~deciding) | just_arrived] = 0.0
        for i in np.flatnonzero(deciding):
            d = selector.select(
                own=AgentState(position=p[i], velocity=v[i]),
                preferred_velocity=record.preferred[k, i],
                neighbors=neighbours(sc, i, p, v, deciding),
                limits=limits(sc, i),
                dt=sc.dt,
            )
            assert np.array_equal(d.velocity, record.commands[k, i]), (k, i)
            assert str(d.status) == record.statuses[k, i], (k, i)
            decisions += 1
    assert decisions == int(record.decided.sum()) > 100


def closest_approach(p: np.ndarray, u: np.ndarray, dt: float) -> np.ndarray:
    """(N, N) least distance of every pair over a step flown at velocities ``u`` from ``p``."""
    d0 = p[:, None, :] - p[None, :, :]
    w = u[:, None, :] - u[None, :, :]
    ww = np.einsum("ijk,ijk->ij", w, w)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.clip(np.where(ww > 0, -np.einsum("ijk,ijk->ij", d0, w) / ww, 0.0), 0.0, dt)
    return np.linalg.norm(d0 + w * t[:, :, None], axis=-1)


def fly_own_loop(sc: Scenario, selector: VelocitySelector) -> tuple[bool, float]:
    """A loop of one's own: each vehicle's preferred velocity straight at its goal (full
    speed, slowing to land on it), one ``select()`` each per period, kinematic flight. Whether
    all arrived, and the least gap (m) of any pair to its protected zone (negative: inside)."""
    dt = float(sc.dt)
    p, v = sc.starts.copy(), np.zeros_like(sc.starts)
    r_pz = np.maximum(sc.r_pz[:, None], sc.r_pz[None, :])
    others = ~np.eye(sc.n_agents, dtype=bool)
    arrived = np.zeros(sc.n_agents, dtype=bool)
    closest = np.inf
    for _ in range(sc.n_steps):
        to_goal = sc.goals - p
        dist = np.linalg.norm(to_goal, axis=1)
        speed = np.minimum(sc.max_speed, dist / dt)
        pref = to_goal / np.maximum(dist, 1e-12)[:, None] * speed[:, None]
        u = np.zeros_like(p)
        for i in np.flatnonzero(~arrived):
            u[i] = selector.select(
                own=AgentState(position=p[i], velocity=v[i]),
                preferred_velocity=pref[i],
                neighbors=neighbours(sc, i, p, v, ~arrived),
                limits=limits(sc, i),
                dt=dt,
            ).velocity
        gap = closest_approach(p, u, dt) - r_pz
        closest = min(closest, float(gap[others].min()))
        p, v = p + u * dt, u
        arrived |= np.linalg.norm(sc.goals - p, axis=1) <= sc.goal_tolerance
        if arrived.all():
            break
    return bool(arrived.all()), closest


@pytest.mark.parametrize("name", SCENARIOS)
def test_a_loop_of_ones_own_flies_without_an_intrusion(name: str) -> None:
    arrived, closest = fly_own_loop(load_scenario(name), VelocitySelector())
    assert arrived
    assert closest >= 0.0, f"a pair came {-closest:.3f} m inside a protected zone"


def test_the_paper_preset_in_the_same_loop_lets_pairs_into_each_others_zones() -> None:
    """The selection as published, in the same loop: vehicles slide into each other's zones,
    what the default's reciprocity, buffer and closing guard prevent."""
    _, closest = fly_own_loop(load_scenario(SCENARIOS[0]), VelocitySelector(preset="paper"))
    assert closest < 0.0
