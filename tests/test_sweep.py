"""``vo3d sweep``: families, Dask runs, rates, outputs and replays.

Clusters are small (2 local worker processes) and the encounters short, so the module stays
well under a minute of wall time beyond the clusters' start.
"""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import yaml
import pytest
from scipy.stats import binomtest

from vo3d_opt.sim.metrics import CONTRACT_KEYS
from vo3d_opt.sim.scenario import load_scenario, scenario_from_dict, scenario_variant
from vo3d_opt.sim.simulator import scenario_selector
from vo3d_opt.sweep import (
    FAMILIES,
    TIMING_COLUMNS,
    Draw,
    Family,
    Method,
    SweepError,
    SweepResult,
    clopper_pearson,
    encounter_problems,
    make_encounter,
    run_encounter,
    run_sweep,
    upper_bound,
)
from vo3d_opt.generators import TIME_FACTOR, TIME_SLACK, encounter_rng
from vo3d_opt.sweep.flight import DEFAULT_METHOD
from vo3d_opt.sweep.flight import fly_encounter as fly
from vo3d_opt.sweep.output import failed_rows, failure_scenario, write_results
from vo3d_opt.sweep.runner import rows_equal

SWEEP_SUMMARY_KEYS = ("family", "encounters", "seed", "method", "formulation", "solver",
                      "collisions", "encounters_with_collision", "pz_intrusions",
                      "encounters_with_intrusion", "not_arrived", "limit_violations",
                      "collision_rate_upper95", "wall_time")
TIMING_SUMMARY_KEYS = {"decision_time_median_us", "decision_time_p99_us", "decision_time_max_us",
                       "wall_time"}


def vo3d(*args: str | Path) -> subprocess.CompletedProcess:
    script = Path(sys.executable).with_name("vo3d")
    cmd = [str(script)] if script.exists() else [sys.executable, "-m", "vo3d_opt.cli"]
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}
    return subprocess.run(cmd + [str(a) for a in args], capture_output=True, text=True,
                          timeout=600, env=env)


# ----------------------------------------------------------------- test-only families


def _crossing(rng: np.random.Generator, vehicle_range: float) -> Draw:
    """Two UAVs crossing at right angles at the origin, 18 m out at 4 m/s (a 9 s flight)."""
    dz = rng.uniform(-0.2, 0.2)
    scenario = {
        "dt": 0.2, "max_time": 60.0,
        "limits": {"speed": [0.0, 4.0], "altitude": [0.0, 40.0]},
        "sensing": {"vehicle_range": vehicle_range, "obstacle_range": 55.0},
        "defaults": {"r_pz": 3.0},
        "agents": [{"id": "a", "start": [-18.0, 0.0, 20.0], "goal": [18.0, 0.0, 20.0]},
                   {"id": "b", "start": [0.0, -18.0, 20.0 + dz], "goal": [0.0, 18.0, 20.0 + dz]}],
    }
    return Draw(params={"dz": float(dz)}, scenario=scenario)


def blind_family() -> Family:
    """Vehicles that sense each other only at 1 m, when their 0.5 m bodies touch: they collide,
    every time. (The loader rejects a range shorter than one step, 4 m/s x 0.2 s.)"""
    return Family(name="blind", summary="test", obstacle_free=True,
                  generate=lambda rng: _crossing(rng, vehicle_range=1.0))


FLAKY_P = 0.5


def flaky_family() -> Family:
    """Raises in about half the encounters (when the stream's first number is below 0.5)."""
    def generate(rng: np.random.Generator) -> Draw:
        if rng.random() < FLAKY_P:
            raise RuntimeError("injected failure")
        return _crossing(rng, vehicle_range=55.0)

    return Family(name="flaky", summary="test", obstacle_free=True, generate=generate)


#: This process: the client, which draws a few encounters too (the manifest's ``draws``), and
#: is not the worker the test families below mean to kill.
CLIENT = os.getpid()


def lethal_family() -> Family:
    """Kills its worker process in about a third of the encounters."""
    def generate(rng: np.random.Generator) -> Draw:
        if rng.random() < 0.3 and os.getpid() != CLIENT:
            os._exit(3)
        return _crossing(rng, vehicle_range=55.0)

    return Family(name="lethal", summary="test", obstacle_free=True, generate=generate)


def transient_family(flag: Path) -> Family:
    """Kills its worker in about a third of the encounters while ``flag`` exists: a cluster
    that fails for a time, not an encounter that does."""
    def generate(rng: np.random.Generator) -> Draw:
        if rng.random() < 0.3 and flag.exists() and os.getpid() != CLIENT:
            os._exit(3)
        return _crossing(rng, vehicle_range=55.0)

    return Family(name="transient", summary="test", obstacle_free=True, generate=generate)


@pytest.fixture(scope="module")
def cluster():
    """Two local workers; a task whose worker dies is given up at once (no retry)."""
    import dask
    from distributed import LocalCluster

    with dask.config.set({"distributed.scheduler.allowed-failures": 0}), LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=None,
                      scheduler_kwargs={"dashboard_address": "127.0.0.1:0"}) as c:
        yield c.scheduler_address


# -------------------------------------------------------------------- Clopper–Pearson


