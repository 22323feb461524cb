"""The template every vehicle model follows (:class:`Dynamics`: N vehicles, ``reset``,
``step``, ``hold``, ``release``), what a step returns, and the scenario keys ``dynamics`` and
``wind`` (:mod:`vo3d_opt.sim.dynamics` has the models and ``make_dynamics``)."""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, StrictBool, model_validator

from vo3d_opt.extras import missing, needs_text
from vo3d_opt.types import Positive, Vec3, raise_problems

#: Sub-steps per second of the ``rotorpy`` model unless the caller says otherwise: 50 Hz is the
#: lowest measured rate at which both vehicles are stable and their step responses stay close
#: to a 1 kHz integration; this is a factor 2 above it (formulations/dynamics.md).
DEFAULT_SUBSTEP_RATE = 100.0

#: The same for ``batched: true``: RotorPy's batched vehicles take one fixed RK4 step per
#: sub-step. At 100 Hz a set-point jump of 4 m/s (a right angle, a diagonal from hover) puts
#: that 2.4-3.4 m from the adaptive RK45 of a single ``Multirotor``; at 200 Hz 1.8-4.6 mm
#: (docs/results/dynamics.md, formulations/dynamics.md).
BATCHED_SUBSTEP_RATE = 200.0

MODELS = ("kinematic", "first_order", "rotorpy")
VEHICLES = ("hummingbird", "crazyflie")


class _Config(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, arbitrary_types_allowed=True)


#: The strongest wind (m/s) a scenario may ask for: RotorPy's vehicles are blown away far
#: below it, and far above it its integration overflows.
MAX_WIND = 100.0


class WindConfig(_Config):
    """The ``wind`` mapping of a scenario (``rotorpy`` only). ``sigma`` (turbulence intensity
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
        for key, value in (("velocity", self.velocity), ("sigma", self.sigma)):
            if value is not None and np.linalg.norm(value) > MAX_WIND:
                what = f"at most {MAX_WIND:g} m/s (a hurricane is 70)"
                raise_problems("wind", [((key,), what, value)])
        return self


class DynamicsConfig(_Config):
    """The ``dynamics`` mapping of a scenario; ``substep_rate`` (Hz), ``command_ramp``
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
        if self.model == "rotorpy" and (absent := missing("rotorpy")):
            problems.append((("model",), needs_text("rotorpy", absent), self.model))
        if self.batched and (absent := missing("batched")):
            problems.append((("batched",), needs_text("batched", absent), True))
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
        simulator's arrived agents hover at their goal); their commands are ignored until
        ``release``."""
        m = np.asarray(mask, dtype=bool)
        if m.shape != (self.n,):
            raise ValueError(f"mask: must have shape ({self.n},), got {m.shape}")
        self._held |= m
        self._v[m] = 0.0
        self._hold_model(m)

    def release(self, mask: Any) -> None:
        """Held vehicles where ``mask`` (N,) is true follow their commands again, starting from
        hover where they are (the simulator's arrived agents that must avoid a vehicle that does
        not: ``vo3d_opt.sim.traffic.keep_watch``)."""
        m = np.asarray(mask, dtype=bool)
        if m.shape != (self.n,):
            raise ValueError(f"mask: must have shape ({self.n},), got {m.shape}")
        m = m & self._held
        self._held &= ~m
        self._release_model(m)

    def step(self, commands: Any, dt: float) -> StepResult:
        """Fly every vehicle for ``dt`` seconds with its command (N, 3) m/s held constant."""
        u = _check_array(commands, "commands", self.n)
        return self._step(u, _check_dt(dt))

    def _reset_model(self) -> None:  # noqa: B027 - a hook: most models have nothing to reset
        """Model state beyond positions and velocities (none by default)."""

    def _hold_model(self, mask: np.ndarray) -> None:  # noqa: B027 - a hook, like _reset_model
        """Stop the model state of the vehicles in ``mask`` (nothing more by default)."""

    def _release_model(self, mask: np.ndarray) -> None:  # noqa: B027 - a hook, like _hold_model
        """Restart the model state of the vehicles in ``mask`` at hover (nothing by default)."""

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
