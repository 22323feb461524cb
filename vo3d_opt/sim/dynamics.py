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
* ``rotorpy`` with ``batched: true``: the same vehicles, controller, wind and ramp, all vehicles
  in one RotorPy ``BatchedMultirotor`` (torch; the ``batched`` extra), one fixed RK4 step per
  sub-step at 200 Hz by default: for swarms, where integrating vehicles one by one takes hours.

Within one period ``kinematic`` and ``first_order`` move in a straight line at constant velocity
(their single sample is the period's end); ``rotorpy`` samples every sub-step, between which the
path is close to straight at the default rate.
"""

from __future__ import annotations

import importlib.util
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

#: The same for ``batched: true``: RotorPy's batched vehicles take one fixed RK4 step per
#: sub-step. At 100 Hz a set-point jump of 4 m/s (a right angle, a diagonal from hover) puts
#: that 2.4-3.4 m from the adaptive RK45 of a single ``Multirotor``; at 200 Hz 1.8-4.6 mm
#: (benchmarks/results_dynamics.md, formulations/dynamics.md).
BATCHED_SUBSTEP_RATE = 200.0

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


#: How to get the ``batched`` extra (torch's CPU build first: PyPI's torch is a CUDA build).
BATCHED_INSTALL = (
    "pip install torch==2.13.0 --index-url https://download.pytorch.org/whl/cpu, then "
    "pip install 'vo3d-opt[batched]'"
)


def _missing_batched_extra() -> str:
    """The modules of the ``batched`` extra that cannot be imported ('' if none), found
    without importing them (torch takes seconds)."""
    missing = []
    for name in ("torch", "torchdiffeq", "roma"):
        try:
            found = importlib.util.find_spec(name) is not None
        except ValueError:  # in sys.modules as None: blocked
            found = False
        if not found:
            missing.append(name)
    return ", ".join(missing)


class DynamicsConfig(_Config):
    """The ``dynamics`` mapping of contract §5; ``substep_rate`` (Hz), ``command_ramp``
    (default true) and ``batched`` (default false: all vehicles in one RotorPy
    ``BatchedMultirotor``, needs the ``batched`` extra), all ``rotorpy`` only, extend it."""

    model: Literal["kinematic", "first_order", "rotorpy"] = "kinematic"
    vehicle: Literal["hummingbird", "crazyflie"] | None = None
    tau: Positive | None = None
    substep_rate: Positive | None = None
    command_ramp: StrictBool | None = None
    batched: StrictBool | None = None

    @property
    def ramped(self) -> bool:
        """Whether the velocity set-point is ramped over each period (rotorpy's default)."""
        return self.model == "rotorpy" and self.command_ramp is not False

    @model_validator(mode="after")
    def _keys_of_the_model(self) -> DynamicsConfig:
        problems: list[tuple[tuple[Any, ...], str, Any]] = []
        if self.model == "first_order" and self.tau is None:
            problems.append((("tau",), "required for model first_order", None))
        if self.batched and (missing := _missing_batched_extra()):
            problems.append((("batched",), f"needs {missing}: {BATCHED_INSTALL}", True))
        # an omitted model is kinematic: say so, the usual slip is forgetting `model: rotorpy`
        model = self.model if "model" in self.model_fields_set else f"{self.model} (no model given)"
        for key, owner in (
            ("tau", "first_order"),
            ("vehicle", "rotorpy"),
            ("substep_rate", "rotorpy"),
            ("command_ramp", "rotorpy"),
            ("batched", "rotorpy"),
        ):
            if self.model != owner and getattr(self, key) is not None:
                problem = f"only for model {owner}, not {model}"
                problems.append(((key,), problem, getattr(self, key)))
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
        if p.ndim != 2 or p.shape[1] != 3 or p.shape[0] == 0:
            raise ValueError(f"positions: must have shape (N, 3) with N >= 1, got {p.shape}")
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
    installed (it is only in the ``batched`` extra: a CPU build alone is about 800 MB), a
    placeholder module stands in for that import alone and is taken out of ``sys.modules``
    again at once, so nothing else ever sees it."""
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


class _RotorPyModel(Dynamics):
    """What both RotorPy models share: the vehicle's parameters, the wind objects, the seeded
    streams, the sub-steps and the ramped set-point. Subclasses integrate the vehicles."""

    model = "rotorpy"

    def __init__(
        self,
        vehicle: str,
        *,
        wind: WindConfig | Mapping | None,
        substep_rate: float,
        command_ramp: bool,
        seed: int,
    ) -> None:
        super().__init__()
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
        self.hover_speed = hover_rotor_speed(self.params)
        self.t = 0.0
        self.setpoints = np.zeros((0, 3))  # (N, 3) the velocity set-point each vehicle flies now
        self.winds: list[Any] = []
        self._rng = _GlobalRNG(self.seed)

    def substeps(self, dt: float) -> int:
        """Sub-steps in a period of ``dt`` s."""
        return max(1, math.ceil(dt * self.substep_rate - 1e-9))

    def _hover_state(self, p: np.ndarray, v: np.ndarray) -> dict[str, np.ndarray]:
        """RotorPy's state of vehicles level at ``p`` with velocity ``v``, rotors at hover
        speed: one vehicle for ``p`` of shape (3,), a batch for (n, 3)."""
        lead = p.shape[:-1]
        return {
            "x": p.copy(),
            "v": v.copy(),
            "q": np.broadcast_to([0.0, 0.0, 0.0, 1.0], (*lead, 4)).copy(),
            "w": np.zeros((*lead, 3)),
            "wind": np.zeros((*lead, 3)),
            "rotor_speeds": np.full((*lead, self.params["num_rotors"]), self.hover_speed),
        }

    def _reset_model(self) -> None:
        self.t = 0.0
        self._rng = _GlobalRNG(self.seed)
        self.setpoints = self._v.copy()
        with self._rng:  # Dryden draws its first gust at construction
            self.winds = [make_wind(self.wind, 1.0 / self.substep_rate) for _ in range(self.n)]

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
                cmd_v = start + (u - start) * ((k + 1) / s)  # the set-point of this sub-step
                p_out[k], v_out[k] = self._substep(self.t + k * h, h, cmd_v, active)
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

    @abstractmethod
    def _substep(
        self, t: float, h: float, cmd_v: np.ndarray, active: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Fly the ``active`` vehicles for ``h`` s from time ``t`` (wind first, as RotorPy's
        ``simulate`` does) towards the set-points ``cmd_v`` (N, 3); return every vehicle's
        (N, 3) positions and velocities (rows of held vehicles are overwritten by the caller)."""


class RotorPyDynamics(_RotorPyModel):
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
        super().__init__(
            vehicle, wind=wind, substep_rate=substep_rate, command_ramp=command_ramp, seed=seed
        )
        from rotorpy.vehicles.multirotor import Multirotor

        self.multirotor = Multirotor(
            self.params,
            control_abstraction="cmd_vel",
            integrator_kwargs=dict(integrator_kwargs or {"method": "RK45"}),
        )
        self.states: list[dict[str, np.ndarray]] = []

    def _reset_model(self) -> None:
        super()._reset_model()
        self.states = [self._hover_state(self._p[i], self._v[i]) for i in range(self.n)]

    def _hold_model(self, mask: np.ndarray) -> None:
        for i in np.flatnonzero(mask):
            self.states[i] = self._hover_state(self._p[i], np.zeros(3))
        self.setpoints[mask] = 0.0

    def _substep(
        self, t: float, h: float, cmd_v: np.ndarray, active: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        for i in active:
            state = self.states[i]
            state["wind"] = np.asarray(self.winds[i].update(t, state["x"]), dtype=float)
            self.states[i] = self.multirotor.step(state, {"cmd_v": cmd_v[i]}, h)
        return (
            np.array([st["x"] for st in self.states]),
            np.array([st["v"] for st in self.states]),
        )


def _import_torch() -> Any:
    """torch, after checking that the rest of the ``batched`` extra (torchdiffeq, roma, which
    RotorPy's batched vehicles import) is there too; a ``ValueError`` naming the key if not."""
    try:
        import roma  # noqa: F401 - imported by RotorPy's batched vehicles
        import torch
        import torchdiffeq  # noqa: F401 - the same
    except ImportError as exc:
        raise ValueError(f"dynamics.batched: needs {exc.name}: {BATCHED_INSTALL}") from exc
    return torch


class BatchedRotorPyDynamics(_RotorPyModel):
    """All vehicles in one RotorPy ``BatchedMultirotor`` (torch, on the CPU) under the same
    ``cmd_vel`` controller, the same parameters, wind objects, ramp and seed as
    :class:`RotorPyDynamics` (a seed gives both the same Dryden gusts), integrated by RotorPy's
    fixed-step ``rk4`` (one step per sub-step, hence the higher default ``substep_rate``): for
    swarms, where the one-by-one model takes hours (cost and accuracy:
    ``benchmarks/results_dynamics.md``). Needs the ``batched`` extra. RotorPy's batched motor
    noise draws from torch's random stream (its scale is 0 for both vehicles): the model keeps
    that stream private and seeded by ``seed``, as it does numpy's."""

    def __init__(
        self,
        vehicle: str = "hummingbird",
        *,
        wind: WindConfig | Mapping | None = None,
        substep_rate: float = BATCHED_SUBSTEP_RATE,
        command_ramp: bool = True,
        seed: int = 0,
        integrator_kwargs: Mapping[str, Any] | None = None,
    ) -> None:
        if integrator_kwargs is not None:
            raise ValueError(
                "integrator_kwargs: only for the one-by-one RotorPy model (the batched one "
                "integrates with RotorPy's fixed-step rk4)"
            )
        self.torch = _import_torch()
        super().__init__(
            vehicle, wind=wind, substep_rate=substep_rate, command_ramp=command_ramp, seed=seed
        )
        self.vehicles: Any = None  # a BatchedMultirotor for the N vehicles of the last reset
        self.state: dict[str, Any] = {}  # RotorPy's batched state: (N, k) float64 tensors
        self._torch_rng = self._seeded_torch_rng()

    def _seeded_torch_rng(self) -> Any:
        with self.torch.random.fork_rng(devices=[]):
            self.torch.manual_seed(self.seed)
            return self.torch.random.get_rng_state()

    def _tensors(self, arrays: Mapping[str, np.ndarray]) -> dict[str, Any]:
        return {key: self.torch.from_numpy(np.ascontiguousarray(a)) for key, a in arrays.items()}

    def _reset_model(self) -> None:
        from rotorpy.vehicles.multirotor import BatchedMultirotor, BatchedMultirotorParams

        super()._reset_model()
        self._torch_rng = self._seeded_torch_rng()
        cpu = self.torch.device("cpu")
        self.state = self._tensors(self._hover_state(self._p, self._v))
        self.vehicles = BatchedMultirotor(
            BatchedMultirotorParams([self.params] * self.n, self.n, cpu),
            self.n,
            self.state,
            cpu,
            control_abstraction="cmd_vel",
            integrator="rk4",
        )

    def _hold_model(self, mask: np.ndarray) -> None:
        self.setpoints[mask] = 0.0

    def _substep(
        self, t: float, h: float, cmd_v: np.ndarray, active: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        torch = self.torch
        if active.size:
            if self.wind is not None:
                self.state["wind"][active] = torch.from_numpy(self._winds_at(t, active))
            with torch.random.fork_rng(devices=[]), torch.no_grad():
                torch.random.set_rng_state(self._torch_rng)
                # RotorPy returns NaN rows for the vehicles it does not step (the held ones):
                # never stepped again, and _step overwrites their samples
                self.state = self.vehicles.step(
                    self.state, {"cmd_v": torch.from_numpy(cmd_v)}, h, idxs=torch.from_numpy(active)
                )
                self._torch_rng = torch.random.get_rng_state()
        # views: the caller copies them into its samples, and step() returns new tensors
        return self.state["x"].numpy(), self.state["v"].numpy()

    def _winds_at(self, t: float, active: np.ndarray) -> np.ndarray:
        """(len(active), 3) the wind of each active vehicle, drawn from numpy's stream in the
        one-by-one model's order: there ``Multirotor.step`` draws its motor noise (4 normals,
        scale 0 for both vehicles) after each vehicle's wind, so the same draws are made here
        and a seed gives both models the same Dryden gusts."""
        x = self.state["x"].numpy()
        out = np.empty((active.size, 3))
        for k, i in enumerate(active):
            out[k] = self.winds[i].update(t, x[i])
            np.random.normal(scale=0.0, size=self.params["num_rotors"])
        return out


def make_dynamics(
    dynamics: DynamicsConfig | Mapping[str, Any] | None = None,
    wind: WindConfig | Mapping[str, Any] | None = None,
    *,
    seed: int = 0,
    **rotorpy_options: Any,
) -> Dynamics:
    """The model of a scenario's ``dynamics`` and ``wind`` mappings (contract §5; None: the
    defaults, ``kinematic`` and no wind). ``seed`` fixes the Dryden gusts; ``rotorpy_options``
    (``integrator_kwargs``) go to :class:`RotorPyDynamics` (refused by the batched model).
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