def test_clopper_pearson_known_values():
    # closed forms at the ends, the textbook 5/10 interval, and scipy's exact binomtest
    assert clopper_pearson(0, 10) == (0.0, pytest.approx(1 - 0.025 ** 0.1, rel=1e-9))
    assert clopper_pearson(10, 10) == (pytest.approx(0.025 ** 0.1, rel=1e-9), 1.0)
    lo, hi = clopper_pearson(5, 10)
    assert (lo, hi) == (pytest.approx(0.187086, abs=1e-6), pytest.approx(0.812914, abs=1e-6))
    for k, n in [(1, 7), (3, 50), (17, 1000), (0, 10_000)]:
        ci = binomtest(k, n).proportion_ci(method="exact")
        assert clopper_pearson(k, n) == (pytest.approx(ci.low, rel=1e-9, abs=1e-15),
                                         pytest.approx(ci.high, rel=1e-9))
        one_sided = binomtest(k, n, alternative="less").proportion_ci(method="exact")
        assert upper_bound(k, n) == pytest.approx(one_sided.high, rel=1e-9)


def test_zero_events_upper_bound_is_about_three_over_n():
    for n in (100, 1000, 10_000):
        assert upper_bound(0, n) == pytest.approx(1 - 0.05 ** (1 / n), rel=1e-9)
        assert 2.9 / n < upper_bound(0, n) < 3.0 / n
    with pytest.raises(ValueError):
        clopper_pearson(3, 2)


# --------------------------------------------------------------------------- families


RUNNABLE = sorted(f.name for f in FAMILIES.values() if not f.missing_keys())


@pytest.mark.parametrize("name", RUNNABLE)
def test_family_encounters_are_valid_and_reachable(name):
    for index in range(15):
        enc = make_encounter(name, 11, index)
        assert encounter_problems(enc.scenario) == []
        sc = enc.load()
        assert sc.start_warnings() == []
        flight = np.linalg.norm(sc.goals - sc.starts, axis=1) / sc.max_speed
        assert TIME_FACTOR * flight.max() + TIME_SLACK <= sc.max_time + 1e-9
        if FAMILIES[name].obstacle_free:
            assert not sc.obstacles


def test_invalid_encounters_are_recognised():
    enc = next(e for e in (make_encounter("group", 3, i) for i in range(50))
               if e.scenario.get("obstacles"))
    assert encounter_problems(enc.scenario) == []
    body = enc.load().bodies[0]  # a goal outside the body, inside its protected prism
    near_prism = json.loads(json.dumps(enc.scenario))
    near_prism["agents"][0]["goal"] = [body.center[0] + body.side / 2 - 0.5, body.center[1], 5.0]
    assert any("protected prism" in p for p in encounter_problems(near_prism))
    crowded = json.loads(json.dumps(enc.scenario))
    g = crowded["agents"][0]["goal"]
    crowded["agents"][1]["goal"] = [g[0], g[1], g[2] + 1.0]  # hovering 1 m apart: forced intrusion
    assert any("apart" in p for p in encounter_problems(crowded))
    inside = json.loads(json.dumps(enc.scenario))
    inside["agents"][1]["start"] = list(inside["agents"][0]["start"])
    assert encounter_problems(inside)  # the loader's own rejection (overlapping starts)


def test_family_parameters_follow_their_distributions():
    pair = [make_encounter("pair", 2, i).params for i in range(40)]
    assert all(2.0 <= p[f"speed_{k}"] <= 6.0 and -1.5 <= p[f"climb_{k}"] <= 1.5
               and 5.0 <= p[f"r_pz_{k}"] <= 12.0 for p in pair for k in (0, 1))
    assert all(0.0 <= p["miss_over_r_pz"] <= 1.2 for p in pair)
    group = [make_encounter("group", 2, i) for i in range(40)]
    assert {len(e.load().agents) for e in group} <= set(range(3, 9))
    assert {len(e.load().obstacles) for e in group} <= set(range(0, 7))
    assert len({len(e.load().obstacles) for e in group}) > 3  # it does vary
    dense = [make_encounter("dense", 2, i).load() for i in range(10)]
    assert all(10 <= sc.n_agents <= 24 for sc in dense)


def test_pair_flies_its_planned_miss_distance_without_avoidance():
    for index in range(20):
        enc = make_encounter("pair", 5, index)
        sc = enc.load()
        direction = sc.goals - sc.starts
        v = direction / np.linalg.norm(direction, axis=1, keepdims=True) * sc.max_speed[:, None]
        dp, dv = sc.starts[0] - sc.starts[1], v[0] - v[1]
        t = -dp @ dv / (dv @ dv)
        assert t == pytest.approx(enc.params["t_cpa"], abs=0.05)
        assert np.linalg.norm(dp + t * dv) == pytest.approx(enc.params["miss_distance"], abs=0.01)


def test_an_encounter_is_regenerated_alone_from_seed_and_index():
    a = make_encounter("group", 7, 12)
    assert make_encounter("group", 7, 12) == a  # nothing else drawn before it matters
    assert make_encounter("group", 7, 13).scenario != a.scenario
    assert make_encounter("group", 8, 12).scenario != a.scenario
    assert a.scenario["name"] == "group-s7-i12"
    with pytest.raises(ValueError, match="unknown 'nope'"):
        make_encounter("nope", 0, 0)


