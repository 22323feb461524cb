"""How a vehicle follows its commanded velocity: one template, three models (contract §5).

Every model integrates N vehicles at once and keeps their state between control periods::

    dyn = make_dynamics({"model": "rotorpy", "vehicle": "hummingbird"},
                        wind={"type": "dryden", "velocity": [2, 0, 0]}, seed=1)
    dyn.reset(starts)                          # (N, 3) positions, velocities 0 (hovering)
    out = dyn.step(commands, dt)               # (N, 3) commanded velocities for the period
    out.positions, out.velocities              # (N, 3) each: the real state at the period's end
    out.sample_positions                       # (S, N, 3): the state at each sub-step end
    dyn.hold(arrived)                          # these stop dead where they are from now on

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

Within one period ``kinematic`` and ``first_order`` move in a straight line at constant velocity
(their single sample is the period's end); ``rotorpy`` samples every sub-step, between which the
path is close to straight at the default rate.
"""

from __future__ import annotations

import math
import sys
import types
from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, StrictBool, model_validator

from vo3d_opt.types import Positive, Vec3, raise_problems

#: Sub-steps per second of the ``rotorpy`` model unless the caller says otherwise: 50 Hz is the
#: lowest measured rate at which both vehicles are stable and their step responses stay close
#: to a 1 kHz integration; this is a factor 2 above it (formulations/dynamics.md).
DEFAULT_SUBSTEP_RATE = 100.0

MODELS = ("kinematic", "first_order", "rotorpy")
VEHICLES = ("hummingbird", "crazyflie")


class _Config(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, arbitrary_types_allowed=True)


class WindConfig(_Config):
    """The ``wind`` mapping of contract §5 (``rotorpy`` only). ``sigma`` (turbulence intensity
    per axis, m/s) and ``altitude`` (m, sets the Dryden length scales) are extensions that
    default to RotorPy's ``DrydenGust`` defaults."""

    type: Literal["constant", "dryden"]
    velocity: Vec3
    sigma: Vec3 | None = None
    altitude: Positive = 2.0

    @model_validator(mode="after")
    def _sigma_only_for_dryden(self) -> WindConfig:
        if self.sigma is not None and self.type != "dryden":
            raise_problems("wind", [(("sigma",), "only for type dryden", self.sigma)])
        if self.sigma is not None and np.any(self.sigma < 0):
            raise_problems("wind", [(("sigma",), "must be >= 0", self.sigma)])
        return self


class DynamicsConfig(_Config):
    """The ``dynamics`` mapping of contract §5; ``substep_rate`` (Hz) and ``command_ramp``
    (default true), both ``rotorpy`` only, extend it."""

    model: Literal["kinematic", "first_order", "rotorpy"] = "kinematic"
    vehicle: Literal["hummingbird", "crazyflie"] | None = None
    tau: Positive | None = None
    substep_rate: Positive | None = None
    command_ramp: StrictBool | None = None

    @property
    def ramped(self) -> bool:
        """Whether the velocity set-point is ramped over each period (rotorpy's default)."""
        return self.model == "rotorpy" and self.command_ramp is not False

    @model_validator(mode="after")
    def _keys_of_the_model(self) -> DynamicsConfig:
        problems = []
        if self.model == "first_order" and self.tau is None:
            problems.append((("tau",), "required for model first_order", None))
        for key, owner in (
            ("tau", "first_order"),
            ("vehicle", "rotorpy"),
            ("substep_rate", "rotorpy"),
            ("command_ramp", "rotorpy"),
        ):
            if self.model != owner and getattr(self, key) is not None:
                problems.append(((key,), f"only for model {owner}", getattr(self, key)))
        raise_problems("dynamics", problems)  # each at its own key: dynamics.tau: ...
        return self


@dataclass(frozen=True)
class StepResult:
    """One control period of N vehicles. ``positions``/``velocities`` (N, 3): the real state at
    the period's end (what the others sense next and the own state of the next decision).
    ``sample_times`` (S,): seconds after the period's start of each sample, the last one ``dt``;
    ``sample_positions``/``sample_velocities`` (S, N, 3): the state at those times."""

    positions: np.ndarray
    velocities: np.ndarray
    sample_times: np.ndarray
    sample_positions: np.ndarray
    sample_velocities: np.ndarray


