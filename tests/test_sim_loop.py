"""The one simulation loop (sim.simulator.fly) with its decision steps, the metrics at swarm
scale (k-d tree pairs against every pair), the report files and the swarm scenarios."""
from __future__ import annotations

import copy

import numpy as np
import pandas as pd
import pytest
import yaml

from vo3d_opt import report
from vo3d_opt.sim import simulator
from vo3d_opt.sim.deciders import PerAgentSelect, SwarmSelect
from vo3d_opt.sim.metrics import close_pairs, nearest_vehicle_distance, pair_min_distances, summarize
from vo3d_opt.sim.scenario import bundled_dir, bundled_files, load_scenario, scenario_from_dict
from vo3d_opt.generators import random_crossing_scenario
from vo3d_opt.sim.simulator import fly, scenario_selector

SWARMS = {"random-crossing-1000", "rvo2-sphere-812"}
SMALL = [p for p in bundled_files() if p.stem not in SWARMS]


@pytest.mark.parametrize("path", SMALL, ids=lambda p: p.stem)
def test_select_many_flies_every_bundled_scenario_as_per_agent_select_calls(path):
    sc = load_scenario(path)
    sel, formulation, solver = scenario_selector(sc)
    swarm = fly(sc, SwarmSelect(sc, sel, formulation=formulation, solver=solver), progress=False)
    single = fly(sc, PerAgentSelect(sc, sel, formulation=formulation, solver=solver), progress=False)
    assert swarm.steps == single.steps and swarm.extra["compiled"]
    np.testing.assert_allclose(swarm.positions, single.positions, rtol=0, atol=1e-9)
    assert np.array_equal(swarm.statuses, single.statuses)
    assert np.array_equal(swarm.arrived, single.arrived)


def test_first_order_dynamics_and_max_neighbors_in_the_loop():
    sc = load_scenario("sphere-swap-16").model_copy(update={"velocity_response_tau": 0.6, "max_time": 12.0})
    sel, _, _ = scenario_selector(sc)
    swarm = fly(sc, SwarmSelect(sc, sel), progress=False)
    single = fly(sc, PerAgentSelect(sc, sel), progress=False)
    np.testing.assert_allclose(swarm.positions, single.positions, rtol=0, atol=1e-9)
    assert not np.array_equal(swarm.commands, swarm.velocities)  # a velocity response: they differ
    few = fly(sc, SwarmSelect(sc, sel, max_neighbors=2), progress=False, max_steps=40)
    assert not np.allclose(few.positions, swarm.positions[:41])  # fewer neighbours, other paths


def test_progress_bar_completes_when_everyone_arrives_early(capsys, monkeypatch):
    sc = load_scenario("vertical-encounter")
    sel, _, _ = scenario_selector(sc)
    monkeypatch.setattr(simulator, "PROGRESS_DELAY", 0.0)  # shown from the first step
    rec = fly(sc, SwarmSelect(sc, sel), progress=True)
    assert rec.steps < sc.n_steps and rec.arrived[-1].all()
    err = capsys.readouterr().err
    assert f"{rec.steps}/{rec.steps}" in err and "100%" in err and "arrived 3/3" in err
    assert err.endswith("\r") and err.rstrip("\r").endswith(" ")  # cleared on close
    monkeypatch.undo()  # a run shorter than the delay: no bar at all, none left behind
    fly(sc, SwarmSelect(sc, sel), progress=True)
    assert capsys.readouterr().err == ""


def test_random_crossing_1000_is_the_generator_output_and_its_first_steps_fly():
    sc = load_scenario("random-crossing-1000")
    made = random_crossing_scenario(1000, seed=1000)
    assert sc.n_agents == 1000 and sc.warnings() == []
    np.testing.assert_array_equal(sc.starts, made.starts)
    np.testing.assert_array_equal(sc.goals, made.goals)
    assert (sc.dt, sc.max_time, sc.limits) == (made.dt, made.max_time, made.limits)
    sel, _, _ = scenario_selector(sc)
    rec = fly(sc, SwarmSelect(sc, sel), progress=False, max_steps=3)
    assert rec.steps == 3 and set(rec.statuses.ravel()) <= {"optimal", "inside_protected_zone"}
    d = np.linalg.norm(sc.starts[:, None] - sc.starts[None], axis=-1)
    assert d[np.triu_indices(1000, 1)].min() >= 25.0 - 0.02  # spacing, up to the rounding


def test_constant_density_crossing_keeps_its_density():
    small, large = random_crossing_scenario(50, seed=3), random_crossing_scenario(400, seed=3)
    for sc in (small, large):
        flown = np.linalg.norm(sc.goals - sc.starts, axis=1)
        np.testing.assert_allclose(flown, 200.0, atol=0.05)
        side = np.ptp(sc.starts[:, :2], axis=0).max()
        assert sc.n_agents * 40.0 ** 3 / (80.0 * side ** 2) == pytest.approx(1.0, rel=0.25)