# ------------------------------------------------------------------------ Dask sweeps


def test_same_results_with_one_and_two_workers(cluster):
    one = run_sweep("pair", 4, seed=3, workers=1, progress=False)
    two = run_sweep("pair", 4, seed=3, scheduler=cluster, progress=False)
    assert one.summary["workers"] == 1 and two.summary["workers"] == 2
    assert list(one.rows["index"]) == [0, 1, 2, 3] and one.rows["error"].isna().all()
    assert rows_equal(one.rows, two.rows)
    assert two.rows["worker"].nunique() == 2  # both workers did take part
    ignore = {"wall_time", "setup_time", "encounters_per_second", "workers", "scheduler"}
    assert {k: v for k, v in one.summary.items() if k not in ignore} == \
        {k: v for k, v in two.summary.items() if k not in ignore}
    # and the same as encounter 2 alone, in this process
    alone = pd.DataFrame([run_encounter("pair", 3, 2)])
    assert rows_equal(alone, one.rows.iloc[[2]])


def test_an_encounter_that_raises_is_reported_and_the_sweep_finishes(cluster):
    n = 8
    expected = [i for i in range(n) if encounter_rng(0, i).random() < FLAKY_P]
    assert 0 < len(expected) < n
    result = run_sweep(flaky_family(), n, seed=0, scheduler=cluster, progress=False)
    rows = result.rows
    assert list(rows["index"]) == list(range(n))
    assert [e["index"] for e in result.summary["errors"]] == expected
    assert all(e["error"] == "RuntimeError: injected failure" for e in result.summary["errors"])
    ran = rows[rows["error"].isna()]
    assert sorted(ran["index"]) == sorted(set(range(n)) - set(expected))
    assert ran["all_reached"].all()
    assert result.summary["completed"] == n - len(expected)
    assert result.summary["rates"]["error"]["events"] == len(expected)
    assert result.summary["rates"]["collision"]["encounters"] == n - len(expected)


def test_a_worker_that_dies_is_reported_and_the_sweep_finishes(cluster):
    from distributed import Client

    n = 4
    lethal = [i for i in range(n) if encounter_rng(0, i).random() < 0.3]
    assert 0 < len(lethal) < n
    result = run_sweep(lethal_family(), n, seed=0, scheduler=cluster, in_flight=2,
                       progress=False)
    with Client(cluster) as client:  # the nanny restarts the worker: leave the cluster whole
        client.wait_for_workers(2, timeout=120)
    assert list(result.rows["index"]) == list(range(n))  # none dropped
    errors = {e["index"]: e["error"] for e in result.summary["errors"]}
    assert set(lethal) <= set(errors)
    assert all(msg.startswith("KilledWorker") for msg in errors.values())
    assert result.rows.loc[~result.rows["index"].isin(errors), "all_reached"].all()


def test_resume_flies_again_what_a_lost_worker_left_as_errors(cluster, tmp_path):
    """Rows a lost worker left as errors are flown again by --resume, which then ends with the
    rows of a sweep that lost none."""
    from distributed import Client

    n, flag, out = 4, tmp_path / "failing", tmp_path / "out"
    flag.touch()
    lost = run_sweep(transient_family(flag), n, seed=0, scheduler=cluster, in_flight=2,
                     progress=False, out=out)
    with Client(cluster) as client:  # the nanny restarts the worker: leave the cluster whole
        client.wait_for_workers(2, timeout=120)
    assert lost.summary["errors"]  # some encounters lost their worker
    flag.unlink()
    resumed = run_sweep(transient_family(flag), n, seed=0, scheduler=cluster, progress=False,
                        out=out, resume=True)
    whole = run_sweep(transient_family(flag), n, seed=0, scheduler=cluster, progress=False)
    assert not resumed.summary["errors"]
    assert rows_equal(resumed.rows, whole.rows)


def test_bad_options_are_refused_before_any_cluster_starts():
    with pytest.raises(SweepError, match="--method rvo2: family 'group' has obstacles"):
        run_sweep("group", 2, method=Method(name="rvo2"))
    with pytest.raises(SweepError, match="unknown 'nope'"):
        run_sweep("nope", 2)
    with pytest.raises(SweepError, match="--n"):
        run_sweep("pair", 0)
    # the rows keep the seed in an int64 Parquet column: refused before anything flies
    with pytest.raises(SweepError, match="--seed"):
        run_sweep("pair", 2, seed=2**63)
    # a list of every index is made before anything flies: 10**30 of them never end
    with pytest.raises(SweepError, match="--n: must be at most"):
        run_sweep("pair", 10**30)
    # a local worker is a process of its own: a huge count would exhaust memory first
    with pytest.raises(SweepError, match="--workers: must be at most"):
        run_sweep("pair", 2, workers=10**6)
    with pytest.raises(SweepError, match="solver 'bogus'"):
        run_sweep("pair", 2, method=Method(solver="bogus"))
    with pytest.raises(ValueError, match="selector_options.closing_guard: .*boolean"):
        Method(selector_options=(("closing_guard", 3),))
    with pytest.raises(ValueError, match="selector_options.pz_bufer: .*'pz_buffer'"):
        Method(selector_options=(("pz_bufer", 1.0),))
    with pytest.raises(SweepError, match="--preset/--selector-option: not used by --method rvo2"):
        run_sweep("pair", 2, method=Method(name="rvo2", selector_options=(("margin", 0.1),)))


