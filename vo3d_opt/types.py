"""Public data types of the API, validated with pydantic.

Malformed input raises :class:`InputError` (a ``ValueError``) with a one-line message naming
each bad field: ``Cylinder: radius: must be a number, got '3'``. Numbers are numbers: booleans
and strings are rejected wherever a number is expected (``True`` is not 1 m, ``"3"`` is not 3);
numpy scalars and arrays are accepted. Vectors are stored as read-only numpy arrays, world
frame, SI units (m, s, m/s, rad), x and y horizontal and z up.

The same field types and checks validate scenario files (``vo3d_opt.sim.scenario``), which
embed these models; there, pydantic's structured errors (with the key path) are kept, and
cross-field problems are located at the field they concern (:func:`raise_problems`).
"""

from __future__ import annotations

import math
import numbers
import reprlib
from collections.abc import Container, Iterable, Mapping
from functools import cached_property
from typing import Annotated, Any

import numpy as np
from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    PlainSerializer,
    PlainValidator,
    StrictBool,
    ValidationError,
    field_validator,
    model_validator,
)
from pydantic_core import PydanticCustomError

#: Margin (m) added around a static obstacle when L_pz or h_pz is not given (section 4).
PZ_MARGIN = 2.0
#: Every number of the inputs is at most this in magnitude (SI units: 10,000 km, 10,000 km/s,
#: 115 days): beyond it the geometry's squares and products lose every digit that matters.
MAX_MAGNITUDE = 1e7

# ------------------------------------------------------------------------------------ errors


class InputError(ValueError):
    """Malformed input to a public type. The message is one line, ``Type: field: problem``
    (problems joined by ``; ``); ``problems`` holds the (field path, problem) pairs."""

    def __init__(self, message: str, problems: list[tuple[str, str]]) -> None:
        super().__init__(message)
        self.problems = problems

    @classmethod
    def from_validation(cls, title: str, exc: ValidationError) -> InputError:
        problems = [describe_error(err) for err in exc.errors()]
        text = "; ".join(f"{path}: {msg}" if path else msg for path, msg in problems)
        return cls(one_line(f"{title}: {text}"), problems)


def one_line(text: Any) -> str:
    """``text`` with every run of whitespace (newlines included) turned into one space."""
    return " ".join(str(text).split())


_SHORT = reprlib.Repr()
_SHORT.maxlevel, _SHORT.maxlist, _SHORT.maxtuple, _SHORT.maxdict = 2, 4, 4, 4
_SHORT.maxstring, _SHORT.maxother, _SHORT.maxlong = 40, 40, 40


def short_repr(value: Any, limit: int = 40) -> str:
    """``repr(value)``, cut to ``limit`` characters, never built whole: a nested value (a YAML
    alias bomb, a huge array) is walked only a few items and levels deep."""
    text = _SHORT.repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def field_path(loc: Iterable[Any], skip: Container[Any] = ()) -> str:
    """pydantic's error location as ``key.path[2].key``; parts in ``skip`` (the tags of a
    discriminated union, which are no keys of the input) are left out."""
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        elif part not in skip:
            out += ("." if out else "") + str(part)
    return out


def describe_error(err: Any, skip: Container[Any] = ()) -> tuple[str, str]:
    """(field path, one-line problem) of one of pydantic's ``ValidationError.errors()``."""
    path = field_path(err.get("loc", ()), skip)
    kind = str(err.get("type", ""))
    if kind == "missing":
        return path, "missing required field"
    if kind == "extra_forbidden":
        return path, "unknown field"
    msg = str(err.get("msg", "invalid")).removeprefix("Value error, ")
    msg = msg[:1].lower() + msg[1:]
    if kind.endswith("_type") or kind.endswith("_parsing"):
        msg += f", got {short_repr(err.get('input'))}"
    return path, one_line(msg)


def raise_problems(title: str, problems: list[tuple[tuple[Any, ...], str, Any]]) -> None:
    """Raise, from inside a validator, every (location, problem, value) at its own location;
    pydantic prefixes the location of the model being validated. Nothing when empty."""
    if problems:
        raise ValidationError.from_exception_data(
            title,
            [
                {
                    "type": PydanticCustomError("value_error", "{problem}", {"problem": msg}),
                    "loc": loc,
                    "input": value,
                }
                for loc, msg, value in problems
            ],
        )


# ------------------------------------------------------------------------------------ fields


def _is_real(x: Any) -> bool:
    if type(x) is float or type(x) is int:  # the common case, without the ABC check
        return True
    return isinstance(x, numbers.Real) and not isinstance(x, (bool, np.bool_))


