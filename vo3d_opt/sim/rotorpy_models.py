"""RotorPy's multirotors behind the :class:`~vo3d_opt.sim.dynamics_base.Dynamics` template:
one by one (:class:`RotorPyDynamics`) or batched in torch (:class:`BatchedRotorPyDynamics`),
with RotorPy's velocity controller, its winds and a ramped set-point (the models' story:
:mod:`vo3d_opt.sim.dynamics`)."""

from __future__ import annotations

import math
import sys
import threading
import types
from abc import abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from vo3d_opt.extras import needs
from vo3d_opt.sim.dynamics_base import (
    BATCHED_SUBSTEP_RATE,
    DEFAULT_SUBSTEP_RATE,
    VEHICLES,
    Dynamics,
    StepResult,
    WindConfig,
)
from vo3d_opt.sim.rotorpy_fleet import RotorPyFleet, import_torch


def vehicle_params(vehicle: str) -> dict[str, Any]:
    """RotorPy's parameter dictionary of ``vehicle`` (``hummingbird`` or ``crazyflie``)."""
    if vehicle not in VEHICLES:
        raise ValueError(f"vehicle: must be one of {', '.join(VEHICLES)}, got {vehicle!r}")
    with needs("rotorpy", "dynamics.model: rotorpy"):  # the first import of every RotorPy model
        if vehicle == "hummingbird":
            from rotorpy.vehicles.hummingbird_params import quad_params
        else:
            from rotorpy.vehicles.crazyflie_params import quad_params
    return dict(quad_params)


def hover_rotor_speed(params: Mapping[str, Any]) -> float:
    """Rotor speed (rad/s) at which the rotors carry the weight."""
    return math.sqrt(params["mass"] * 9.81 / (params["num_rotors"] * params["k_eta"]))


class _GlobalRNG:
    """RotorPy's Dryden gusts (and its motor noise) draw from numpy's global random state; this
    gives them a private, seeded stream that is swapped in only while the model steps, so a run
    is reproducible for a seed whatever else in the process uses ``np.random``. One lock for
    all of them: models of runs flown in threads (a fleet) never swap the state under each
    other."""

    _lock = threading.RLock()

    def __init__(self, seed: int) -> None:
        with self._lock:
            saved = np.random.get_state()
            np.random.seed(seed)
            self._state = np.random.get_state()
            np.random.set_state(saved)

    def __enter__(self) -> None:
        self._lock.acquire()
        try:
            self._saved = np.random.get_state()
            np.random.set_state(self._state)
        except BaseException:
            self._lock.release()
            raise

    def __exit__(self, *exc: object) -> None:
        try:
            self._state = np.random.get_state()
            np.random.set_state(self._saved)
        finally:
            self._lock.release()


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


@dataclass
class Period:
    """One control period of a RotorPy model in flight: the commands ``u`` (N, 3), its
    sub-steps of ``h`` s, the vehicles it steps (``active``) and the samples it fills."""

    u: np.ndarray
    dt: float
    substeps: int
    h: float
    start: np.ndarray  # (N, 3) the set-points the ramp starts from
    active: np.ndarray
    p_out: np.ndarray  # (substeps, N, 3)
    v_out: np.ndarray

    def command(self, k: int) -> np.ndarray:
        """The velocity set-point of sub-step ``k``: ramped from ``start`` to ``u``."""
        return self.start + (self.u - self.start) * ((k + 1) / self.substeps)


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
        period = self._begin(u, dt)
        self._fly(period)
        return self._end(period)

    def _begin(self, u: np.ndarray, dt: float) -> Period:
        s = self.substeps(dt)
        return Period(
            u=u,
            dt=dt,
            substeps=s,
            h=dt / s,
            start=self.setpoints if self.command_ramp else u,
            active=np.flatnonzero(~self._held),
            p_out=np.empty((s, self.n, 3)),
            v_out=np.empty((s, self.n, 3)),
        )

    @abstractmethod
    def _fly(self, period: Period) -> None:
        """Fly the period's ``active`` vehicles through its sub-steps (at each, the wind first,
        as RotorPy's ``simulate`` does, then the set-point ``period.command(k)``), filling its
        samples (rows of held vehicles are overwritten by ``_end``)."""

    def follow_substep(self, h: float) -> None:
        """Dryden's discretisation follows the sub-step ``h``."""
        for w in self.winds:
            if hasattr(w, "dt"):
                w.dt = h

    def _end(self, period: Period) -> StepResult:
        p_out, v_out = period.p_out, period.v_out
        self.t += period.dt
        self.setpoints = np.where(self._held[:, None], 0.0, period.u)
        p_out[:, self._held] = self._p[self._held]
        v_out[:, self._held] = 0.0
        self._p, self._v = p_out[-1].copy(), v_out[-1].copy()
        return StepResult(
            positions=p_out[-1].copy(),
            velocities=v_out[-1].copy(),
            sample_times=period.h * np.arange(1, period.substeps + 1),
            sample_positions=p_out,
            sample_velocities=v_out,
        )


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

    def _fly(self, period: Period) -> None:
        """Fill ``period``'s samples, sub-step by sub-step."""
        h = period.h
        with self._rng:
            self.follow_substep(h)
            for k in range(period.substeps):
                period.p_out[k], period.v_out[k] = self._substep(
                    self.t + k * h, h, period.command(k), period.active
                )

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