def test_a_finished_sweep_is_kept_unless_resumed_or_overwritten(cluster, tmp_path):
    """A directory holding a finished sweep is refused without --resume or --overwrite (its
    rows would be lost) and left as it was, whatever the arguments; --resume of the same sweep
    flies nothing and gives its rows; --overwrite replaces it, even past a corrupt manifest."""
    out = tmp_path / "done"
    first = run_sweep("pair", 4, seed=0, scheduler=cluster, progress=False, out=out)
    write_results(first, out)
    table = (out / "encounters.parquet").read_bytes()
    with pytest.raises(SweepError, match="finished sweep of other arguments .*encounters: 4 there"):
        run_sweep("pair", 3, seed=0, scheduler=cluster, progress=False, out=out)
    with pytest.raises(SweepError, match="holds a finished sweep; continue or keep it with --res"):
        run_sweep("pair", 4, seed=0, scheduler=cluster, progress=False, out=out)
    res = vo3d("sweep", "pair", "--n", "3", "--out", out, "--json")
    assert res.returncode == 2 and res.stdout == "", res.stderr
    assert len(res.stderr.strip().splitlines()) == 1 and "--overwrite" in res.stderr
    assert (out / "encounters.parquet").read_bytes() == table
    with pytest.raises(SweepError, match="--resume, --overwrite: give one of them"):
        run_sweep("pair", 4, seed=0, scheduler=cluster, out=out, resume=True, overwrite=True)
    again = run_sweep("pair", 4, seed=0, scheduler=cluster, progress=False, out=out,
                      resume=True)
    assert again.flown == 0 and rows_equal(again.rows, first.rows)
    (out / "sweep.json").write_text("[1]")
    replaced = run_sweep("pair", 3, seed=0, scheduler=cluster, progress=False, out=out,
                         overwrite=True)
    write_results(replaced, out)
    assert json.loads((out / "sweep.json").read_text())["encounters"] == 3
    kept = pd.read_parquet(out / "encounters.parquet")
    assert list(kept["index"]) == [0, 1, 2]
    assert rows_equal(kept, first.rows[first.rows["index"] < 3])


def test_a_resume_refuses_rows_of_a_family_that_drew_other_encounters(cluster, tmp_path):
    """The manifest names a digest of what the family draws (its encounter 0's scenario: a
    version with other dynamics or draws is another sweep); a resume where it differs is
    refused naming it, and nothing there changes."""
    from vo3d_opt.generators import get_family
    from vo3d_opt.sweep.runner import draws_digest

    out = tmp_path / "older"
    run_sweep("pair", 2, seed=0, scheduler=cluster, progress=False, out=out)
    found = json.loads((out / "sweep.json").read_text())
    assert found["draws"] == draws_digest(get_family("pair"), 0, 2)
    assert draws_digest(get_family("pair"), 1, 2) != found["draws"]
    (out / "sweep.json").write_text(json.dumps({**found, "draws": "0" * 16}))
    before = sorted((p.name, p.read_bytes()) for p in out.rglob("*") if p.is_file())
    with pytest.raises(SweepError, match='another sweep .*draws: "0{16}" there'):
        run_sweep("pair", 2, seed=0, scheduler=cluster, progress=False, out=out, resume=True)
    assert sorted((p.name, p.read_bytes()) for p in out.rglob("*") if p.is_file()) == before


# ------------------------------------------------------------- outputs and the CLI


def test_collisions_are_written_as_scenarios_that_vo3d_run_replays(cluster, tmp_path):
    result = run_sweep(blind_family(), 2, seed=0, scheduler=cluster, progress=False)
    assert result.summary["encounters_with_collision"] == 2
    assert result.summary["collision_rate_upper95"] == pytest.approx(upper_bound(2, 2))
    written = write_results(result, tmp_path)
    failures = sorted((tmp_path / "failures").glob("*.yaml"))
    assert [p.name for p in failures] == ["blind-s0-i0.yaml", "blind-s0-i1.yaml"]
    assert set(failures) <= set(written) and len(failed_rows(result.rows)) == 2
    rows = pd.read_parquet(tmp_path / "encounters.parquet")
    assert rows_equal(rows, result.rows)
    for path in failures:
        assert load_scenario(path).name == path.stem
        replay = vo3d("run", path, "--json")
        assert replay.returncode == 0, replay.stderr
        summary = json.loads(replay.stdout)
        row = rows[rows["scenario"] == path.stem].iloc[0]
        for key, value in summary.items():
            if key in TIMING_SUMMARY_KEYS:
                continue
            as_text = key in ("status_counts", "selector_options")
            expected = json.loads(row[key]) if as_text else row[key]
            if isinstance(value, float):  # vo3d run's JSON keeps 12 significant digits
                assert value == pytest.approx(expected, rel=1e-11, abs=0), key
            else:
                assert value == expected, key


