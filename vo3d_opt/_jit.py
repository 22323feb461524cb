"""The compiler for the per-step loops: numba's ``njit``, cached on disk.

The geometry of one decision is a few hundred tiny numbers; in numpy every step costs a call of a
few microseconds, so the per-decision work is written as plain loops (the paper's formulas one
cone, plane and generator at a time) and compiled. ``error_model="numpy"`` keeps numpy's float
semantics (x / 0 is inf or NaN, never an exception), which the formulas rely on.

Five flavours, by what a function does:

- ``entry``: called from Python (it gets a Python wrapper);
- ``jit``: called only from compiled code and allocates arrays (no Python wrapper, which saves
  compile time, most of all for functions taking NamedTuples of arrays);
- ``kernel``: called only from compiled code, allocates nothing and returns no array: compiled
  without numba's reference counting (``_nrt=False``), whose atomic counter updates on every
  array passed or sliced otherwise cost more than the arithmetic of these small loops;
- ``inline``: a ``kernel`` that LLVM always inlines where it is called (``forceinline``: the
  ``alwaysinline`` attribute): the helpers of hot loops, whose arithmetic costs less than a
  call, and the functions whose call would pass every array of the VOs or of the plane QPs by
  value (tens of arrays, each several machine words): the fallbacks' per-point checks (inlined,
  a fallback decision of the sphere swap took about a quarter of its time before),
  ``plane_rows``, ``solve_qp``, ``containing``, ``vo_base``, ``min_speed``. Typed and lowered
  once, not once per call site as numba's own IR inlining (``inline="always"``) does (its
  inlining pass alone took 4.8 s of a 37 s first call); the answers are bitwise the same;
- ``inline_alloc``: inlined by numba at the IR level (so it may allocate, with its caller's
  flags): ``decide_one`` into ``decide`` and ``decide_range`` and the per-vehicle code into
  ``decide_range``. A function numba compiles on its own gets an LLVM module of its own, and
  numba links every callee's module into its caller's and optimises and generates machine code
  for the whole again, so a compiled wrapper around ``decide_one`` would repeat all of that.

``forceinline`` is inherited by callees that do not set it, so every flavour sets it.

Compile time (first call with an empty cache, about 35 s: benchmarks/results_first_call.md):
numba's own typing and lowering is about half, LLVM (optimising and generating machine code
for each compiled function's module, its callees linked in) the other half.
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


_COMMON: dict[str, Any] = dict(cache=True, error_model="numpy", nogil=True, forceinline=False)

entry = _compiler(**_COMMON)
jit = _compiler(**_COMMON, no_cpython_wrapper=True)
kernel = _compiler(**_COMMON, no_cpython_wrapper=True, _nrt=False)
inline = _compiler(**{**_COMMON, "forceinline": True}, no_cpython_wrapper=True, _nrt=False)
inline_alloc = _compiler(**_COMMON, no_cpython_wrapper=True, inline="always")
