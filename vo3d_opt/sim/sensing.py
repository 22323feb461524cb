"""What each vehicle senses of the others: Gaussian noise and latency (the scenario's ``sensing``).

::

    sensor = Sensor(n, dt, position_noise=0.5, velocity_noise=0.3, latency=0.2, seed=1)
    sensor.push(p, v)              # every step: the true state (N, 3) each, now
    seen_p, seen_v = sensor.sensed(i)   # (N, 3) each: what vehicle i senses of everyone

* Latency: what is sensed of the others is ``latency`` old (a whole number of steps, kept in a
  ring buffer of the last ``latency / dt + 1`` snapshots); before that much history exists the
  oldest snapshot stands in.
* Noise: each sensed position and velocity gets a fresh Gaussian error per axis (1-sigma
  ``position_noise`` m, ``velocity_noise`` m/s), drawn per (observer, target) pair and per
  step: two vehicles never see the same error on a third, as with on-board sensors. The draws
  of observer i at step k come from their own stream, keyed by (seed, k, i), so a run is
  reproducible for a seed whatever the order (or subset) of observers asked, and only those
  that ask pay: 6 N normal draws per ``sensed`` call (measured in benchmarks/bench_dynamics.py).
* A vehicle's own row is its exact current state.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np


def _non_negative(value: Any, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{name}: must be a number, got {value!r}")
    if not math.isfinite(value) or value < 0:
        raise ValueError(f"{name}: must be a finite number >= 0, got {value!r}")
    return float(value)


def latency_steps(latency: float, dt: float) -> int:
    """``latency`` in whole steps of ``dt``; ValueError naming ``latency`` when it is not a
    multiple of ``dt`` (to 1e-6 of a step)."""
    steps = _non_negative(latency, "latency") / dt
    if abs(steps - round(steps)) > 1e-6:
        raise ValueError(f"latency: must be a multiple of dt = {dt:g} s, got {latency!r}")
    return int(round(steps))


class Sensor:
    """Noisy, late views of N vehicles' states; ``push`` the truth once per step."""

    def __init__(
        self,
        n: int,
        dt: float,
        *,
        position_noise: float = 0.0,
        velocity_noise: float = 0.0,
        latency: float = 0.0,
        seed: int = 0,
    ) -> None:
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise ValueError(f"n: must be a positive integer, got {n!r}")
        if _non_negative(dt, "dt") == 0:
            raise ValueError("dt: must be > 0")
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ValueError(f"seed: must be a non-negative integer, got {seed!r}")
        self.n, self.dt, self.seed = int(n), float(dt), int(seed)
        self.position_noise = _non_negative(position_noise, "position_noise")
        self.velocity_noise = _non_negative(velocity_noise, "velocity_noise")
        self.lag = latency_steps(latency, self.dt)
        self._p = np.zeros((self.lag + 1, self.n, 3))
        self._v = np.zeros((self.lag + 1, self.n, 3))
        self.pushes = 0

    @property
    def latency(self) -> float:
        return self.lag * self.dt

    @property
    def noisy(self) -> bool:
        return self.position_noise > 0 or self.velocity_noise > 0

    def push(self, positions: Any, velocities: Any) -> None:
        """Record the true state (N, 3) each of the current step."""
        slot = self.pushes % (self.lag + 1)
        for name, value, buf in (
            ("positions", positions, self._p),
            ("velocities", velocities, self._v),
        ):
            arr = np.asarray(value, dtype=float)
            if arr.shape != (self.n, 3):
                raise ValueError(f"{name}: must have shape ({self.n}, 3), got {arr.shape}")
            if not np.all(np.isfinite(arr)):
                raise ValueError(f"{name}: must be finite (no NaN or inf)")
            buf[slot] = arr
        self.pushes += 1

    def _slot(self, age: int) -> int:
        if self.pushes == 0:
            raise RuntimeError("Sensor: push a state before sensing")
        age = min(age, self.pushes - 1)  # not enough history yet: the oldest snapshot
        return (self.pushes - 1 - age) % (self.lag + 1)

    def delayed(self) -> tuple[np.ndarray, np.ndarray]:
        """The noiseless snapshot everyone senses now, ``latency`` old: (N, 3) each, copies."""
        slot = self._slot(self.lag)
        return self._p[slot].copy(), self._v[slot].copy()

    def noise(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """Observer ``i``'s errors on every target's position and velocity this step, (N, 3)
        each, drawn from the stream keyed by (seed, step, i)."""
        rng = np.random.default_rng([self.seed, self.pushes - 1, int(i)])
        z = rng.standard_normal((2, self.n, 3))
        return z[0] * self.position_noise, z[1] * self.velocity_noise

    def sensed(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """What vehicle ``i`` senses now: positions and velocities (N, 3) of every vehicle,
        the others ``latency`` old and noisy, row ``i`` its own exact current state."""
        if isinstance(i, bool) or not isinstance(i, (int, np.integer)) or not 0 <= i < self.n:
            raise ValueError(f"i: must be a vehicle index in [0, {self.n}), got {i!r}")
        p, v = self.delayed()
        if self.noisy:
            dp, dv = self.noise(i)
            p += dp
            v += dv
        now = self._slot(0)
        p[i], v[i] = self._p[now, i], self._v[now, i]
        return p, v

    def sensed_many(self, who: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``sensed(i)`` for each vehicle index ``i`` of ``who`` (checked as ``sensed`` checks
        it), stacked: (D, N, 3) each, the same numbers (one noiseless snapshot, each
        observer's own errors added to it)."""
        raw = np.asarray(who)
        if raw.size and raw.dtype.kind not in "iu":
            raise ValueError(f"i: must be vehicle indices (integers), got {raw.dtype}")
        who = raw.astype(np.int64).reshape(-1)
        bad = (who < 0) | (who >= self.n)
        if bad.any():
            raise ValueError(f"i: must be a vehicle index in [0, {self.n}), got {who[bad][0]}")
        slot = self._slot(self.lag)
        p = np.repeat(self._p[slot][None], who.shape[0], axis=0)
        v = np.repeat(self._v[slot][None], who.shape[0], axis=0)
        if self.noisy:
            for d, i in enumerate(who.tolist()):
                dp, dv = self.noise(i)
                p[d] += dp
                v[d] += dv
        now, rows = self._slot(0), np.arange(who.shape[0])
        p[rows, who], v[rows, who] = self._p[now, who], self._v[now, who]
        return p, v

    def sensed_all(self) -> tuple[np.ndarray, np.ndarray]:
        """Every observer's view at once: (N, N, 3) each, ``[i]`` = ``sensed(i)``. O(N²)."""
        return self.sensed_many(np.arange(self.n))