def test_sweep_json_prints_one_object_with_the_contract_keys(cluster, tmp_path):
    proc = vo3d("sweep", "pair", "--n", "2", "--seed", "5", "--scheduler", cluster, "--json",
                "--out", tmp_path, "-o", "closing_guard=true")
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout.strip()
    assert out.startswith("{") and "\n" not in out
    summary = json.loads(out)
    assert set(SWEEP_SUMMARY_KEYS) <= set(summary)
    assert (summary["family"], summary["encounters"], summary["seed"]) == ("pair", 2, 5)
    assert summary["method"] == "vo3d" and summary["formulation"] == "plane_qp"
    assert summary["selector_options"] == {"preset": "safe", "closing_guard": True}
    k = summary["encounters_with_collision"]
    assert summary["collision_rate_upper95"] == pytest.approx(upper_bound(k, 2))
    assert json.loads((tmp_path / "summary.json").read_text()) == summary
    rows = pd.read_parquet(tmp_path / "encounters.parquet")
    assert list(rows["index"]) == [0, 1] and (rows["family"] == "pair").all()
    assert {"param_miss_distance", "param_speed_0"} <= set(rows.columns)
    assert set(CONTRACT_KEYS) <= set(rows.columns)
    assert (rows["selector_options"] == '{"closing_guard": true, "preset": "safe"}').all()
    table = vo3d("sweep", "pair", "--n", "1", "--scheduler", cluster, "-o", "closing_guard=true")
    assert re.search(r"^selector_options +preset=safe closing_guard=true$", table.stdout, re.M), \
        table.stdout
    assert (tmp_path / "min_distance.png").stat().st_size > 0


def test_sweep_cli_lists_families_and_refuses_rvo2_with_obstacles():
    listed = vo3d("sweep", "--list")
    assert listed.returncode == 0, listed.stderr
    lines = listed.stdout.strip().splitlines()
    assert [line.split()[0] for line in lines] == list(FAMILIES)
    assert all(("rvo2 ok" in line) == FAMILIES[line.split()[0]].obstacle_free for line in lines)
    refused = vo3d("sweep", "group", "--n", "2", "--method", "rvo2")
    assert refused.returncode == 2 and refused.stdout == ""
    assert refused.stderr.strip().splitlines()[-1].startswith("vo3d: --method rvo2:")
    bad = vo3d("sweep", "pair", "--n", "2", "-o", "margin=0", "-o", "closing_guard=[")
    assert bad.returncode == 2 and bad.stdout == ""
    (line,) = bad.stderr.strip().splitlines()
    assert "selector_options.closing_guard" in line and "invalid YAML" in line
    bad = vo3d("sweep", "pair", "--n", "2", "-o", "margin=0")
    assert bad.returncode == 2 and bad.stdout == ""
    assert bad.stderr.strip() == ("vo3d: --selector-option: selector_options.margin: input "
                                  "should be greater than 0")


def test_rvo2_flies_the_same_encounters_keeping_the_larger_r_pz_apart():
    row = run_encounter("pair", 0, 1, Method(name="rvo2"))
    assert row["error"] is None and row["formulation"] == "rvo2-3d"
    assert row["scenario"] == run_encounter("pair", 0, 1)["scenario"]
    assert row["fallbacks"] is None  # RVO2 does not say
    assert row["min_normalised_distance"] > 0.999  # kept the larger r_pz (to float32 precision)
    # with RVO2's radius r_pz/2 per agent, the pair of unequal zones would come closer
    from vo3d_opt.baselines import run_rvo2
    from vo3d_opt.sweep.flight import normalised_min_distance

    enc = make_encounter("pair", 0, 1)
    r0, r1 = enc.params["r_pz_0"], enc.params["r_pz_1"]
    assert abs(r0 - r1) > 0.5
    per_agent = normalised_min_distance(run_rvo2(enc.load(), progress=False))
    assert per_agent < (r0 + r1) / 2 / max(r0, r1) + 1e-3 < 0.99


def test_formulation_and_solver_pass_through_to_the_runs_and_the_replays():
    method = Method(formulation="cone_qp", solver="osqp")
    row = run_encounter("pair", 0, 1, method)
    assert (row["error"], row["formulation"], row["solver"]) == (None, "cone_qp", "osqp")
    result = SweepResult(family=FAMILIES["pair"], seed=0, method=method, rows=pd.DataFrame())
    data = failure_scenario(result, 1)
    assert (data["formulation"], data["solver"]) == ("cone_qp", "osqp")
    assert data["agents"] == make_encounter("pair", 0, 1).scenario["agents"]


