"""Public data types of the contract (shared/spec/contracts.md §1), validated with pydantic.

Every malformed value raises ``ValueError`` (pydantic's ``ValidationError`` is one) whose
message names the field. Vectors are stored as read-only numpy arrays, world frame, SI units
(m, s, m/s, rad), x and y horizontal and z up.
"""
from __future__ import annotations

import math
from functools import cached_property
from typing import Annotated, Any

import numpy as np
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, PlainSerializer, StrictBool, model_validator

#: Margin (m) added around a static obstacle when L_pz or h_pz is not given (section 4).
PZ_MARGIN = 2.0


def check_vector(value: Any, n: int) -> np.ndarray:
    """``value`` as a read-only float array of shape (n,); ValueError if it is not n finite
    numbers."""
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"must be {n} numbers") from exc
    if arr.shape != (n,):
        raise ValueError(f"must be {n} numbers, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError("must be finite (no NaN or inf)")
    arr.setflags(write=False)
    return arr


def _vector(n: int):
    return lambda value: check_vector(value, n)


Vec2 = Annotated[np.ndarray, BeforeValidator(_vector(2)), PlainSerializer(lambda a: a.tolist())]
Vec3 = Annotated[np.ndarray, BeforeValidator(_vector(3)), PlainSerializer(lambda a: a.tolist())]
Finite = Annotated[float, Field(allow_inf_nan=False)]
Positive = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNegative = Annotated[float, Field(ge=0, allow_inf_nan=False)]


class _Model(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid", arbitrary_types_allowed=True)


class AgentState(_Model):
    """The avoiding vehicle A: position p_A (m) and current velocity V_A (m/s)."""

    position: Vec3
    velocity: Vec3 = Field(default_factory=lambda: np.zeros(3))


class Neighbor(_Model):
    """A moving obstacle B seen by A: position p_B, velocity V_B, protected-zone radius r_pz."""

    position: Vec3
    velocity: Vec3 = Field(default_factory=lambda: np.zeros(3))
    r_pz: Positive
    #: Whether B avoids A too (another vehicle running a selector). With the ``reciprocal``
    #: option A takes only half the avoidance of a cooperative neighbour, and all of it for one
    #: that keeps its velocity whatever A does (a hovering vehicle, a static sphere).
    cooperative: StrictBool = True

    @property
    def row(self) -> tuple[float, ...]:
        """(x, y, z, v_x, v_y, v_z, r_pz, cooperative): what the VO needs, as plain floats."""
        return (*self.position.tolist(), *self.velocity.tolist(), self.r_pz, float(self.cooperative))


class _StaticObstacle(_Model):
    """Shared fields of obstacles standing on the ground (z = 0)."""

    center: Vec2
    height: Positive
    L_pz: Positive | None = None  # side of the square protected prism C_pz (section 4)
    h_pz: Positive | None = None  # height of C_pz
    margin: NonNegative = PZ_MARGIN  # used only to derive L_pz / h_pz when omitted

    def footprint_extent(self) -> float:  # pragma: no cover - overridden
        raise NotImplementedError

    @property
    def side(self) -> float:
        """L_pz: given, or the footprint's largest extent plus a margin on each side."""
        return self.L_pz if self.L_pz is not None else self.footprint_extent() + 2.0 * self.margin

    @property
    def prism_height(self) -> float:
        """h_pz: given, or the obstacle height plus the margin."""
        return self.h_pz if self.h_pz is not None else self.height + self.margin

    def model_copy(self, *, update: dict[str, Any] | None = None, deep: bool = False):
        """pydantic's copy, without the cached ``prism`` when fields change."""
        copy = super().model_copy(update=update, deep=deep)
        if update:
            copy.__dict__.pop("prism", None)
        return copy

    @cached_property
    def prism(self) -> tuple[float, float, float, float]:
        """(x, y, L_pz, h_pz) of the protected prism C_pz, as plain floats (cached: static
        obstacles are usually the same objects from one control step to the next)."""
        return (*self.center.tolist(), float(self.side), float(self.prism_height))

    @model_validator(mode="after")
    def _prism_covers_obstacle(self):
        # Section 4: h_pz must exceed the obstacle height and L_pz its largest length.
        if self.h_pz is not None and self.h_pz < self.height:
            raise ValueError("h_pz must be at least the obstacle height")
        if self.L_pz is not None and self.L_pz < self.footprint_extent():
            raise ValueError("L_pz must be at least the obstacle's largest horizontal extent")
        return self


class Cylinder(_StaticObstacle):
    """A vertical cylinder on the ground: centre (x, y), radius, height."""

    radius: Positive

    def footprint_extent(self) -> float:
        return 2.0 * self.radius  # a square of side 2r contains the disc in any orientation

    def surface_distance(self, points: np.ndarray) -> np.ndarray:
        """Distance (m) from points (..., 3) to the cylinder's surface (0 inside)."""
        p = np.asarray(points, dtype=float)
        radial = np.maximum(np.linalg.norm(p[..., :2] - self.center, axis=-1) - self.radius, 0.0)
        vertical = np.maximum(p[..., 2] - self.height, 0.0) + np.maximum(-p[..., 2], 0.0)
        return np.hypot(radial, vertical)


class Box(_StaticObstacle):
    """A box on the ground: centre (x, y), size (lx, ly) before the yaw, height, yaw (rad)."""

    size: Vec2
    yaw: Finite = 0.0

    @model_validator(mode="after")
    def _positive_size(self):
        if np.any(self.size <= 0):
            raise ValueError("size: both sides must be positive")
        return self

    def footprint_extent(self) -> float:
        return float(math.hypot(*self.size))  # the diagonal: any orientation of C_pz covers it

    def surface_distance(self, points: np.ndarray) -> np.ndarray:
        """Distance (m) from points (..., 3) to the box's surface (0 inside)."""
        p = np.asarray(points, dtype=float)
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        d = p[..., :2] - self.center
        local = np.stack([c * d[..., 0] + s * d[..., 1], -s * d[..., 0] + c * d[..., 1]], axis=-1)
        out = np.maximum(np.abs(local) - self.size / 2.0, 0.0)
        vertical = np.maximum(p[..., 2] - self.height, 0.0) + np.maximum(-p[..., 2], 0.0)
        return np.sqrt(np.sum(out**2, axis=-1) + vertical**2)


Obstacle = Cylinder | Box


class Limits(_Model):
    """Speed range (m/s), altitude range (m) and an optional per-axis acceleration limit (m/s²)."""

    speed: tuple[NonNegative, Positive] = (0.0, 4.0)
    altitude: tuple[Finite, Finite] = (0.0, 40.0)
    acceleration: Positive | None = None

    @model_validator(mode="after")
    def _ranges(self):
        if self.speed[0] > self.speed[1]:
            raise ValueError("speed: empty range (v_min > v_max)")
        if self.altitude[0] >= self.altitude[1]:
            raise ValueError("altitude: empty range (z_min >= z_max)")
        return self

    @property
    def v_min(self) -> float:
        return self.speed[0]

    @property
    def v_max(self) -> float:
        return self.speed[1]

    @property
    def z_min(self) -> float:
        return self.altitude[0]

    @property
    def z_max(self) -> float:
        return self.altitude[1]
