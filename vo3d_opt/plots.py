"""Figures of a run: the names of :mod:`vo3d_opt.figures`, where they are drawn, kept here for
the code and notebooks that import them from ``vo3d_opt.plots``."""

from vo3d_opt.figures import *  # noqa: F403
from vo3d_opt.figures import __all__  # noqa: F401