def test_selector_options_pass_through_to_the_runs_and_the_replays(tmp_path):
    """Each encounter flies as its scenario with the options in selector_options (as a file
    written with them flies); without reciprocity and buffer the encounters fly differently
    from the defaults."""
    options = {"pz_buffer": 0.0, "reciprocal": False}
    method = Method(selector_options=(("reciprocal", False), ("pz_buffer", 0)))
    assert method == Method(selector_options=tuple(options.items()))  # one form: sorted, valid
    changed = 0
    for index in range(3):
        row = run_encounter("pair", 0, index, method)
        assert row["error"] is None
        assert json.loads(row["selector_options"]) == {"preset": "safe", **options}
        data = {**make_encounter("pair", 0, index).scenario, "selector_options": options}
        _, summary = fly(scenario_from_dict(data), DEFAULT_METHOD)
        for key, value in summary.items():
            if key not in TIMING_SUMMARY_KEYS:
                as_text = key in ("status_counts", "selector_options")
                assert value == (json.loads(row[key]) if as_text else row[key]), (index, key)
        plain = run_encounter("pair", 0, index)
        assert json.loads(plain["selector_options"]) == {"preset": "safe"}
        changed += row["min_vehicle_distance"] != plain["min_vehicle_distance"]
    assert changed
    result = SweepResult(family=FAMILIES["pair"], seed=0, method=method, rows=pd.DataFrame())
    data = failure_scenario(result, 1)
    assert data["selector_options"] == options
    path = tmp_path / "replay.yaml"
    path.write_text(yaml.safe_dump(data))
    replay = vo3d("run", path, "--json")
    assert replay.returncode == 0, replay.stderr
    assert json.loads(replay.stdout)["selector_options"] == {"preset": "safe", **options}


def test_a_family_s_own_selector_options_stay_under_the_method_s():
    enc = make_encounter("pair", 0, 0)
    sc = scenario_from_dict({**enc.scenario, "selector_options": {"margin": 0.01,
                                                                  "reciprocal": True}})
    _, summary = fly(sc, Method(selector_options=(("reciprocal", False),)))
    assert summary["selector_options"] == {"preset": "safe", "margin": 0.01, "reciprocal": False}
    with pytest.raises(ValueError, match="selector_options.corrections"):
        Method(selector_options=(("corrections", ["bogus"]),))
    kept = Method(selector_options=(("corrections", frozenset({"tg_range"})),))
    assert kept.selector_options == (("corrections", ["tg_range"]),)  # JSON: rows, files


def test_horizon_sensing_is_each_encounter_s_own_sensing_horizon():
    """horizon=sensing (``vo3d sweep --swarm``) resolves per encounter and per vehicle: the
    encounter's sensing range over twice the vehicle's own top speed. A pair encounter whose
    vehicles share one top speed flies as its scenario with that horizon given as a number
    (the pair family's speeds differ between encounters, so the horizons do)."""
    method = Method(selector_options=(("horizon", "sensing"),))
    horizons = set()
    for index in range(2):
        sc = scenario_from_dict(make_encounter("pair", 0, index).scenario)
        top = float(max(sc.max_speed))
        sc = scenario_variant(sc, agents=[{**a, "max_speed": top} for a in
                                          sc.model_dump(exclude_none=True)["agents"]])
        horizons.add(sc.sensing_horizon)
        resolved = scenario_selector(scenario_variant(sc, selector_options={"horizon": "sensing"}))
        for v in (top, 0.5 * top):
            want = sc.sensing.vehicle_range / (2.0 * v)
            assert resolved[0].options_for(v, sc.dt).horizon == want
        _, by_sensing = fly(sc, method)
        assert by_sensing["selector_options"] == {"preset": "safe", "horizon": "sensing"}
        _, summary = fly(sc, Method(selector_options=(("horizon", sc.sensing_horizon),)))
        for key in ("min_vehicle_distance", "steps", "pz_intrusions", "time"):
            assert summary[key] == by_sensing[key], (index, key)
    assert len(horizons) == 2
    # a failure scenario carries horizon: sensing and replays with its own horizon
    result = SweepResult(family=FAMILIES["pair"], seed=0, method=method, rows=pd.DataFrame())
    data = failure_scenario(result, 1)
    assert data["selector_options"] == {"horizon": "sensing"}
    replay = scenario_from_dict(data)
    top = float(max(replay.max_speed))
    assert scenario_selector(replay)[0].options_for(top, replay.dt).horizon == replay.sensing_horizon
    assert run_encounter("pair", 0, 1, method)["error"] is None


# ------------------------------------------------- group variants (real-world keys)

FAMILIES_WITH_KEYS = ("intruder", "rotorpy", "noisy")
#: The scenario keys each family adds to its ``group`` draw (removed, the rest is a group scenario).
ADDED_KEYS = {"lagged": ("dynamics",), "rotorpy": ("dynamics", "wind")}


def first_draw(name: str, seed: int, index: int) -> Draw:
    """The first draw the family's generator keeps from the stream of (seed, index), before
    the loader's checks (which need the added keys for some families)."""
    rng = encounter_rng(seed, index)
    return next(d for d in iter(lambda: FAMILIES[name].generate(rng), 0) if d is not None)


def without_added_keys(name: str, scenario: dict) -> dict:
    """The draw with the keys the variant adds removed (a plain group scenario)."""
    data = {k: v for k, v in scenario.items() if k not in ADDED_KEYS.get(name, ())}
    data["sensing"] = {k: scenario["sensing"][k] for k in ("vehicle_range", "obstacle_range")}
    data["agents"] = [{k: v for k, v in a.items() if k != "avoids"} for a in scenario["agents"]]
    return data


@pytest.mark.parametrize("name", ["lagged", *FAMILIES_WITH_KEYS])
def test_group_variants_are_deterministic_and_sound_group_scenarios(name):
    for index in range(12):
        a, b = first_draw(name, 4, index), first_draw(name, 4, index)
        assert a == b  # per (seed, index) alone
        assert a.scenario != first_draw(name, 5, index).scenario
        data = {"name": f"{name}-{index}", **without_added_keys(name, a.scenario)}
        sc = scenario_from_dict(data)  # this build's loader takes the rest
        assert 3 <= sc.n_agents - (name == "intruder") <= 8
        assert len(sc.obstacles) <= 6
        json.dumps(a.scenario)  # plain data: written to YAML as it is