def check_number(value: Any) -> Any:
    """``value`` if pydantic may read it as a number: booleans and strings are refused (a YAML
    ``yes`` or a quoted ``"3"`` is a mistake, not a number), so are NaN and infinities; numpy
    scalars become Python ones."""
    if isinstance(value, (bool, np.bool_, str, bytes)):
        raise ValueError(f"must be a number, got {short_repr(value)}")
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, complex):
        raise ValueError(f"must be a real number, got {short_repr(value)}")
    if isinstance(value, (int, float)):
        try:
            x = float(value)
        except OverflowError:  # an int beyond a float's range
            raise ValueError(f"must be at most {MAX_MAGNITUDE:g} in magnitude") from None
        if not math.isfinite(x):
            raise ValueError(f"must be finite (no NaN or inf), got {value}")
        if abs(x) > MAX_MAGNITUDE:
            raise ValueError(f"must be at most {MAX_MAGNITUDE:g} in magnitude, got {x:g}")
    return value


def positive_seconds(value: Any, name: str) -> float:
    """``value`` as a positive number of seconds (at most ``MAX_MAGNITUDE``); ``ValueError``
    naming ``name`` otherwise."""
    try:
        seconds = float(check_number(value)) if _is_real(value) else math.nan
    except ValueError as exc:
        raise ValueError(f"{name}: {exc}") from None
    if math.isnan(seconds):
        raise ValueError(f"{name}: must be a number, got {short_repr(value)}")
    if not seconds > 0:
        raise ValueError(f"{name}: must be a positive number of seconds, got {short_repr(value)}")
    return seconds


def check_vector(value: Any, n: int) -> np.ndarray:
    """``value`` as a read-only, contiguous float array of shape (n,); ValueError if it is not
    n finite numbers (booleans and strings are not numbers). Read-only, contiguous, aligned float
    arrays of the right shape come back as they are (every public type stores its vectors so: the
    compiled kernels take them without a copy or a new compilation)."""
    if isinstance(value, (list, tuple)):
        if len(value) != n:
            raise ValueError(f"must be {n} numbers, got {len(value)}")
        if not all(_is_real(x) for x in value):
            raise ValueError(f"must be {n} numbers, got {short_repr(value)}")
        try:
            arr = np.array(value, dtype=float)
        except OverflowError:  # an int beyond a float's range
            raise ValueError(f"must be at most {MAX_MAGNITUDE:g} in magnitude") from None
    else:
        raw = np.asarray(value)
        if raw.dtype.kind not in "iuf":
            raise ValueError(f"must be {n} numbers, got {short_repr(value)}")
        if raw.shape != (n,):
            raise ValueError(f"must be {n} numbers, got shape {raw.shape}")
        if (
            raw.dtype == np.float64
            and not raw.flags.writeable
            and raw.flags.c_contiguous
            and raw.flags.aligned  # the compiled kernels assume aligned arrays
            and all(math.isfinite(x) and abs(x) <= MAX_MAGNITUDE for x in raw.tolist())
        ):
            return raw
        arr = raw.astype(float)  # a copy: the caller's array stays theirs
    if not all(math.isfinite(x) for x in arr.tolist()):
        raise ValueError("must be finite (no NaN or inf)")
    if not all(abs(x) <= MAX_MAGNITUDE for x in arr.tolist()):
        raise ValueError(f"must be at most {MAX_MAGNITUDE:g} in magnitude")
    arr.setflags(write=False)
    return arr


def _range(value: Any) -> tuple[float, float]:
    lo, hi = check_vector(value, 2).tolist()
    return lo, hi


def _vector(n: int):  # noqa: ANN202 - a validator
    return lambda value: check_vector(value, n)


def _to_list(a: np.ndarray) -> list[float]:
    return a.tolist()


Vec2 = Annotated[np.ndarray, BeforeValidator(_vector(2)), PlainSerializer(_to_list)]
Vec3 = Annotated[np.ndarray, BeforeValidator(_vector(3)), PlainSerializer(_to_list)]
#: (low, high): two finite numbers; the model checks their order.
Range = Annotated[tuple[float, float], PlainValidator(_range)]
Finite = Annotated[float, BeforeValidator(check_number), Field(allow_inf_nan=False)]
Positive = Annotated[float, BeforeValidator(check_number), Field(gt=0, allow_inf_nan=False)]
NonNegative = Annotated[float, BeforeValidator(check_number), Field(ge=0, allow_inf_nan=False)]