class BatchedRotorPyDynamics(_RotorPyModel):
    """All vehicles in one RotorPy ``BatchedMultirotor`` (torch, on the CPU) under the same
    ``cmd_vel`` controller, the same parameters, wind objects, ramp and seed as
    :class:`RotorPyDynamics` (a seed gives both the same Dryden gusts), integrated by RotorPy's
    fixed-step ``rk4`` (one step per sub-step, hence the higher default ``substep_rate``): for
    swarms, where the one-by-one model takes hours (cost and accuracy:
    ``docs/results/dynamics.md``). Needs the ``batched`` extra.

    ``fleet``: a :class:`~vo3d_opt.sim.rotorpy_fleet.RotorPyFleet` whose one ``BatchedMultirotor``
    steps the vehicles of many models at once, each model's run flown in a thread of its own
    (a sweep's RotorPy encounters); None: a fleet of this model alone. Either way a vehicle's
    numbers are the same (the fleet's docstring says why)."""

    def __init__(
        self,
        vehicle: str = "hummingbird",
        *,
        wind: WindConfig | Mapping | None = None,
        substep_rate: float = BATCHED_SUBSTEP_RATE,
        command_ramp: bool = True,
        seed: int = 0,
        integrator_kwargs: Mapping[str, Any] | None = None,
        fleet: RotorPyFleet | None = None,
    ) -> None:
        if integrator_kwargs is not None:
            raise ValueError(
                "integrator_kwargs: only for the one-by-one RotorPy model (the batched one "
                "integrates with RotorPy's fixed-step rk4)"
            )
        import_torch()  # the extra this model needs, named before RotorPy's
        super().__init__(
            vehicle, wind=wind, substep_rate=substep_rate, command_ramp=command_ramp, seed=seed
        )
        if fleet is not None and self.params.get("motor_noise_std", 0.0) != 0.0:
            raise ValueError(
                "fleet: RotorPy's motor noise would draw from the fleet's torch stream: a "
                "vehicle with motor noise flies alone"
            )
        self._own_fleet = fleet is None
        self.fleet = RotorPyFleet(seed=self.seed) if fleet is None else fleet
        self.torch = self.fleet.torch
        self.state: dict[str, Any] = {}  # RotorPy's batched state: (N, k) float64 tensors
        self.fleet.join(self)

    def leave(self) -> None:
        """This model's run is over: its fleet steps without it from now on."""
        self.fleet.leave(self)

    def _reset_model(self) -> None:
        super()._reset_model()
        if self._own_fleet:  # a model alone starts its torch stream again, as numpy's
            self.fleet.reseed(self.seed)
        self.state = {
            key: self.torch.from_numpy(np.ascontiguousarray(a))
            for key, a in self._hover_state(self._p, self._v).items()
        }

    def _hold_model(self, mask: np.ndarray) -> None:
        self.setpoints[mask] = 0.0

    def _release_model(self, mask: np.ndarray) -> None:
        # held rows are NaN (never stepped): each starts again level, at hover, where it stopped
        idx = np.flatnonzero(mask)
        if idx.size:
            rows = self._hover_state(self._p[idx], np.zeros((idx.size, 3)))
            at = self.torch.from_numpy(idx)
            for key, a in rows.items():
                self.state[key][at] = self.torch.from_numpy(a).to(self.state[key].dtype)

    def _fly(self, period: Period) -> None:
        self.fleet.fly(self, period)

    def period_winds(self, period: Period) -> np.ndarray | None:
        """(sub-steps, active vehicles, 3): each active vehicle's wind at each sub-step of
        ``period`` (None without a wind model). Drawn at once, in the one-by-one model's order
        (sub-step by sub-step, vehicle by vehicle): RotorPy's constant and Dryden winds depend
        on neither the time nor the position they are given."""
        if self.wind is None or not period.active.size:
            return None
        h = period.h
        with self._rng:
            self.follow_substep(h)
            return np.stack(
                [self._winds_at(self.t + k * h, period.active) for k in range(period.substeps)]
            )

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