def test_lagged_draws_tau_in_its_range_and_runs():
    taus = [first_draw("lagged", 1, i).scenario["dynamics"]["tau"] for i in range(60)]
    assert 0.1 <= min(taus) and max(taus) <= 1.0 and max(taus) - min(taus) > 0.5
    enc = make_encounter("lagged", 1, 0)
    dyn = enc.load().vehicle_dynamics
    assert dyn.model == "first_order" and dyn.tau == enc.params["tau"]


def test_intruder_adds_one_non_avoiding_uav_clear_of_the_obstacles():
    from vo3d_opt.generators.families import PRISM_CLEARANCE, _prism_half_side

    for index in range(30):
        draw = first_draw("intruder", 2, index)
        agents = draw.scenario["agents"]
        x = agents[-1]
        assert x["id"] == "x0" and x["avoids"] is False
        assert all("avoids" not in a for a in agents[:-1])
        assert 1.0 <= x["max_speed"] <= 4.0 and 5.0 <= x["r_pz"] <= 10.0
        assert x["max_speed"] == pytest.approx(draw.params["intruder_speed"], abs=1e-6)
        start, goal = np.array(x["start"]), np.array(x["goal"])
        assert draw.scenario["max_time"] >= TIME_FACTOR * np.linalg.norm(goal - start) \
            / x["max_speed"] + TIME_SLACK - 1e-9
        track = start[:2] + np.linspace(0.0, 1.0, 2001)[:, None] * (goal - start)[:2]
        for ob in draw.scenario["obstacles"]:  # its straight track misses every prism
            gap = np.linalg.norm(track - np.asarray(ob["center"]), axis=1).min()
            assert gap >= _prism_half_side(ob) + PRISM_CLEARANCE - 1e-3


def test_rotorpy_draws_hummingbird_in_constant_or_dryden_wind():
    draws = [first_draw("rotorpy", 3, i) for i in range(60)]
    batched = {"model": "rotorpy", "vehicle": "hummingbird", "batched": True}
    assert all(d.scenario["dynamics"] == batched for d in draws)
    winds = [d.scenario["wind"] for d in draws]
    assert {w["type"] for w in winds} == {"constant", "dryden"}
    speeds = [np.linalg.norm(w["velocity"]) for w in winds]
    assert max(speeds) <= 3.0 + 1e-3 and max(speeds) > 2.0
    assert all(w["velocity"][2] == 0.0 for w in winds)
    assert all(d.params["wind_speed"] == pytest.approx(s, abs=1e-3)
               for d, s in zip(draws, speeds, strict=True))


def test_noisy_draws_sensing_noise_latency_and_seed():
    draws = [first_draw("noisy", 6, i) for i in range(60)]
    sensing = [d.scenario["sensing"] for d in draws]
    assert all(s["vehicle_range"] == 55.0 and s["obstacle_range"] == 55.0 for s in sensing)
    assert all(0.0 <= s["position_noise"] <= 0.5 and 0.0 <= s["velocity_noise"] <= 0.3
               for s in sensing)
    assert {s["latency"] for s in sensing} == {0.0, 0.2, 0.4}  # whole steps of dt = 0.2 s
    assert all(isinstance(s["seed"], int) and s["seed"] >= 0 for s in sensing)
    assert len({s["seed"] for s in sensing}) == len(sensing)


@pytest.mark.parametrize("name", FAMILIES_WITH_KEYS)
def test_families_with_keys_run_or_are_refused_naming_them(name):
    fam = FAMILIES[name]
    missing = fam.missing_keys()
    if missing:  # a loader without the added keys: refused before any cluster starts
        with pytest.raises(SweepError, match=f"{name!r} needs the scenario keys "
                                             f"{missing[0]}"):
            run_sweep(name, 1)
    else:
        assert encounter_problems(make_encounter(name, 0, 0).scenario) == []


def test_encounters_that_do_not_arrive_are_written_as_failures_too(tmp_path):
    """A crossing with too little time (every agent short of its goal, nothing else wrong)."""
    def generate(rng: np.random.Generator) -> Draw:
        draw = _crossing(rng, vehicle_range=55.0)
        return Draw(params=draw.params, scenario={**draw.scenario, "max_time": 4.0})

    late = Family(name="late", summary="test", obstacle_free=True, generate=generate)
    rows = pd.DataFrame([run_encounter(late, 0, i) for i in range(2)])
    assert (rows["reached"] == 0).all() and (rows["collisions"] == 0).all()
    assert (rows["pz_intrusions"] == 0).all()
    written = write_results(SweepResult(family=late, seed=0, method=Method(), rows=rows), tmp_path)
    failures = sorted((tmp_path / "failures").glob("*.yaml"))
    assert [p.name for p in failures] == ["late-s0-i0.yaml", "late-s0-i1.yaml"]
    assert set(failures) <= set(written)
    assert "reached 0 of 2" in failures[0].read_text().splitlines()[0]
    assert load_scenario(failures[0]).max_time == 4.0


