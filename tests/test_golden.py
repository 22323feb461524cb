"""Recorded decisions (``tests/golden_cases.py``) decided again: the same answers.

The file was recorded before the presets and the layout of today's code; every named
configuration of it is asked for here the way a user asks for it today. The compiled path must
give the same answers bit for bit; the Python paths over outside backends the same within the
backends' own tolerances.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from golden_cases import (
    GOLDEN,
    GOLDEN_RUNS,
    N_SWARMS,
    SWARM_LIMITS,
    SWARM_SETS,
    encounter,
    limits_of,
    many_kwargs,
    option_set,
    run_summary,
    select_kwargs,
    swarm,
)
from vo3d_opt import VelocitySelector

DATA = np.load(GOLDEN)


def selector(name: str, v_max: float, dt: float, formulation: str = "plane_qp", solver=None):
    """The selector configuration ``name`` stands for."""
    return VelocitySelector(formulation, solver, **option_set(name, v_max, dt))


def _rows(path: str) -> np.ndarray:
    return np.flatnonzero(DATA["dec_path"] == path)


@pytest.mark.parametrize(
    "path",
    sorted(set(DATA["dec_path"].tolist())),
)
def test_recorded_decisions_are_decided_again(path: str) -> None:
    form, solver = path.split("/")
    rows = _rows(path)
    exact = solver == "exact2d"
    selectors: dict[tuple, VelocitySelector] = {}
    for k in rows:
        seed, name = int(DATA["dec_seed"][k]), str(DATA["dec_set"][k])
        e = encounter(seed)
        v_max, dt = float(e["limits"][1]), float(e["dt"])
        key = (name, v_max, dt)
        if key not in selectors:
            selectors[key] = selector(name, v_max, dt, form, solver or None)
        d = selectors[key].select(**select_kwargs(e))
        where = f"{path} {name} encounter {seed}"
        assert str(d.status) == DATA["dec_status"][k], where
        if exact:
            assert np.array_equal(d.velocity, DATA["dec_velocity"][k]), where
            assert str(d.info.get("round", "")) == DATA["dec_round"][k], where
        else:
            np.testing.assert_allclose(
                d.velocity, DATA["dec_velocity"][k], atol=1e-6, err_msg=where
            )


@pytest.mark.parametrize("seed", range(N_SWARMS))
def test_recorded_swarms_are_decided_again(seed: int) -> None:
    s = swarm(seed)
    kw = many_kwargs(s, limits_of(SWARM_LIMITS))
    for name in SWARM_SETS:
        res = selector(name, 4.0, 0.2).select_many(**kw)
        assert np.array_equal(res.velocities, DATA[f"swarm{seed}_{name}_velocities"]), name
        assert np.array_equal(
            np.asarray(res.statuses, dtype=str), DATA[f"swarm{seed}_{name}_statuses"]
        ), name


#: Keys of a run's summary that say how it was configured, not what it flew.
_CONFIG_KEYS = ("selector_options",)


@pytest.mark.parametrize("run", sorted(json.loads(GOLDEN_RUNS.read_text())))
def test_recorded_runs_fly_again(run: str) -> None:
    want = json.loads(GOLDEN_RUNS.read_text())[run]
    got = run_summary(*run.split())
    for key in _CONFIG_KEYS:
        want.pop(key, None), got.pop(key, None)
    assert got == want
