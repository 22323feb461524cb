"""Baselines flown on the same scenarios and judged by the same metrics as vo3d_opt.

``rvo2``: RVO2-3D (reciprocal velocity obstacles in 3D, van den Berg et al.) through the
``rvo23d`` module of the optional ``baselines`` extra (package jt-pyrvo23d). Importing this
package does not import ``rvo23d``; :func:`rvo2.available` says whether it is installed.
"""

from .rvo2 import available as rvo2_available
from .rvo2 import run_rvo2, summarize_record, summarize_rvo2

__all__ = [
    "rvo2_available",
    "run_rvo2",
    "summarize_record",
    "summarize_rvo2",
]