# ------------------------------------------------ without avoidance, and risk ratios


def test_method_none_flies_the_planned_miss_distance_and_replays():
    from vo3d_opt.sweep.flight import without_avoidance

    for index in range(4):
        row = run_encounter("pair", 5, index, Method(name="none"))
        assert row["error"] is None and (row["formulation"], row["solver"]) == ("none", "none")
        assert row["decisions"] == 0 and row["selector_options"] == "null"
        enc = make_encounter("pair", 5, index)
        assert row["min_vehicle_distance"] == pytest.approx(enc.params["miss_distance"], abs=0.01)
        # the encounter with nobody avoiding, as the failure files hold it, flies the same
        _, summary = fly(scenario_from_dict(without_avoidance(enc.scenario)), DEFAULT_METHOD)
        assert summary["min_vehicle_distance"] == row["min_vehicle_distance"]
        assert summary["pz_intrusions"] == row["pz_intrusions"]
    with pytest.raises(SweepError, match="not used by --method none"):
        run_sweep("pair", 2, method=Method(name="none", selector_options=(("margin", 0.1),)))


def _koopman_chi2(theta: float, x1: int, n1: int, x2: int, n2: int) -> float:
    """Koopman's score statistic for H0: p1 = theta p2, its restricted MLE found numerically
    (brute force, not the closed form statsmodels uses)."""
    from scipy.optimize import minimize_scalar

    def nll(p2: float) -> float:
        p1 = theta * p2
        eps = 1e-300
        return -(x1 * np.log(p1 + eps) + (n1 - x1) * np.log(1 - p1 + eps)
                 + x2 * np.log(p2 + eps) + (n2 - x2) * np.log(1 - p2 + eps))

    hi = min(1.0, 1.0 / theta) if theta > 0 else 1.0
    p2 = minimize_scalar(nll, bounds=(1e-12, hi - 1e-12), method="bounded",
                         options={"xatol": 1e-14}).x
    p1 = theta * p2
    return (x1 - n1 * p1) ** 2 / (n1 * p1 * (1 - p1)) + (x2 - n2 * p2) ** 2 / (n2 * p2 * (1 - p2))


def test_risk_ratio_is_koopman_score_interval():
    from vo3d_opt.sweep.stats import risk_ratio, risk_ratios

    for x1, n1, x2, n2 in [(3, 1000, 150, 1000), (10, 400, 60, 400), (0, 1000, 40, 1000)]:
        r = risk_ratio(x1, n1, x2, n2)
        assert r["ratio"] == pytest.approx((x1 / n1) / (x2 / n2))
        lo, hi = r["ci95"]
        assert _koopman_chi2(hi, x1, n1, x2, n2) == pytest.approx(3.841459, rel=2e-3)
        if x1:
            assert _koopman_chi2(lo, x1, n1, x2, n2) == pytest.approx(3.841459, rel=2e-3)
        else:
            assert lo == 0.0 and r["ratio"] == 0.0
        assert lo <= r["ratio"] <= r["upper95"] < hi  # one-sided bound inside the two-sided
    assert risk_ratio(0, 10, 0, 10)["ratio"] is None  # nothing to reduce
    summary = {"family": "pair", "seed": 0, "encounters": 10, "method": "vo3d",
               "rates": {"collision": {"events": 0, "encounters": 10},
                         "intrusion": {"events": 1, "encounters": 10}}}
    without = {**summary, "method": "none",
               "rates": {"collision": {"events": 2, "encounters": 10},
                         "intrusion": {"events": 5, "encounters": 10}}}
    assert risk_ratios(summary, without)["intrusion"]["ratio"] == pytest.approx(0.2)
    with pytest.raises(ValueError, match="seed: 1 there, 0 here"):
        risk_ratios(summary, {**without, "seed": 1})


def test_sweep_against_a_sweep_without_avoidance(cluster, tmp_path):
    plain, ours = tmp_path / "none", tmp_path / "vo3d"
    proc = vo3d("sweep", "pair", "--n", "6", "--scheduler", cluster, "--method", "none",
                "--out", plain, "--json")
    assert proc.returncode == 0, proc.stderr
    base = json.loads(proc.stdout)
    assert base["method"] == "none" and base["encounters_with_intrusion"] > 0
    assert len(list((plain / "failures").glob("*.yaml"))) == base["encounters_with_intrusion"]
    proc = vo3d("sweep", "pair", "--n", "6", "--scheduler", cluster, "--out", ours, "--json",
                "--against", plain)
    assert proc.returncode == 0, proc.stderr
    ratios = json.loads(proc.stdout)["risk_ratios"]
    assert ratios["intrusion"]["events_without_avoidance"] == base["encounters_with_intrusion"]
    assert ratios["intrusion"]["ratio"] == 0.0 and ratios["intrusion"]["ci95"][0] == 0.0
    assert json.loads((ours / "summary.json").read_text())["risk_ratios"] == ratios
    bad = vo3d("sweep", "pair", "--n", "7", "--scheduler", cluster, "--against", plain)
    assert bad.returncode == 2 and "--against" in bad.stderr and "encounters 6, not 7" in bad.stderr
