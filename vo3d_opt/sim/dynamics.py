"""How a vehicle follows its commanded velocity: one template, three models.

Every model integrates N vehicles at once and keeps their state between control periods::

    dyn = make_dynamics({"model": "rotorpy", "vehicle": "hummingbird"},
                        wind={"type": "dryden", "velocity": [2, 0, 0]}, seed=1)
    dyn.reset(starts)                          # (N, 3) positions, velocities 0 (hovering)
    out = dyn.step(commands, dt)               # (N, 3) commanded velocities for the period
    out.positions, out.velocities              # (N, 3) each: the real state at the period's end
    out.sample_positions                       # (S, N, 3): the state at each sub-step end
    dyn.hold(arrived)                          # these stop dead where they are, until
    dyn.release(watching)                      # these fly their commands again, from hover

Models (the vehicle, its velocity controller and the wind are kept apart as in RotorPy):

* ``kinematic``: the vehicle takes the command at once, ``p += v_cmd dt``.
* ``first_order``: ``v += (v_cmd - v) min(1, dt / tau)``, ``p += v dt``: the simulator's
  ``velocity_response_tau``, bit for bit.
* ``rotorpy``: each vehicle is a RotorPy ``Multirotor`` (``hummingbird`` or ``crazyflie``
  parameters) under RotorPy's own velocity controller (the ``cmd_vel`` control abstraction),
  integrated in ``ceil(dt * substep_rate)`` equal sub-steps per period, the wind
  (RotorPy's ``ConstantWind`` or ``DrydenGust``) updated before each sub-step as RotorPy's
  ``simulate`` does. The controller's rotor command is held over a sub-step, so the sub-step
  rate decides stability: see ``formulations/dynamics.md`` for the measured figures. The
  velocity set-point moves from the last command to the new one over the period, a step per
  sub-step (``command_ramp``, on by default), as an autopilot smooths its set-points: RotorPy's
  stiff velocity loop (``k_v`` 10) turns a set-point step into an attitude step, and a step of
  0.25 m/s per axis on top of the usual lag saturated the hummingbird's rotors in paper case 1
  (45 degrees of tilt, 28 degrees of yaw, 4.7 m/s for a 3.7 m/s command).
* ``rotorpy`` with ``batched: true``: the same vehicles, controller, wind and ramp, all vehicles
  in one RotorPy ``BatchedMultirotor`` (torch; the ``batched`` extra), one fixed RK4 step per
  sub-step at 200 Hz by default: for swarms, where integrating vehicles one by one takes hours.

Within one period ``kinematic`` and ``first_order`` move in a straight line at constant velocity
(their single sample is the period's end); ``rotorpy`` samples every sub-step, between which the
path is close to straight at the default rate.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from vo3d_opt.sim.dynamics_base import (
    BATCHED_SUBSTEP_RATE,
    DEFAULT_SUBSTEP_RATE,
    MODELS,
    VEHICLES,
    Dynamics,
    DynamicsConfig,
    StepResult,
    WindConfig,
)
from vo3d_opt.sim.rotorpy_models import (
    BatchedRotorPyDynamics,
    RotorPyDynamics,
    dryden_gust_class,
    hover_rotor_speed,
    make_wind,
    vehicle_params,
)


class KinematicDynamics(Dynamics):
    """The vehicle flies its command at once: ``v = v_cmd``, ``p += v dt``."""

    model = "kinematic"

    def _step(self, u: np.ndarray, dt: float) -> StepResult:
        return self._straight(u.copy(), dt)


class FirstOrderDynamics(Dynamics):
    """First-order velocity response with time constant ``tau`` (s), one explicit step per
    period: ``v += (v_cmd - v) min(1, dt / tau)``, then ``p += v dt``."""

    model = "first_order"

    def __init__(self, tau: float) -> None:
        super().__init__()
        if not (isinstance(tau, (int, float)) and math.isfinite(tau) and tau > 0):
            raise ValueError(f"tau: must be a positive finite number, got {tau!r}")
        self.tau = float(tau)

    def _step(self, u: np.ndarray, dt: float) -> StepResult:
        alpha = min(1.0, dt / self.tau)
        return self._straight(self._v + (u - self._v) * alpha, dt)


def make_dynamics(
    dynamics: DynamicsConfig | Mapping[str, Any] | None = None,
    wind: WindConfig | Mapping[str, Any] | None = None,
    *,
    seed: int = 0,
    **rotorpy_options: Any,
) -> Dynamics:
    """The model of a scenario's ``dynamics`` and ``wind`` mappings (None: the
    defaults, ``kinematic`` and no wind). ``seed`` fixes the Dryden gusts; ``rotorpy_options``
    go to the RotorPy model: ``integrator_kwargs`` to :class:`RotorPyDynamics` (refused by the
    batched model), ``fleet`` to :class:`BatchedRotorPyDynamics` (``RotorPyFleet``).
    Bad values raise ``ValueError`` naming the key."""
    cfg = (
        dynamics
        if isinstance(dynamics, DynamicsConfig)
        else DynamicsConfig.model_validate(dict(dynamics or {}))
    )
    wcfg = (
        wind
        if (wind is None or isinstance(wind, WindConfig))
        else WindConfig.model_validate(dict(wind))
    )
    if wcfg is not None and cfg.model != "rotorpy":
        raise ValueError(f"wind: only with dynamics model rotorpy, not {cfg.model}")
    if cfg.model == "kinematic":
        return KinematicDynamics()
    if cfg.model == "first_order":
        assert cfg.tau is not None  # DynamicsConfig requires tau for first_order
        return FirstOrderDynamics(cfg.tau)
    model, rate = (
        (BatchedRotorPyDynamics, BATCHED_SUBSTEP_RATE)
        if cfg.batched
        else (RotorPyDynamics, DEFAULT_SUBSTEP_RATE)
    )
    return model(
        cfg.vehicle or "hummingbird",
        wind=wcfg,
        seed=seed,
        substep_rate=cfg.substep_rate or rate,
        command_ramp=cfg.ramped,
        **rotorpy_options,
    )


__all__ = [
    "BATCHED_SUBSTEP_RATE",
    "DEFAULT_SUBSTEP_RATE",
    "MODELS",
    "VEHICLES",
    "BatchedRotorPyDynamics",
    "Dynamics",
    "DynamicsConfig",
    "FirstOrderDynamics",
    "KinematicDynamics",
    "RotorPyDynamics",
    "StepResult",
    "WindConfig",
    "dryden_gust_class",
    "hover_rotor_speed",
    "make_dynamics",
    "make_wind",
    "vehicle_params",
]