# ------------------------------------------------------------------------------ metrics


def random_walks(seed: int, n: int = 40, steps: int = 30) -> np.ndarray:
    """n vehicles wandering for ``steps`` samples in a 60 m cube, 1.5 m per axis per step."""
    rng = np.random.default_rng(seed)
    moves = rng.normal(scale=1.5, size=(steps, n, 3))
    moves[0] = rng.uniform(0.0, 60.0, (n, 3))
    return np.cumsum(moves, axis=0)


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("threshold", [0.5, 6.0, 20.0])
def test_close_pairs_are_every_pair_below_the_threshold_and_the_closest(seed, threshold):
    p = random_walks(seed)
    ii, jj, d = pair_min_distances(p)
    ci, cj, cd = close_pairs(p, threshold)
    want = {(int(i), int(j)): float(x) for i, j, x in zip(ii, jj, d, strict=True) if x < threshold}
    k = int(np.argmin(d))
    want[(int(ii[k]), int(jj[k]))] = float(d[k])
    got = {(int(i), int(j)): float(x) for i, j, x in zip(ci, cj, cd, strict=True)}
    assert got == want  # the same pairs, the same distances to the last bit


def test_nearest_vehicle_distance_is_brute_force():
    p = random_walks(9, n=12, steps=6)
    d = np.linalg.norm(p[:, :, None] - p[:, None], axis=-1)
    d[:, np.arange(12), np.arange(12)] = np.inf
    from types import SimpleNamespace
    np.testing.assert_allclose(nearest_vehicle_distance(SimpleNamespace(positions=p)), d.min(axis=2))


# ------------------------------------------------------------------------------ report


@pytest.fixture(scope="module")
def crossing(tmp_path_factory) -> tuple:
    sc = load_scenario("paper-case1-ten-uav-crossing").model_copy(update={"max_time": 8.0})
    sel, formulation, solver = scenario_selector(sc)
    rec = fly(sc, SwarmSelect(sc, sel, formulation=formulation, solver=solver), progress=False)
    return rec, summarize(rec)


def test_parquet_has_one_row_per_agent_and_sample(crossing, tmp_path):
    rec, _ = crossing
    path = report.write_parquet(rec, tmp_path / "t.parquet")
    df = pd.read_parquet(path)
    assert list(df.columns) == report.COLUMNS and len(df) == rec.n_agents * (rec.steps + 1)
    k, i = 7, 3
    row = df[(df.step == k) & (df.agent == rec.ids[i])].iloc[0]
    np.testing.assert_array_equal(row[["x", "y", "z"]].to_numpy(float), rec.positions[k, i])
    np.testing.assert_array_equal(row[["vx", "vy", "vz"]].to_numpy(float), rec.velocities[k, i])
    assert row.status == rec.statuses[k, i] and row.time == rec.times[k]
    last = df[df.step == rec.steps]
    assert last[["vx", "cmd_vz", "decision_time_us"]].isna().all().all() and set(last.status) == {""}
    csv = pd.read_csv(report.write_csv(rec, tmp_path / "t.csv"))
    np.testing.assert_allclose(csv[["x", "y", "z"]].to_numpy(), df[["x", "y", "z"]].to_numpy(), atol=1e-6)


def test_large_runs_write_parquet_instead_of_csv(crossing, tmp_path, monkeypatch):
    pytest.importorskip("matplotlib")
    rec, summary = crossing
    monkeypatch.setattr(report, "CSV_MAX_ROWS", rec.n_agents * (rec.steps + 1) - 1)
    names = {p.name for p in report.write_outputs(rec, summary, tmp_path)}
    assert "trajectories.parquet" in names and "trajectories.csv" not in names
    assert "summary.json" in names and (tmp_path / "top_view.png").exists()


def test_swarm_figures_draw_collections(tmp_path):
    sc = random_crossing_scenario(120, seed=5)
    sel, _, _ = scenario_selector(sc)
    rec = fly(sc, SwarmSelect(sc, sel), progress=False, max_steps=20)
    from vo3d_opt.figures import figure_top_view

    ax = figure_top_view(rec).axes[0]
    assert len(ax.collections) >= 3 and len(ax.get_lines()) < 10


def test_scenario_checks_use_close_pairs_only(tmp_path):
    data = yaml.safe_load((bundled_dir() / "sphere-swap-16.yaml").read_text())
    data = copy.deepcopy(data)
    data["agents"][3]["start"] = list(np.add(data["agents"][2]["start"], [0.5, 0.0, 0.0]))
    with pytest.raises(ValueError, match=r"agents\[3\]\.start.*overlaps agents\[2\]"):
        scenario_from_dict(data)
    data["agents"][3]["start"] = list(np.add(data["agents"][2]["start"], [3.0, 0.0, 0.0]))
    warnings = scenario_from_dict(data).start_warnings()
    assert len(warnings) == 1 and warnings[0].startswith(f"{data['agents'][2]['id']} and {data['agents'][3]['id']}")
