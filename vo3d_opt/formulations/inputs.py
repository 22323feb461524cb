"""One decision's inputs checked, in the forms the compiled core reads.

``select`` takes the public types. They are validated when they are built, so a decision only
checks that each input is of its type, and hands over the rows each keeps (``Neighbor.row``,
an obstacle's ``prism``) as the Python tuples they are: the core reads them without a numpy
array in between (``kernel.decide_rows``). ``select_arrays`` takes numpy arrays instead, checked
here with numpy, once per call. A malformed input is a ``ValueError`` naming the argument (for
an array, the entry and its column).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

import vo3d_opt._core as _core

from ..geometry.pyramid import prism_rows
from ..types import (
    MAX_MAGNITUDE,
    AgentState,
    Box,
    Cylinder,
    Limits,
    Neighbor,
    check_vector,
    positive_seconds,
)

#: The limits of a decision given none (frozen: one object serves every such decision).
DEFAULT_LIMITS = Limits()
#: The columns of ``select_arrays``' neighbour array: ``Neighbor``'s fields but ``cooperative``,
#: which is an array of its own.
NEIGHBOR_COLUMNS = ("px", "py", "pz", "vx", "vy", "vz", "r_pz")
#: The columns of ``select_arrays``' obstacle array: each obstacle's prism row
#: (``Cylinder.prism``); the first four alone (no roof) are accepted too.
PRISM_COLUMNS = ("x", "y", "L_pz", "h_pz", "height", "rim")

Vector3 = tuple[float, float, float] | np.ndarray
Row = tuple[float, ...]


def _finite_numbers(values: Sequence[Any]) -> bool:
    """Whether every value is a float or an int within ``MAX_MAGNITUDE`` (NaN and infinities
    fail the comparison; booleans are of neither type)."""
    for x in values:
        t = type(x)
        if not ((t is float or t is int) and -MAX_MAGNITUDE <= x <= MAX_MAGNITUDE):
            return False
    return True


def vector3(value: Any, name: str) -> Vector3:
    """Three finite numbers: a tuple of them as it is (or a list's or a float array's as a
    tuple); anything else through ``check_vector``, whose message is prefixed with ``name``."""
    kind = type(value)
    if (kind is tuple or kind is list) and len(value) == 3 and _finite_numbers(value):
        return tuple(value)
    if kind is np.ndarray and value.shape == (3,) and value.dtype == np.float64:
        items = value.tolist()
        if _finite_numbers(items):
            return tuple(items)
    try:
        return check_vector(value, 3)
    except ValueError as exc:
        raise ValueError(f"{name}: {exc}") from None


def agent(own: Any) -> AgentState:
    if not isinstance(own, AgentState):
        raise ValueError(f"own: expected AgentState, got {type(own).__name__}")
    return own


def _listed(value: Any) -> Sequence[Any]:
    kind = type(value)
    return value if kind is list or kind is tuple else ([] if value is None else list(value))


def _typed(items: Sequence[Any], kinds: tuple[type, ...], name: str) -> None:
    """ValueError naming the first item not of one of ``kinds``."""
    for i, item in enumerate(items):
        if not isinstance(item, kinds):
            expected = " or ".join(k.__name__ for k in kinds)
            raise ValueError(f"{name}[{i}]: expected {expected}, got {type(item).__name__}")


def neighbor_tuples(neighbors: Any) -> list[Row]:
    """Each ``Neighbor``'s row (position, velocity, r_pz, cooperative 1/0)."""
    items = _listed(neighbors)
    rows = [nb.row for nb in items if type(nb) is Neighbor]
    if len(rows) != len(items):  # a subclass, or something else: ValueError naming it
        _typed(items, (Neighbor,), "neighbors")
        rows = [nb.row for nb in items]
    return rows


def prism_tuples(obstacles: Any) -> list[Row]:
    """Each obstacle's prism row (``Cylinder.prism``)."""
    items = _listed(obstacles)
    rows: list[Row] = [o.prism for o in items if type(o) is Cylinder or type(o) is Box]
    if len(rows) != len(items):
        _typed(items, (Cylinder, Box), "obstacles")
        rows = [o.prism for o in items]
    return rows


def limits_of(limits: Any) -> Limits:
    if limits is None:
        return DEFAULT_LIMITS
    if not isinstance(limits, Limits):
        raise ValueError(f"limits: expected Limits, got {type(limits).__name__}")
    return limits


def period(dt: Any) -> float:
    """The control period dt (s), a positive number."""
    if type(dt) is float and 0.0 < dt <= MAX_MAGNITUDE:
        return dt
    return positive_seconds(dt, "dt")


def bounds_row(limits: Limits, dt: float) -> Row:
    """``Bounds``' fields as one tuple: v_min, v_max, z_min, z_max, acceleration (NaN: none),
    dt."""
    acc = math.nan if limits.acceleration is None else limits.acceleration
    return (*limits.speed, *limits.altitude, acc, dt)


