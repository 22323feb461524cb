"""The compiler for the per-step loops: numba's ``njit``, cached on disk.

The geometry of one decision is a few hundred tiny numbers; in numpy every step costs a call of a
few microseconds, so the per-decision work is written as plain loops (the paper's formulas one
cone, plane and generator at a time) and compiled. ``error_model="numpy"`` keeps numpy's float
semantics (x / 0 is inf or NaN, never an exception), which the formulas rely on.

Four flavours, by what a function does:

- ``entry``: called from Python (it gets a Python wrapper);
- ``jit``: called only from compiled code and allocates arrays (no Python wrapper, which saves
  compile time, most of all for functions taking NamedTuples of arrays);
- ``kernel``: called only from compiled code, allocates nothing and returns no array: compiled
  without numba's reference counting (``_nrt=False``), whose atomic counter updates on every
  array passed or sliced otherwise cost more than the arithmetic of these small loops;
- ``inline``: inlined by numba where it is called (and compiled with that caller's flags):
  the small helpers of hot loops, whose arithmetic costs less than a call, the per-section code
  into ``plane_rows``, and ``decide_one`` into its two callers. Inlining is costly to compile
  (nested inlining most), so the large kernels are called, not inlined.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol, TypeVar

import numba

_F = TypeVar("_F", bound=Callable[..., Any])


class _Compiler(Protocol):
    """A decorator that compiles a function; mypy checks its calls against the Python
    signature (numba dispatches on the same arguments)."""

    def __call__(self, fn: _F, /) -> _F: ...


def _compiler(**options: Any) -> _Compiler:
    # Options as **Any: numba's stubs omit those it takes through **options (no_cpython_wrapper,
    # _nrt); typed as _Compiler, not numba's Dispatcher, so that calls are checked.
    return numba.njit(**options)


_COMMON: dict[str, Any] = dict(cache=True, error_model="numpy", nogil=True)

entry = _compiler(**_COMMON)
jit = _compiler(**_COMMON, no_cpython_wrapper=True)
kernel = _compiler(**_COMMON, no_cpython_wrapper=True, _nrt=False)
inline = _compiler(**_COMMON, no_cpython_wrapper=True, _nrt=False, inline="always")
