"""Recorded decisions (``tests/golden_cases.py``) decided again: the same answers.

The file was recorded before the presets and the layout of today's code; every named
configuration of it is asked for here the way a user asks for it today. The compiled path must
give the same answers bit for bit; the Python paths over outside backends the same within the
backends' own tolerances.
"""

from __future__ import annotations

import functools
import json

import numpy as np
import pytest
from golden_cases import (
    GOLDEN,
    GOLDEN_RUNS,
    N_SWARMS,
    OPTION_SETS,
    SWARM_LIMITS,
    SWARM_SETS,
    encounter,
    limits_of,
    many_kwargs,
    recorded_selector,
    run_summary,
    select_kwargs,
    swarm,
)

from vo3d_opt import VelocitySelector

DATA = np.load(GOLDEN)


#: How each recorded configuration is asked for today: a preset and overrides. (The recorded
#: option values, ``golden_cases.option_set``, resolved per decision: the safe buffer is two
#: steps at the decision's top speed, the swarm horizon the range over twice that speed, none
#: under an acceleration limit below 2 v_max / dt.)
PRESET_OF = {
    "paper": ("paper", {}),
    "safe": ("safe", {}),
    "fast": ("fast", {}),
    "swarm": ("swarm", {"sensing_range": 55.0}),
    "safe_no_escape": ("safe", {"least_bad_escape": False}),
    "fast_coarse": ("fast", {"fine_fallback": False}),
    "paper_planes20": ("paper", {"plane_step_deg": 20.0, "qp_samples": 24, "margin": 1e-2}),
    "paper_corr": ("paper", {"corrections": frozenset({"tg_range", "triangle", "base_chord"})}),
    "safe_horizon": ("safe", {"horizon": 4.0}),
}


def selector(name: str, formulation: str = "plane_qp", solver=None) -> VelocitySelector:
    """The selector configuration ``name`` stands for."""
    preset, overrides = PRESET_OF[name]
    return VelocitySelector(formulation, solver, preset=preset, **overrides)


def test_every_recorded_configuration_is_asked_for() -> None:
    assert set(PRESET_OF) == set(OPTION_SETS)


@pytest.mark.parametrize("name", OPTION_SETS)
def test_presets_resolve_to_the_recorded_options(name: str) -> None:
    """Each configuration resolves, for a decision's top speed and period, to every option
    value it was recorded with: its options over the paper preset, as the recorder asks."""
    for v_max, dt in ((4.0, 0.2), (2.7, 0.05), (5.9, 0.43)):
        for acc in (None, 2.0, 2.0 * v_max / dt * 1.01):
            recorded = recorded_selector(name, v_max, dt, acceleration=acc)
            today = selector(name).options_for(v_max, dt, None, acc)
            assert today == recorded.options_for(v_max, dt, None, acc), (name, acc)


@functools.cache
def _select_kwargs(seed: int) -> dict:
    """Encounter ``seed``'s arguments of ``select``, built once for every configuration and
    path that decides it (the inputs are immutable)."""
    return select_kwargs(encounter(seed))


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
    selectors: dict[str, VelocitySelector] = {}
    for k in rows:
        seed, name = int(DATA["dec_seed"][k]), str(DATA["dec_set"][k])
        if name not in selectors:
            selectors[name] = selector(name, form, solver or None)
        key = name
        d = selectors[key].select(**_select_kwargs(seed))
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
        res = selector(name).select_many(**kw)
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