class Model(BaseModel):
    """Base of the public types (and of the scenario specs): frozen, unknown fields refused,
    one-line :class:`InputError` when built directly (``model_validate`` keeps pydantic's
    structured ``ValidationError``, which the scenario loader formats itself)."""

    model_config = ConfigDict(frozen=True, extra="forbid", arbitrary_types_allowed=True)

    def __init__(self, /, **data: Any) -> None:
        try:
            super().__init__(**data)
        except ValidationError as exc:
            raise InputError.from_validation(type(self).__name__, exc) from None

    # Tells pydantic that nested validation need not call this __init__ (it only reformats
    # errors), so a model inside another one reports its errors with their locations.
    __init__.__pydantic_base_init__ = True  # type: ignore[attr-defined]

    def model_copy(self, *, update: Mapping[str, Any] | None = None, deep: bool = False) -> Any:
        """pydantic's copy, without the values cached from the fields (each ``cached_property``)
        when fields change: the copy computes its own."""
        copy = super().model_copy(update=update, deep=deep)
        if update:
            for klass in type(self).__mro__:
                for name, attr in vars(klass).items():
                    if isinstance(attr, cached_property):
                        copy.__dict__.pop(name, None)
        return copy


# ------------------------------------------------------------------------------------ models


class AgentState(Model):
    """The avoiding vehicle A: position p_A (m) and current velocity V_A (m/s)."""

    position: Vec3
    velocity: Vec3 = Field(default_factory=lambda: np.zeros(3))


class Neighbor(Model):
    """A moving obstacle B seen by A: position p_B, velocity V_B, protected-zone radius r_pz."""

    position: Vec3
    velocity: Vec3 = Field(default_factory=lambda: np.zeros(3))
    r_pz: Positive
    #: Whether B avoids A too (another vehicle running a selector). With the ``reciprocal``
    #: option A takes only half the avoidance of a cooperative neighbour, and all of it for one
    #: that keeps its velocity whatever A does (a hovering vehicle, a static sphere). With a
    #: buffer (``pz_buffer``), in the inner half of a cooperative neighbour's buffer the VO's
    #: apex moves away from it, reciprocal or not; one that does not avoid is only kept off.
    cooperative: StrictBool = True

    @cached_property
    def row(self) -> tuple[float, ...]:
        """(x, y, z, v_x, v_y, v_z, r_pz, cooperative): what the VO needs, as plain floats
        (cached: the model is frozen, and a neighbour is often reused over many calls)."""
        return (
            *self.position.tolist(),
            *self.velocity.tolist(),
            self.r_pz,
            float(self.cooperative),
        )


class _StaticObstacle(Model):
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

    @cached_property
    def prism(self) -> tuple[float, float, float, float, float, float]:
        """(x, y, L_pz, h_pz) of the protected prism C_pz and the obstacle's height and rim
        (``footprint_extent() / 2``), as plain floats: a vehicle inside C_pz and over the roof
        must not sink, whichever margin is nearer. Cached: static obstacles are usually the same
        objects from one control step to the next."""
        x, y = self.center.tolist()
        return (
            x,
            y,
            float(self.side),
            float(self.prism_height),
            float(self.height),
            0.5 * self.footprint_extent(),
        )

    @model_validator(mode="after")
    def _prism_covers_obstacle(self) -> _StaticObstacle:
        # Section 4: h_pz must exceed the obstacle height and L_pz its largest length.
        problems = []
        if self.h_pz is not None and self.h_pz < self.height:
            problems.append(
                (
                    ("h_pz",),
                    f"{self.h_pz:g} is below the obstacle height "
                    f"{self.height:g} (section 4: h_pz > height)",
                    self.h_pz,
                )
            )
        extent = self.footprint_extent()
        if self.L_pz is not None and self.L_pz < extent:
            problems.append(
                (
                    ("L_pz",),
                    f"{self.L_pz:g} is below the obstacle's largest extent "
                    f"{extent:.3g} (section 4)",
                    self.L_pz,
                )
            )
        raise_problems(type(self).__name__, problems)
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

    @field_validator("size")
    @classmethod
    def _positive_size(cls, size: np.ndarray) -> np.ndarray:
        if np.any(size <= 0):
            raise ValueError("both sides must be positive")
        return size

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


class Limits(Model):
    """Speed range (m/s), altitude range (m) and an optional per-axis acceleration limit (m/s²)."""

    speed: Range = (0.0, 4.0)
    altitude: Range = (0.0, 40.0)
    acceleration: Positive | None = None

    @field_validator("speed")
    @classmethod
    def _speed_range(cls, speed: tuple[float, float]) -> tuple[float, float]:
        lo, hi = speed
        if lo < 0:
            raise ValueError(f"minimum speed {lo:g} is negative")
        if hi <= 0:
            raise ValueError(f"maximum speed {hi:g} must be positive")
        if lo > hi:
            raise ValueError(f"empty range [{lo:g}, {hi:g}] (v_min > v_max)")
        return speed

    @field_validator("altitude")
    @classmethod
    def _altitude_range(cls, altitude: tuple[float, float]) -> tuple[float, float]:
        if altitude[0] >= altitude[1]:
            raise ValueError(f"empty range [{altitude[0]:g}, {altitude[1]:g}] (z_min >= z_max)")
        return altitude

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
