"""``select_many``'s arguments checked: each a ``ValueError`` naming the argument when it is
malformed, by ``select``'s rules (real numbers only, finite, at most ``MAX_MAGNITUDE``)."""

from __future__ import annotations

import math
import numbers
from typing import Any

import numpy as np

from ..formulations.common import bounds_array
from ..types import MAX_MAGNITUDE, Box, Cylinder, Limits, short_repr


def _real(value: Any) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def _array(value: Any, name: str, shape: tuple[int, ...]) -> np.ndarray:
    """A finite float array of exactly ``shape`` (C-contiguous, a copy), or ValueError: real
    numbers only (as ``select`` takes them: no booleans, strings or complex numbers), each at
    most ``MAX_MAGNITUDE``."""
    try:
        raw = np.asarray(value)
    except (TypeError, ValueError, OverflowError):
        raw = np.asarray(None)
    if raw.dtype.kind not in "iuf":
        if raw.dtype.kind == "O" and raw.size and all(_real(x) for x in raw.ravel().tolist()):
            raw = _objects_as_floats(raw, name)
        else:
            raise ValueError(
                f"{name}: expected real numbers of shape {shape}, got {_kind_of(value, raw)}"
            )
    if raw.shape != shape:
        raise ValueError(f"{name}: expected shape {shape}, got {raw.shape}")
    arr = np.array(raw, dtype=float)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: must be finite (no NaN or inf)")
    if np.any(np.abs(arr) > MAX_MAGNITUDE):
        raise ValueError(f"{name}: must be at most {MAX_MAGNITUDE:g} in magnitude")
    return np.ascontiguousarray(arr)


def _objects_as_floats(raw: np.ndarray, name: str) -> np.ndarray:
    """An object array of Python numbers (ints beyond int64 among them) as floats."""
    try:
        return raw.astype(float)
    except OverflowError:
        raise ValueError(f"{name}: must be at most {MAX_MAGNITUDE:g} in magnitude") from None


def _kind_of(value: Any, raw: np.ndarray) -> str:
    kinds = {"b": "booleans", "c": "complex numbers", "U": "text", "S": "bytes", "O": "objects"}
    return kinds.get(raw.dtype.kind, type(value).__name__)


def points(value: Any, name: str, n: int | None = None) -> np.ndarray:
    """(n, 3) finite floats; ``n`` None: any number of rows."""
    if n is None:
        shape = np.shape(value)
        if len(shape) != 2 or shape[1] != 3:
            raise ValueError(f"{name}: expected shape (N, 3), got {shape}")
        n = shape[0]
    return _array(value, name, (n, 3))


def radii(value: Any, name: str, n: int) -> np.ndarray:
    """(n,) positive finite floats from one number or n of them."""
    if _real(value):
        value = np.full(n, float(value))
    arr = _array(value, name, (n,))
    if np.any(arr <= 0):
        raise ValueError(f"{name}: must be positive")
    return arr


def mask(value: Any, name: str, n: int) -> np.ndarray:
    """(n,) bool from None (all true) or n booleans (or 0/1)."""
    if value is None:
        return np.ones(n, dtype=bool)
    arr = np.asarray(value)
    if arr.shape != (n,):
        raise ValueError(f"{name}: expected shape ({n},), got {arr.shape}")
    if arr.dtype != bool:
        if not (np.issubdtype(arr.dtype, np.number) and np.all((arr == 0) | (arr == 1))):
            raise ValueError(f"{name}: expected booleans (or 0/1)")
        arr = arr != 0
    return arr.copy()


def distance(value: Any, name: str, *, allow_inf: bool = False) -> float:
    """A positive distance in m (inf allowed when ``allow_inf``; a finite one at most
    ``MAX_MAGNITUDE``)."""
    try:
        metres = float(value) if _real(value) else math.nan
    except OverflowError:  # an int beyond a float's range: as far as any
        metres = math.inf
    if math.isinf(metres) and allow_inf and metres > 0:
        return metres
    if not (math.isfinite(metres) and 0 < metres <= MAX_MAGNITUDE):
        what = "positive" if allow_inf else "positive finite"
        raise ValueError(
            f"{name}: must be a {what} number of metres (at most {MAX_MAGNITUDE:g} when "
            f"finite), got {short_repr(value)}"
        )
    return metres


#: A count beyond this is as good as "all" (no swarm has more vehicles).
COUNT_MAX = 10**9


def count(value: Any, name: str) -> int | None:
    """None or an integer >= 0 (beyond ``COUNT_MAX``: ``COUNT_MAX``, which means all)."""
    if value is None:
        return None
    if not isinstance(value, numbers.Integral) or isinstance(value, (bool, np.bool_)) or value < 0:
        raise ValueError(f"{name}: must be None or an integer >= 0, got {short_repr(value)}")
    return min(int(value), COUNT_MAX)


def vehicle_limits(limits: Limits, dt: float, n: int, max_speed: Any) -> np.ndarray:
    """(n, 6) ``bounds_array`` rows; the ``max_speed`` extension (one number or (n,), m/s) caps
    each vehicle's v_max (a scenario's per-agent ``max_speed``)."""
    rows = np.tile(bounds_array(limits, dt), (n, 1))
    if max_speed is not None:
        cap = radii(max_speed, "max_speed", n)
        if np.any(cap < limits.v_min):
            raise ValueError(f"max_speed: below the minimum speed {limits.v_min:g}")
        rows[:, 1] = np.minimum(rows[:, 1], cap)
    return rows


def sphere_rows(value: Any) -> np.ndarray:
    """The ``spheres`` extension: (S, 5) x, y, z, radius, r_pz (radius >= 0, r_pz > 0)."""
    if value is None:
        return np.zeros((0, 5))
    shape = np.shape(value)
    if len(shape) != 2 or shape[1] != 5:
        raise ValueError(f"spheres: expected shape (S, 5) (x, y, z, radius, r_pz), got {shape}")
    arr = _array(value, "spheres", shape)
    if np.any(arr[:, 3] < 0) or np.any(arr[:, 4] <= 0):
        raise ValueError("spheres: radius must be >= 0 and r_pz positive")
    return arr


def obstacle_list(value: Any) -> list[Cylinder | Box]:
    items = [] if value is None else list(value)
    for i, item in enumerate(items):
        if not isinstance(item, (Cylinder, Box)):
            raise ValueError(f"obstacles[{i}]: expected Cylinder or Box, got {type(item).__name__}")
    return items
