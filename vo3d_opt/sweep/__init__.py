"""Monte Carlo sweeps of random encounters on Dask (``vo3d sweep``).

The last layer: it uses the simulator, the scenario loader, the selector (through the
simulator), the metrics and the RVO2-3D baseline; nothing but the CLI imports it.

* :mod:`.families`: the registry of encounter families (``pair``, ``group``, ``dense`` and the
  group variants ``lagged``, ``intruder``, ``rotorpy``, ``noisy``) and
  :func:`make_encounter`, which regenerates any encounter from (family, seed, index);
* :mod:`.flight`: :func:`run_encounter`, one encounter flown where it is called, and
  ``run_encounters``, several, side by side where they can;
* :mod:`.runner`: :func:`run_sweep`, N encounters on Dask (:mod:`.cluster` is the Dask side);
* :mod:`.store`: the rows kept in ``--out`` as they come, and ``--resume``;
* :mod:`.stats`: Clopper–Pearson bounds, risk ratios and the sweep's summary;
* :mod:`.output`: ``encounters.parquet``, ``summary.json``, plots and replayable failures.

A sweep needs the ``[sweep]`` extra (Dask, pandas, statsmodels, with ``[sim]``): without it
``run_sweep`` and the modules that import them raise :class:`~vo3d_opt.extras.MissingExtra`,
one line naming it; importing this package does not (the command line reads its defaults).
"""

from vo3d_opt.generators import (
    FAMILIES,
    Draw,
    Family,
    SweepEncounter,
    encounter_problems,
    get_family,
    make_encounter,
    register,
)
from vo3d_opt.sweep.flight import TIMING_COLUMNS, Method, run_encounter
from vo3d_opt.sweep.runner import SweepError, SweepResult, run_sweep
from vo3d_opt.sweep.stats import clopper_pearson, event_rate, upper_bound

__all__ = [
    "FAMILIES",
    "Draw",
    "SweepEncounter",
    "Family",
    "Method",
    "SweepError",
    "SweepResult",
    "TIMING_COLUMNS",
    "clopper_pearson",
    "encounter_problems",
    "event_rate",
    "get_family",
    "make_encounter",
    "register",
    "run_encounter",
    "run_sweep",
    "upper_bound",
]
