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

import numba

_COMMON = dict(cache=True, error_model="numpy", nogil=True)

entry = numba.njit(**_COMMON)
jit = numba.njit(**_COMMON, no_cpython_wrapper=True)
kernel = numba.njit(**_COMMON, no_cpython_wrapper=True, _nrt=False)
inline = numba.njit(**_COMMON, no_cpython_wrapper=True, _nrt=False, inline="always")