# ------------------------------------------------------------------------------- arrays


def _table(value: Any, name: str, columns: Sequence[str], positive_from: int) -> np.ndarray:
    """``value`` as an (N, len(columns)) float array (a float array as it is): real numbers,
    finite, within ``MAX_MAGNITUDE``, positive in the columns from ``positive_from`` on
    (checked compiled, in one pass); ValueError naming the first bad entry and its column."""
    raw = value if type(value) is np.ndarray else np.asarray(value)
    width = len(columns)
    if raw.shape in ((0,), (0, width)):
        return np.zeros((0, width))  # none (an empty list too)
    shape = f"(N, {width}) ({', '.join(columns)})"
    if raw.dtype.kind not in "iuf":
        raise ValueError(f"{name}: expected real numbers of shape {shape}, got {raw.dtype}")
    if raw.ndim != 2 or raw.shape[1] != width:
        raise ValueError(f"{name}: expected shape {shape}, got {raw.shape}")
    arr = raw if raw.dtype == np.float64 else raw.astype(float)
    bad = _core.first_bad(arr, MAX_MAGNITUDE, positive_from)
    if bad >= 0:
        i, j = divmod(bad, width)
        x = arr[i, j]
        problem = (
            "must be positive"
            if abs(x) <= MAX_MAGNITUDE
            else f"must be finite and at most {MAX_MAGNITUDE:g} in magnitude"
        )
        raise ValueError(f"{name}[{i}, {j}] ({columns[j]}): {problem}, got {x}")
    return arr


def array_vector(value: Any, name: str) -> np.ndarray:
    """(3,) finite floats: a float array as it is."""
    if type(value) is np.ndarray and value.shape == (3,) and value.dtype == np.float64:
        if _finite_numbers(value.tolist()):
            return value
    else:
        raw = np.asarray(value)
        if raw.dtype.kind not in "iuf":
            raise ValueError(f"{name}: expected real numbers of shape (3,), got {raw.dtype}")
        if raw.shape != (3,):
            raise ValueError(f"{name}: expected shape (3,), got {raw.shape}")
        value = raw.astype(float)
        if _finite_numbers(value.tolist()):
            return value
    k = next(k for k, x in enumerate(value.tolist()) if not _finite_numbers((x,)))
    raise ValueError(
        f"{name}[{k}]: must be finite and at most {MAX_MAGNITUDE:g} in magnitude, got {value[k]}"
    )


def neighbor_array(neighbors: Any, cooperative: Any) -> np.ndarray:
    """(N, 8) rows as ``Neighbor.row``: ``neighbors`` (N, 7) (``NEIGHBOR_COLUMNS``; r_pz
    positive) and ``cooperative`` (N,) booleans (None: all cooperative)."""
    if neighbors is None:
        neighbors = np.zeros((0, len(NEIGHBOR_COLUMNS)))
    arr = _table(neighbors, "neighbors", NEIGHBOR_COLUMNS, 6)
    n = arr.shape[0]
    rows = np.empty((n, 8))
    rows[:, :7] = arr
    rows[:, 7] = 1.0 if cooperative is None else _flags(cooperative, n)
    return rows


def _flags(value: Any, n: int) -> np.ndarray:
    raw = value if type(value) is np.ndarray else np.asarray(value)
    if raw.shape != (n,):
        raise ValueError(f"cooperative: expected shape ({n},) (one per neighbour), got {raw.shape}")
    if raw.dtype != bool and not (raw.dtype.kind in "iu" and np.all((raw == 0) | (raw == 1))):
        raise ValueError(f"cooperative: expected booleans (or 0/1), got {raw.dtype}")
    return raw


def prism_array(obstacles: Any) -> np.ndarray:
    """(M, 6) or (M, 4) prism rows: an array of ``PRISM_COLUMNS`` or of their first four (all
    but x and y positive), or Cylinder and Box objects."""
    if obstacles is None:
        return np.zeros((0, len(PRISM_COLUMNS)))
    if isinstance(obstacles, (list, tuple)) and all(
        isinstance(o, (Cylinder, Box)) for o in obstacles
    ):
        return prism_rows(obstacles)
    expected = f"expected shape (N, 6) ({', '.join(PRISM_COLUMNS)}) or (N, 4) (no roof)"
    try:  # converted once: _table takes an array as it is
        raw = obstacles if type(obstacles) is np.ndarray else np.asarray(obstacles)
    except ValueError:  # a ragged sequence
        raise ValueError(f"obstacles: {expected}, got rows of different lengths") from None
    width = raw.shape[1] if raw.ndim == 2 else None
    if width == 4:
        return _table(raw, "obstacles", PRISM_COLUMNS[:4], 2)
    if raw.shape != (0,) and width != len(PRISM_COLUMNS):
        raise ValueError(f"obstacles: {expected}, got {raw.shape}")
    return _table(raw, "obstacles", PRISM_COLUMNS, 2)