def _check_array(value: Any, name: str, n: int) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.shape != (n, 3):
        raise ValueError(f"{name}: must have shape ({n}, 3), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: must be finite (no NaN or inf)")
    return arr


def _check_dt(dt: float) -> float:
    if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt: must be a positive finite number, got {dt!r}")
    return float(dt)


class Dynamics(ABC):
    """N vehicles following commanded velocities; ``reset`` before the first ``step``."""

    model: str = ""

    def __init__(self) -> None:
        self.n = 0
        self._p = np.zeros((0, 3))
        self._v = np.zeros((0, 3))
        self._held = np.zeros(0, dtype=bool)

    @property
    def positions(self) -> np.ndarray:
        """(N, 3) current positions (a copy)."""
        return self._p.copy()

    @property
    def velocities(self) -> np.ndarray:
        """(N, 3) current velocities (a copy)."""
        return self._v.copy()

    @property
    def held(self) -> np.ndarray:
        """(N,) which vehicles ``hold`` stopped."""
        return self._held.copy()

    def reset(self, positions: Any, velocities: Any = None) -> None:
        """Start N = len(positions) vehicles there, with ``velocities`` (default 0: hovering)."""
        p = np.asarray(positions, dtype=float)
        if p.ndim != 2 or p.shape[1] != 3:
            raise ValueError(f"positions: must have shape (N, 3), got {p.shape}")
        self.n = p.shape[0]
        self._p = _check_array(p, "positions", self.n).copy()
        self._v = (
            np.zeros((self.n, 3))
            if velocities is None
            else _check_array(velocities, "velocities", self.n).copy()
        )
        self._held = np.zeros(self.n, dtype=bool)
        self._reset_model()

    def hold(self, mask: Any) -> None:
        """Vehicles where ``mask`` (N,) is true stop dead where they are and stay there (the
        simulator's arrived agents hover at their goal); their commands are ignored from now on."""
        m = np.asarray(mask, dtype=bool)
        if m.shape != (self.n,):
            raise ValueError(f"mask: must have shape ({self.n},), got {m.shape}")
        self._held |= m
        self._v[m] = 0.0
        self._hold_model(m)

    def step(self, commands: Any, dt: float) -> StepResult:
        """Fly every vehicle for ``dt`` seconds with its command (N, 3) m/s held constant."""
        u = _check_array(commands, "commands", self.n)
        return self._step(u, _check_dt(dt))

    def _reset_model(self) -> None:  # noqa: B027 - a hook: most models have nothing to reset
        """Model state beyond positions and velocities (none by default)."""

    def _hold_model(self, mask: np.ndarray) -> None:  # noqa: B027 - a hook, like _reset_model
        """Stop the model state of the vehicles in ``mask`` (nothing more by default)."""

    @abstractmethod
    def _step(self, u: np.ndarray, dt: float) -> StepResult: ...

    def _straight(self, v: np.ndarray, dt: float) -> StepResult:
        """Move at constant velocity ``v`` for ``dt`` (held vehicles do not move)."""
        v[self._held] = 0.0
        self._v = v
        self._p = self._p + v * dt
        p, v = self._p.copy(), self._v.copy()
        return StepResult(
            positions=p,
            velocities=v,
            sample_times=np.array([dt]),
            sample_positions=p[None].copy(),
            sample_velocities=v[None].copy(),
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


def vehicle_params(vehicle: str) -> dict[str, Any]:
    """RotorPy's parameter dictionary of ``vehicle`` (``hummingbird`` or ``crazyflie``)."""
    if vehicle == "hummingbird":
        from rotorpy.vehicles.hummingbird_params import quad_params
    elif vehicle == "crazyflie":
        from rotorpy.vehicles.crazyflie_params import quad_params
    else:
        raise ValueError(f"vehicle: must be one of {', '.join(VEHICLES)}, got {vehicle!r}")
    return dict(quad_params)


def hover_rotor_speed(params: Mapping[str, Any]) -> float:
    """Rotor speed (rad/s) at which the rotors carry the weight."""
    return math.sqrt(params["mass"] * 9.81 / (params["num_rotors"] * params["k_eta"]))


class _GlobalRNG:
    """RotorPy's Dryden gusts (and its motor noise) draw from numpy's global random state; this
    gives them a private, seeded stream that is swapped in only while the model steps, so a run
    is reproducible for a seed whatever else in the process uses ``np.random``."""

    def __init__(self, seed: int) -> None:
        saved = np.random.get_state()
        np.random.seed(seed)
        self._state = np.random.get_state()
        np.random.set_state(saved)

    def __enter__(self) -> None:
        self._saved = np.random.get_state()
        np.random.set_state(self._state)

    def __exit__(self, *exc: object) -> None:
        self._state = np.random.get_state()
        np.random.set_state(self._saved)


def dryden_gust_class() -> type:
    """RotorPy's ``DrydenGust``. RotorPy 3.0's Dryden modules import torch at their top for the
    batched (torch) variants only; the numpy ``DrydenGust`` never touches it. Without torch
    installed (it is not a dependency: a CPU build alone is about 800 MB, and importing it would
    add seconds to every RotorPy import), a placeholder module stands in for that import alone
    and is taken out of ``sys.modules`` again at once, so nothing else ever sees it."""
    try:
        from rotorpy.wind.dryden_winds import DrydenGust

        return DrydenGust
    except ImportError as exc:
        if exc.name != "torch":
            raise
    placeholder = types.ModuleType("torch")
    placeholder.tensor = lambda *args, **kwargs: None  # type: ignore[attr-defined]  # the batched classes' default arguments
    sys.modules["torch"] = placeholder
    try:
        from rotorpy.wind.dryden_winds import DrydenGust
    finally:
        del sys.modules["torch"]
    return DrydenGust


def make_wind(config: WindConfig | None, dt: float) -> Any:
    """A RotorPy wind object (``update(t, position) -> (3,)``) for one vehicle; ``dt`` is the
    sub-step (Dryden's discretisation)."""
    if config is None:
        from rotorpy.wind.default_winds import NoWind

        return NoWind()
    if config.type == "constant":
        from rotorpy.wind.default_winds import ConstantWind

        return ConstantWind(*config.velocity.tolist())
    DrydenGust = dryden_gust_class()
    sigma = np.ones(3) if config.sigma is None else np.array(config.sigma)
    return DrydenGust(
        dt=dt, avg_wind=np.array(config.velocity), sig_wind=sigma, altitude=config.altitude
    )


class RotorPyDynamics(Dynamics):
    """Each vehicle a RotorPy ``Multirotor`` flying RotorPy's ``cmd_vel`` velocity controller.

    ``substep_rate`` (Hz): sub-steps per second (the period is cut into ``ceil(dt * rate)``
    equal ones). ``command_ramp``: the velocity set-point goes from the last command to the new
    one in equal steps, one per sub-step (the module docstring says why); False: the new command
    at once. ``wind``: a :class:`WindConfig` (or its mapping) or None; each vehicle gets its
    own wind object (independent Dryden gusts: the relative motion between vehicles, which
    matters for separation, is the largest). ``seed`` fixes the gusts. ``integrator_kwargs``
    go to RotorPy (``scipy.integrate.solve_ivp``; RotorPy's default RK45 when None).

    Vehicles start level with their rotors at hover speed. ``Multirotor`` keeps no state of its
    own (``step(state, control, dt)`` returns the next state), so one instance serves all.
    """

    model = "rotorpy"

    def __init__(
        self,
        vehicle: str = "hummingbird",
        *,
        wind: WindConfig | Mapping | None = None,
        substep_rate: float = DEFAULT_SUBSTEP_RATE,
        command_ramp: bool = True,
        seed: int = 0,
        integrator_kwargs: Mapping[str, Any] | None = None,
    ) -> None:
        super().__init__()
        from rotorpy.vehicles.multirotor import Multirotor

        if not (
            isinstance(substep_rate, (int, float))
            and math.isfinite(substep_rate)
            and substep_rate > 0
        ):
            raise ValueError(
                f"substep_rate: must be a positive finite number, got {substep_rate!r}"
            )
        if not isinstance(seed, (int, np.integer)) or isinstance(seed, bool) or seed < 0:
            raise ValueError(f"seed: must be a non-negative integer, got {seed!r}")
        self.vehicle = vehicle
        self.params = vehicle_params(vehicle)
        self.wind = (
            None
            if wind is None
            else (wind if isinstance(wind, WindConfig) else WindConfig.model_validate(dict(wind)))
        )
        self.substep_rate = float(substep_rate)
        self.command_ramp = bool(command_ramp)
        self.seed = int(seed)
        self.multirotor = Multirotor(
            self.params,
            control_abstraction="cmd_vel",
            integrator_kwargs=dict(integrator_kwargs or {"method": "RK45"}),
        )
        self.hover_speed = hover_rotor_speed(self.params)
        self.t = 0.0
        self.states: list[dict[str, np.ndarray]] = []
        self.setpoints = np.zeros((0, 3))  # (N, 3) the velocity set-point each vehicle flies now
        self.winds: list[Any] = []
        self._rng = _GlobalRNG(self.seed)

    def substeps(self, dt: float) -> int:
        """Sub-steps in a period of ``dt`` s."""
        return max(1, math.ceil(dt * self.substep_rate - 1e-9))

    def _hover_state(self, p: np.ndarray, v: np.ndarray) -> dict[str, np.ndarray]:
        return {
            "x": p.copy(),
            "v": v.copy(),
            "q": np.array([0.0, 0.0, 0.0, 1.0]),
            "w": np.zeros(3),
            "wind": np.zeros(3),
            "rotor_speeds": np.full(self.params["num_rotors"], self.hover_speed),
        }

    def _reset_model(self) -> None:
        self.t = 0.0
        self._rng = _GlobalRNG(self.seed)
        self.states = [self._hover_state(self._p[i], self._v[i]) for i in range(self.n)]
        self.setpoints = self._v.copy()
        with self._rng:  # Dryden draws its first gust at construction
            self.winds = [make_wind(self.wind, 1.0 / self.substep_rate) for _ in range(self.n)]

    def _hold_model(self, mask: np.ndarray) -> None:
        for i in np.flatnonzero(mask):
            self.states[i] = self._hover_state(self._p[i], np.zeros(3))
        self.setpoints[mask] = 0.0

    def _step(self, u: np.ndarray, dt: float) -> StepResult:
        s = self.substeps(dt)
        h = dt / s
        p_out = np.empty((s, self.n, 3))
        v_out = np.empty((s, self.n, 3))
        active = np.flatnonzero(~self._held)
        start = self.setpoints if self.command_ramp else u
        with self._rng:
            for w in self.winds:
                if hasattr(w, "dt"):
                    w.dt = h  # Dryden's discretisation follows the sub-step
            for k in range(s):
                t = self.t + k * h
                cmd_v = start + (u - start) * ((k + 1) / s)  # the set-point of this sub-step
                for i in active:
                    state = self.states[i]
                    state["wind"] = np.asarray(self.winds[i].update(t, state["x"]), dtype=float)
                    self.states[i] = self.multirotor.step(state, {"cmd_v": cmd_v[i]}, h)
                p_out[k] = [st["x"] for st in self.states]
                v_out[k] = [st["v"] for st in self.states]
        self.t += dt
        self.setpoints = np.where(self._held[:, None], 0.0, u)
        p_out[:, self._held] = self._p[self._held]
        v_out[:, self._held] = 0.0
        self._p, self._v = p_out[-1].copy(), v_out[-1].copy()
        return StepResult(
            positions=p_out[-1].copy(),
            velocities=v_out[-1].copy(),
            sample_times=h * np.arange(1, s + 1),
            sample_positions=p_out,
            sample_velocities=v_out,
        )


def make_dynamics(
    dynamics: DynamicsConfig | Mapping[str, Any] | None = None,
    wind: WindConfig | Mapping[str, Any] | None = None,
    *,
    seed: int = 0,
    **rotorpy_options: Any,
) -> Dynamics:
    """The model of a scenario's ``dynamics`` and ``wind`` mappings (contract §5; None: the
    defaults, ``kinematic`` and no wind). ``seed`` fixes the Dryden gusts; ``rotorpy_options``
    (``integrator_kwargs``) go to :class:`RotorPyDynamics`. Bad values raise ``ValueError``
    naming the key."""
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
    return RotorPyDynamics(
        cfg.vehicle or "hummingbird",
        wind=wcfg,
        seed=seed,
        substep_rate=cfg.substep_rate or DEFAULT_SUBSTEP_RATE,
        command_ramp=cfg.ramped,
        **rotorpy_options,
    )
