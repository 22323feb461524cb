"""The compiler for the per-step loops: numba's ``njit``, cached on disk.

The geometry of one decision is a few hundred tiny numbers; in numpy every step costs a call of a
few microseconds, so the per-decision work is written as plain loops (the paper's formulas one
cone, plane and generator at a time) and compiled. ``error_model="numpy"`` keeps numpy's float
semantics (x / 0 is inf or NaN, never an exception), which the formulas rely on.
"""
from __future__ import annotations

import numba

jit = numba.njit(cache=True, error_model="numpy", nogil=True, no_cpython_wrapper=True)
entry = numba.njit(cache=True, error_model="numpy", nogil=True)
