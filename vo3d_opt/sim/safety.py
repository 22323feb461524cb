"""Margins that keep the selector safe under the scenario's dynamics and sensing.

The selector plans as if every vehicle took its new velocity at once and sensed the others
exactly. :func:`derive_margins` sizes, from the scenario alone, what covers the difference
(``formulations/real_world.md`` gives the reasoning and the cost):

* ``tau_eff`` (s): the vehicle's velocity response time: 0 kinematic, ``tau`` first_order,
  RotorPy's ``1/k_v + kd_att/kp_att`` (velocity loop plus attitude loop; 0.186 s for the
  hummingbird) plus ``dt / 2`` when the set-point is ramped over the period (a bound on its
  mean delay, ``(s - 1) / (2 s) dt`` with ``s`` sub-steps; 0.286 s in all at dt 0.2 s;
  ``tests/test_real_world.py`` flies a reversal and measures it);
* ``acceleration`` (m/s² per axis, the selector's ``Limits.acceleration``): ``v_max / tau_eff``,
  capped by what the rotors can give (RotorPy: ``g (T/W - 1)``) and by what RotorPy's velocity
  loop follows without flipping (``GAP_SHARE g / (k_v dt)``, 2.45 m/s²); none for kinematic
  vehicles;
* ``command_rate`` (m/s² per axis, RotorPy only): how fast the simulator lets a command change
  (``COMMAND_SHARE g / (k_v dt)``, 1.23 m/s², :func:`within_reach`), each command then ramped
  over its period (``dynamics.command_ramp``): faster or stepped changes throw the hummingbird
  off its altitude or over the speed limit;
* ``tracking`` (m): how far a vehicle strays from the straight line the selector planned:
  the velocity gap times ``tau_eff``, the gap at most ``min(2 v_max, √3 a dt)``;
* ``pz_buffer`` (m): ``2 v_max dt`` (both move before the next decision: the selector's
  ``buffer_steps``, two in its presets with a buffer) + ``2 tracking``
  (both stray) + ``k σ_p`` (the sensed position's error) + ``v_max latency`` (the other flew
  on since it was sensed) + ``k σ_v (dt + latency)`` (a wrong sensed velocity, extrapolated);
  ``k`` = :data:`NOISE_QUANTILE`;
* ``obstacle_margin`` (m): the clearance a vehicle's centre needs from an obstacle's surface,
  ``tracking + radius`` (obstacles stand still and are known exactly); an obstacle's prism is
  widened only by what this exceeds the prism's own margin (:func:`inflated`): the prism
  keeps the body off the obstacle;
* ``prism_rise`` (m): ``tracking``, by which every prism's top is raised while planning
  (:func:`planning_bodies`; not over a start or goal above the prism): the top is flat, so a
  ray grazing it has no room for a lagging vehicle to fall below it, while the sides are
  planned as the square turned to face the vehicle, which leaves room around the protected
  disc; 0 when the scenario gives ``safety.obstacle_margin``; a top left within ``tracking``
  of the planning ceiling goes up to it (the prism is then gone round);
* ``altitude_margin`` (m): ``max(v_max tau_eff, tracking)``: room to stop from full vertical
  speed, and the altitude a manoeuvre may cost; with rate-limited commands (RotorPy) the
  braking distance ``v_max tau_eff + v_max² / (2 command_rate)``; at most what keeps every
  start and goal inside;
* ``speed_margin`` (m/s, RotorPy in wind only): planned below each vehicle's top speed by this
  much, :data:`SPEED_MARGIN` (at most half the slowest vehicle's speed), and the simulator's
  command-rate limit caps commands there too: the velocity loop overshoots a command at the top
  speed in wind (without wind it does not: ``docs/results/acceleration-bound.md``).

Every value can be overridden by the scenario's ``safety`` mapping, and ``pz_buffer`` /
``acceleration`` by ``selector_options.pz_buffer`` / ``limits.acceleration``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from vo3d_opt.sim.dynamics import DynamicsConfig, vehicle_params
from vo3d_opt.sim.scenario import Scenario
from vo3d_opt.types import Box, Cylinder, Limits

G = 9.81
#: 99.7 % of the norm of a 3-D standard Gaussian (chi with 3 degrees of freedom) lies below this.
NOISE_QUANTILE = 3.76
#: Altitude margins stop this short of the nearest start or goal (m), so both stay plannable.
ALTITUDE_CLEARANCE = 1e-3
#: RotorPy's velocity controller asks for the force ``m (g - k_v e)`` for a velocity gap ``e``;
#: a gap of ``g / k_v`` (0.98 m/s) above the command points that force sideways or down and the
#: vehicle flips and falls (measured in paper case 1). The selector's acceleration bound keeps
#: each period's change within this share of ``g / k_v`` (2.45 m/s² for the hummingbird).
GAP_SHARE = 0.5
#: ... and the simulator lets each command change by a quarter of it per period (1.23 m/s²,
#: :func:`within_reach`), ramped over the period as it hands it to RotorPy
#: (``dynamics.command_ramp``). Stepped at the start of each period, commands changing by half
#: threw the hummingbird 2.6 m off its altitude on purely horizontal manoeuvres, a quarter 0.13
#: m; ramped, 0.02 m at either rate (``docs/results/acceleration-bound.md``). But at half,
#: even ramped, ``ceiling-squeeze-four-uav`` braked out of its altitude band (3 samples) and
#: over the speed limit (5): a quarter it is. The selector's bound is around the real velocity,
#: the rate limit around the previous command: in a steady wind a P loop keeps a steady gap
#: between the two.
COMMAND_SHARE = 0.25
#: m/s: RotorPy's P velocity loop, holding a command at the top speed in a wind of up to 3 m/s
#: (constant or Dryden gusts), flies up to 0.05 m/s above it for a moment
#: (``docs/results/sweeps/rotorpy-speed.md``); the selector plans twice that below. A fixed
#: figure, not a share of the top speed: the overshoot comes from the wind, not the speed.
SPEED_MARGIN = 0.1


@dataclass(frozen=True)
class Margins:
    """What the simulator hands the selector for a scenario (see the module docstring).
    ``acceleration`` None: no acceleration bound. ``why``: one line per derived value."""

    tau_eff: float
    acceleration: float | None
    tracking: float
    #: m/s² per axis: how fast the simulator lets commands change (None: not rate-limited)
    command_rate: float | None
    pz_buffer: float
    obstacle_margin: float
    altitude_margin: float
    prism_rise: float
    speed_margin: float
    why: dict[str, str] = field(default_factory=dict, compare=False)


def response_time(dyn: DynamicsConfig, dt: float) -> float:
    """The velocity response time ``tau_eff`` (s) of the vehicle model, commanded every ``dt``."""
    if dyn.model == "kinematic":
        return 0.0
    if dyn.model == "first_order":
        assert dyn.tau is not None  # DynamicsConfig requires tau for first_order
        return float(dyn.tau)
    p = vehicle_params(dyn.vehicle or "hummingbird")
    k_v, kp, kd = (float(p.get(k, d)) for k, d in (("k_v", 10.0), ("kp_att", 1.0), ("kd_att", 0.0)))
    # a ramped set-point reaches each command at most dt / 2 later on average
    return 1.0 / k_v + kd / kp + (0.5 * dt if dyn.ramped else 0.0)


def controller_acceleration(dyn: DynamicsConfig, dt: float) -> float:
    """RotorPy: the per-axis acceleration (m/s²) whose velocity change per period, handed to
    the ``cmd_vel`` P loop (gain ``k_v``), is :data:`GAP_SHARE` of ``g / k_v``:
    ``GAP_SHARE g / (k_v dt)``; unbounded (inf) for the other models."""
    if dyn.model != "rotorpy":
        return math.inf
    k_v = float(vehicle_params(dyn.vehicle or "hummingbird").get("k_v", 10.0))
    return GAP_SHARE * G / (k_v * dt)


def command_rate(sc: Scenario) -> float | None:
    """m/s² per axis: the rate limit on the commands of vehicles whose controller turns a
    velocity gap into attitude (RotorPy: :data:`COMMAND_SHARE` ``g / (k_v dt)``); None for the
    others (a first-order vehicle follows any command linearly, so a fallback's jump, e.g. to
    keep the altitude limits, harms nothing there)."""
    if sc.vehicle_dynamics.model != "rotorpy":
        return None
    dyn = sc.vehicle_dynamics
    k_v = float(vehicle_params(dyn.vehicle or "hummingbird").get("k_v", 10.0))
    return COMMAND_SHARE * G / (k_v * float(sc.dt))


def thrust_acceleration(dyn: DynamicsConfig) -> float:
    """The largest acceleration (m/s²) the rotors give on every axis: climbing, ``g (T/W - 1)``
    (the tightest); unbounded (inf) for the kinematic and first-order models."""
    if dyn.model != "rotorpy":
        return math.inf
    p = vehicle_params(dyn.vehicle or "hummingbird")
    thrust = p["num_rotors"] * p["k_eta"] * p["rotor_speed_max"] ** 2
    return max(thrust / p["mass"] - G, 0.0)


def _acceleration(sc: Scenario, tau: float, v_max: float) -> tuple[float | None, str]:
    given = sc.safety.acceleration if sc.limits.acceleration is None else sc.limits.acceleration
    if given is not None:
        return (None if given == 0 else float(given)), "given"
    if tau == 0:
        return None, "kinematic: takes any velocity at once"
    dyn = sc.vehicle_dynamics
    thrust, tilt = thrust_acceleration(dyn), controller_acceleration(dyn, float(sc.dt))
    return (
        min(v_max / tau, thrust, tilt),
        f"min(v_max / tau_eff {v_max / tau:.3g}, thrust {thrust:.3g}, controller {tilt:.3g})",
    )


def _speed_margin(sc: Scenario) -> float:
    """:data:`SPEED_MARGIN` for RotorPy vehicles in a wind (a mean wind or gusts), else 0; at
    most half of what the slowest vehicle that avoids has above the minimum speed."""
    wind = sc.wind
    if sc.vehicle_dynamics.model != "rotorpy" or wind is None:
        return 0.0
    gusts = wind.type == "dryden" and (wind.sigma is None or np.any(wind.sigma > 0))
    if not gusts and not np.any(wind.velocity != 0):
        return 0.0
    return min(SPEED_MARGIN, 0.5 * sc.speed_room)


def _altitude_cap(sc: Scenario) -> float:
    """The largest margin that keeps every start and goal within the planning altitudes."""
    z = np.concatenate([sc.starts[:, 2], sc.goals[:, 2]])
    lo, hi = sc.limits.altitude
    room = float(min(np.min(z - lo), np.min(hi - z), 0.5 * (hi - lo)))
    return max(0.0, room - ALTITUDE_CLEARANCE)


def derive_margins(sc: Scenario, buffer_steps: float = 2.0) -> Margins:
    """The margins of the module docstring for scenario ``sc`` (overrides applied);
    ``buffer_steps``: the selector's buffer in steps of flight at the top speed (the ``2 v_max
    dt`` of ``pz_buffer``, two steps in every preset that has a buffer, none in ``paper``)."""
    dt, v_max, sens = float(sc.dt), float(np.max(sc.max_speed)), sc.sensing
    tau = response_time(sc.vehicle_dynamics, dt)
    accel, why_a = _acceleration(sc, tau, v_max)
    gap = 2.0 * v_max if accel is None else min(2.0 * v_max, math.sqrt(3.0) * accel * dt)
    tracking = gap * tau
    noise = NOISE_QUANTILE * (sens.position_noise + sens.velocity_noise * (dt + sens.latency))
    derived_buffer = buffer_steps * v_max * dt + 2.0 * tracking + noise + v_max * sens.latency
    pz_buffer = _pick(sc.selector_options.get("pz_buffer", sc.safety.pz_buffer), derived_buffer)
    obstacle = _pick(sc.safety.obstacle_margin, tracking + float(np.max(sc.radius)))
    rise = tracking if sc.safety.obstacle_margin is None else 0.0
    cap = _altitude_cap(sc)
    stop = max(v_max * tau, tracking)
    rate = command_rate(sc)
    if rate is None or accel is None:  # no acceleration bound: no rate limit either
        rate = None
    else:
        rate = min(rate, accel)
        # braking is rate-limited too, and the vehicle lags tau_eff behind its commands: the
        # distance to stop from full speed
        stop = v_max * tau + v_max**2 / (2.0 * rate)
    altitude = _pick(sc.safety.altitude_margin, min(stop, cap))
    speed = _pick(sc.safety.speed_margin, _speed_margin(sc))
    why = {
        "tau_eff": f"{sc.vehicle_dynamics.model} response time",
        "acceleration": why_a,
        "command_rate": (
            "not rate-limited" if rate is None else f"COMMAND_SHARE g / (k_v dt) {rate:.3g}"
        ),
        "tracking": f"velocity gap {gap:.3g} m/s x tau_eff {tau:.3g} s",
        "pz_buffer": (
            f"{buffer_steps:g} v_max dt {buffer_steps * v_max * dt:.3g} + 2 tracking "
            f"{2 * tracking:.3g} + noise "
            f"{noise:.3g} + latency {v_max * sens.latency:.3g}"
        ),
        "obstacle_margin": "tracking + vehicle radius",
        "prism_rise": "tracking" if sc.safety.obstacle_margin is None else "given obstacle_margin",
        "altitude_margin": (f"stopping room {stop:.3g}, at most {cap:.3g} (starts and goals)"),
        "speed_margin": f"velocity loop overshoot in wind {speed:.3g}" if speed else "none",
    }
    return Margins(
        tau_eff=tau,
        acceleration=accel,
        command_rate=rate,
        tracking=tracking,
        pz_buffer=pz_buffer,
        obstacle_margin=obstacle,
        altitude_margin=altitude,
        prism_rise=rise,
        speed_margin=speed,
        why=why,
    )


def within_reach(
    commands: np.ndarray,
    previous: np.ndarray,
    rate: float,
    dt: float,
    max_speed: np.ndarray,
) -> np.ndarray:
    """Commands (N, 3) moved into the box ``|u - u_prev| <= rate dt`` per axis around the
    previous commands (N, 3), then scaled to at most ``max_speed`` (N,). A rate limit, not a
    bound on the gap to the real velocity: the gap a P loop keeps in a steady wind stays
    possible (clamped to the real velocity, a hummingbird flew 1.9 m/s into a 3 m/s wind when
    asked for 4), while the asked-for force changes slowly (faster changes throw it off its
    altitude; a 4 m/s jump at once flips it: measured, ``formulations/real_world.md``)."""
    reach = rate * dt
    u = previous + np.clip(commands - previous, -reach, reach)
    speed = np.linalg.norm(u, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = np.where(speed > max_speed, max_speed / speed, 1.0)
    return u * scale[:, None]


def _pick(given: float | None, derived: float) -> float:
    return float(derived if given is None else given)


def planning_limits(limits: Limits, m: Margins) -> Limits:
    """The limits the selector plans with: the altitude range shrunk by ``altitude_margin`` on
    both sides, the top speed lowered by ``speed_margin``, ``acceleration`` from the margins."""
    lo, hi = limits.altitude
    return limits.model_copy(
        update={
            "altitude": (lo + m.altitude_margin, hi - m.altitude_margin),
            "speed": (limits.v_min, max(limits.v_min, limits.v_max - m.speed_margin)),
            "acceleration": m.acceleration,
        }
    )


def planning_speeds(sc: Scenario, m: Margins) -> np.ndarray:
    """(N,) the top speed each agent plans with: its own lowered by ``speed_margin``."""
    return np.maximum(sc.limits.v_min, sc.max_speed - m.speed_margin)


def prism_clearance(body: Cylinder | Box) -> float:
    """The least distance from the obstacle's protected prism to its surface (m): outside the
    prism a point is at least this far from the obstacle (horizontally the prism faces the
    vehicle at ``L_pz / 2`` from the axis, and the footprint lies within ``extent / 2``)."""
    return min(0.5 * (body.side - body.footprint_extent()), body.prism_height - body.height)


def inflated(body: Cylinder | Box, clearance: float, rise: float = 0.0) -> Cylinder | Box:
    """The obstacle with its protected prism widened (each side) and raised by what
    ``clearance`` (m) exceeds :func:`prism_clearance`, its top raised by at least ``rise`` (m):
    unchanged when the prism is enough."""
    extra = max(clearance - prism_clearance(body), 0.0)
    up = max(extra, rise)
    if up <= 0:
        return body
    if up == extra and body.L_pz is None and body.h_pz is None:
        return body.model_copy(update={"margin": body.margin + extra})
    return body.model_copy(update={"L_pz": body.side + 2.0 * extra, "h_pz": body.prism_height + up})


def planning_bodies(sc: Scenario, m: Margins) -> list[Cylinder | Box]:
    """The scenario's obstacles as the selector plans with them: :func:`inflated` by
    ``m.obstacle_margin`` and ``m.prism_rise``, the rise stopping :data:`ALTITUDE_CLEARANCE`
    short of any start or goal above a prism (so that it stays reachable). A raised top that
    leaves less than ``m.tracking`` below the planning ceiling goes up to the ceiling (the
    selector then plans round the prism, never over it): in so thin a layer a lagging vehicle
    cannot keep above the top and below the ceiling at once. A given ``safety.obstacle_margin``
    (no rise) sizes the obstacles alone."""
    ends = np.concatenate([sc.starts, sc.goals])
    ceiling = sc.limits.altitude[1] - m.altitude_margin
    out = []
    for body in sc.bodies:
        wide = inflated(body, m.obstacle_margin)
        over = np.linalg.norm(ends[:, :2] - np.asarray(wide.center), axis=1) < wide.side / 2
        above = ends[over, 2] - wide.prism_height
        room = float(np.min(above[above >= 0], initial=math.inf)) - ALTITUDE_CLEARANCE
        raised = inflated(body, m.obstacle_margin, min(m.prism_rise, room))
        thin = 0.0 < ceiling - raised.prism_height < m.tracking
        if m.prism_rise > 0.0 and math.isinf(room) and thin:
            up = ceiling - body.prism_height + ALTITUDE_CLEARANCE
            raised = inflated(body, m.obstacle_margin, up)
        out.append(raised)
    return out
