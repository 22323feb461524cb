"""The ``vo3d`` command line and its JSON summary, run as a separate process like a user would; the
tests that compare the flights of equivalent options call its ``main`` in this process (the
``here`` fixture: the same code without a process's start each time)."""
from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from vo3d_opt.sim.metrics import CONTRACT_KEYS
from vo3d_opt.sim.safety import derive_margins
from vo3d_opt.sim.scenario import bundled_files, load_scenario, scenario_variant
from vo3d_opt.sim.simulator import scenario_selector

SMALL = {
    "name": "cli-small",
    "description": "Two UAVs head-on past a cylinder. Small enough for the CLI tests.",
    "dt": 0.2,
    "max_time": 14.0,
    "goal_tolerance": 1.0,
    "limits": {"speed": [0.0, 4.0], "altitude": [0.0, 40.0]},
    "sensing": {"vehicle_range": 55.0, "obstacle_range": 55.0},
    "defaults": {"r_pz": 5.0, "radius": 0.5, "max_speed": 4.0},
    "agents": [
        {"id": "u0", "start": [-20.0, 0.0, 20.0], "goal": [20.0, 0.0, 20.0]},
        {"id": "u1", "start": [20.0, 0.5, 20.0], "goal": [-20.0, 0.5, 20.0]},
    ],
    "obstacles": [{"type": "cylinder", "center": [0.0, 9.0], "radius": 1.5, "height": 30.0}],
}


def vo3d(*args: str | Path, cwd: Path | None = None) -> subprocess.CompletedProcess:
    script = Path(sys.executable).with_name("vo3d")
    cmd = [str(script)] if script.exists() else [sys.executable, "-m", "vo3d_opt.cli"]
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}
    return subprocess.run(cmd + [str(a) for a in args], capture_output=True, text=True,
                          timeout=600, cwd=cwd, env=env)


@pytest.fixture(scope="module")
def small(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("cli") / "small.yaml"
    path.write_text(yaml.safe_dump(SMALL, sort_keys=False))
    return path


@pytest.fixture(scope="module")
def run_json(small) -> subprocess.CompletedProcess:
    return vo3d("run", small, "--json")


def test_run_json_prints_exactly_one_object_with_the_contract_keys(run_json):
    assert run_json.returncode == 0, run_json.stderr
    out = run_json.stdout.strip()
    assert out.startswith("{") and out.count("\n") == 0, out[:500]
    summary = json.loads(out)
    assert set(CONTRACT_KEYS) <= set(summary)
    assert summary["scenario"] == "cli-small" and summary["formulation"] == "plane_qp"
    assert isinstance(summary["solver"], str) and summary["solver"]
    assert summary["agents"] == 2 and summary["steps"] > 0
    assert summary["time"] == pytest.approx(summary["steps"] * 0.2)
    for key in ("reached", "pz_intrusions", "collisions", "altitude_violations",
                "speed_violations", "fallbacks", "steps", "agents"):
        assert isinstance(summary[key], int) and not isinstance(summary[key], bool), key
    assert isinstance(summary["all_reached"], bool)
    for key in ("min_vehicle_distance", "min_obstacle_distance", "decision_time_median_us",
                "decision_time_p99_us"):
        assert isinstance(summary[key], float) and summary[key] >= 0.0, key
    assert "running cli-small" in run_json.stderr  # logs go to stderr


def test_run_prints_a_table_by_default(small):
    res = vo3d("run", small, "--formulation", "sampled")
    assert res.returncode == 0, res.stderr
    lines = dict(line.split(None, 1) for line in res.stdout.strip().splitlines())
    assert set(CONTRACT_KEYS) <= set(lines)
    assert lines["formulation"].strip() == "sampled"


def test_run_accepts_a_bundled_name():
    res = vo3d("run", "paper-flight-test", "--json")
    assert res.returncode == 0, res.stderr
    summary = json.loads(res.stdout)
    assert summary["scenario"] == "paper-flight-test" and summary["min_vehicle_distance"] is None


def test_run_out_writes_csv_summary_and_plots(small, tmp_path):
    out = tmp_path / "out"
    res = vo3d("run", small, "--solver", "osqp", "--json", "--out", out)
    assert res.returncode == 0, res.stderr
    summary = json.loads(res.stdout)
    assert json.loads((out / "summary.json").read_text()) == summary
    with (out / "trajectories.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == (summary["steps"] + 1) * 2
    assert {"step", "time", "agent", "x", "y", "z", "vx", "vy", "vz", "status"} <= set(rows[0])
    for name in ("trajectories_3d.png", "top_view.png", "vehicle_distance.png",
                 "obstacle_distance.png"):
        data = (out / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 5000, name


@pytest.mark.parametrize(
    "mutation, fragment",
    [
        pytest.param({"spead": 3.0}, "spead", id="unknown-key"),
        pytest.param({"dt": -1.0}, "dt", id="negative-dt"),
        pytest.param({"limits": {"speed": [0.0, 4.0], "altitude": [0.0, 10.0]}},
                     "agents[0].start", id="start-above-ceiling"),
    ],
)
def test_invalid_scenario_exits_2_with_one_line(tmp_path, mutation, fragment):
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump({**SMALL, **mutation}))
    res = vo3d("run", path, "--json")
    assert res.returncode == 2
    assert res.stdout == ""
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and str(path) in lines[0] and fragment in lines[0], res.stderr


def test_unreadable_scenario_exits_2(tmp_path):
    res = vo3d("run", tmp_path / "missing.yaml")
    assert res.returncode == 2 and res.stdout == ""
    assert len(res.stderr.strip().splitlines()) == 1 and "missing.yaml" in res.stderr


@pytest.mark.parametrize(
    "args, fragment",
    [
        pytest.param(["--formulation", "magic"], "magic", id="unknown-formulation"),
        pytest.param(["--solver", "no-such-solver"], "formulation 'plane_qp', solver "
                     "'no-such-solver'", id="unknown-solver"),
    ],
)
def test_unknown_formulation_or_solver_exits_2(small, args, fragment):
    res = vo3d("run", small, "--json", *args)
    assert res.returncode == 2 and res.stdout == ""
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and fragment in lines[0], res.stderr


def test_compare_one_row_per_combination(small):
    res = vo3d("compare", small, "--formulations", "sampled", "plane_qp", "--json")
    assert res.returncode == 0, res.stderr
    rows = json.loads(res.stdout)
    assert [r["formulation"] for r in rows] == ["sampled", "plane_qp"]
    assert all(set(CONTRACT_KEYS) <= set(r) for r in rows)
    table = vo3d("compare", small, "--formulations", "plane_qp", "--solvers", "osqp", "clarabel")
    assert table.returncode == 0, table.stderr
    lines = table.stdout.strip().splitlines()
    assert lines[1].split()[:2] == ["formulation", "solver"] and len(lines) == 4
    assert "min_vehicle_distance" in lines[1]


TIMING_KEYS = {"decision_time_median_us", "decision_time_p99_us", "decision_time_max_us",
               "wall_time"}


def _behaviour(res: subprocess.CompletedProcess, options: dict | None = None) -> dict:
    """The summary but its timing and the options it reports (checked: ``options``)."""
    assert res.returncode == 0, res.stderr
    summary = json.loads(res.stdout)
    if options is not None:
        assert summary["selector_options"] == options
    return {k: v for k, v in summary.items() if k not in TIMING_KEYS | {"selector_options"}}


def test_selector_options_fly_as_the_scenario_key_and_override_it(small, tmp_path, run_json, here):
    unbuffered = {"reciprocal": False, "pz_buffer": 0.0}
    path = tmp_path / "unbuffered.yaml"
    path.write_text(yaml.safe_dump({**SMALL, "selector_options": unbuffered}))
    in_file = _behaviour(here("run", path, "--json"), {"preset": "safe", **unbuffered})
    flags = _behaviour(here("run", small, "--json", "-o", "reciprocal=false",
                            "--selector-option", "pz_buffer=0"), {"preset": "safe", **unbuffered})
    assert flags == in_file
    assert in_file != _behaviour(run_json, {"preset": "safe"})  # the options change the flight
    # -o merges into the file's options (not replacing them): one from each
    half = tmp_path / "half.yaml"
    half.write_text(yaml.safe_dump({**SMALL, "selector_options": {"reciprocal": False}}))
    both = here("run", half, "--json", "-o", "pz_buffer=0")
    assert _behaviour(both, {"preset": "safe", **unbuffered}) == in_file
    # the command line's value wins over the file's: the preset's own values again
    buffer = derive_margins(load_scenario(small)).pz_buffer
    back = here("run", path, "--json", "-o", "reciprocal=true", "-o", f"pz_buffer={buffer!r}")
    back_options = {"preset": "safe", "reciprocal": True, "pz_buffer": buffer}
    assert _behaviour(back, back_options) == _behaviour(run_json)
    res = here("compare", small, "--json", "-o", "reciprocal=false", "-o", "pz_buffer=0")
    assert res.returncode == 0, res.stderr
    (row,) = json.loads(res.stdout)
    assert row["selector_options"] == {"preset": "safe", **unbuffered}
    assert {k: v for k, v in row.items() if k not in TIMING_KEYS | {"selector_options"}} == in_file


#: The fast preset's fields over the safe preset's, as -o takes them.
COARSE = {"plane_step_deg": 45.0, "qp_samples": 12, "heading_step_deg": 45.0, "speed_levels": 3,
          "fallback_heading_step_deg": "null", "fallback_speed_levels": "null",
          "fine_planes": "false"}


def test_fast_is_the_fast_preset_and_fields_override_it(cli, small, here):
    """--fast is --preset fast is -o preset=fast: the safe preset's flight with fast's fields
    given one by one (COARSE); a field given by -o overrides the preset's
    wherever it stands; sweep takes them too (parsed only: its run is the sweep's -o path)."""
    fast = _behaviour(here("run", small, "--json", "--fast"), {"preset": "fast"})
    assert fast == _behaviour(here("run", small, "--json", "--preset", "fast"), {"preset": "fast"})
    assert fast == _behaviour(here("run", small, "--json", "-o", "preset=fast"))
    as_o = [arg for k, v in COARSE.items() for arg in ("-o", f"{k}={v}")]
    assert fast == _behaviour(here("run", small, "--json", *as_o))
    for order in (["--fast", "-o", "qp_samples=36"], ["-o", "qp_samples=36", "--fast"]):
        _behaviour(here("run", small, "--json", *order), {"preset": "fast", "qp_samples": 36})
    args = cli.build_parser().parse_args(["sweep", "pair", "--n", "1", "-o", "margin=0.01", "--fast"])
    assert args.selector_options == [("margin", 0.01), ("preset", "fast")]
    res = here("compare", small, "--json", "--fast")
    assert res.returncode == 0, res.stderr
    (row,) = json.loads(res.stdout)
    assert row["selector_options"] == {"preset": "fast"}
    paper = _behaviour(here("run", small, "--json", "--preset", "paper"), {"preset": "paper"})
    assert paper != _behaviour(here("run", small, "--json"))


def test_swarm_is_fast_with_the_scenarios_sensing_horizon(cli, small, tmp_path, here):
    """--swarm is the swarm preset: fast with horizon "sensing", resolved for each decision to
    the scenario's vehicle sensing range over twice the top speed; the same flight as the number
    given by -o, in a file or on the command line; a later -o overrides it."""
    near = tmp_path / "near.yaml"  # sensing 10 m, 4 m/s: a 1.25 s horizon (6.875 s in small)
    near.write_text(yaml.safe_dump({**SMALL, "sensing": {"vehicle_range": 10.0,
                                                          "obstacle_range": 55.0}}))
    swarm_options = {"preset": "swarm"}
    for path, horizon in ((small, 55.0 / 8.0), (near, 1.25)):
        sc = load_scenario(path)
        assert sc.sensing_horizon == horizon
        resolved = scenario_selector(scenario_variant(sc, selector_options=swarm_options))[0]
        assert resolved.options_for(4.0, sc.dt).horizon == horizon
        swarm = _behaviour(here("run", path, "--json", "--swarm"), swarm_options)
        as_number = here("run", path, "--json", "--fast", "-o", f"horizon={horizon!r}")
        assert swarm == _behaviour(as_number)
    in_file = tmp_path / "in_file.yaml"
    in_file.write_text(yaml.safe_dump({**SMALL, "sensing": {"vehicle_range": 10.0,
                                                             "obstacle_range": 55.0},
                                       "selector_options": swarm_options}))
    assert _behaviour(here("run", in_file, "--json"), swarm_options) == swarm
    # the obstacles keep no horizon; one of 1.25 s drops the cylinder's pyramid until it is
    # 5 m off: another flight
    short = here("run", near, "--json", "--swarm", "-o", "obstacle_horizon=1.25")
    assert swarm != _behaviour(short, {"preset": "swarm", "obstacle_horizon": 1.25})
    later = here("run", near, "--json", "--swarm", "-o", "horizon=3")
    _behaviour(later, {"preset": "swarm", "horizon": 3.0})
    res = here("compare", near, "--json", "--swarm")
    assert res.returncode == 0, res.stderr
    (row,) = json.loads(res.stdout)
    assert row["selector_options"] == swarm_options
    assert {k: v for k, v in row.items() if k not in TIMING_KEYS | {"selector_options"}} == swarm
    args = cli.build_parser().parse_args(["sweep", "pair", "--n", "1", "--swarm", "-o", "margin=0.01"])
    assert args.selector_options == [("preset", "swarm"), ("margin", 0.01)]


@pytest.mark.parametrize(
    "command, option, fragment",
    [
        pytest.param("run", "closing_guard=3", "selector_options.closing_guard", id="bad-value"),
        pytest.param("run", "pz_bufer=1", "selector_options.pz_bufer: unknown key (did you mean "
                     "'pz_buffer'?)", id="unknown-key"),
        pytest.param("run", "margin", "KEY=VALUE", id="no-value"),
        pytest.param("run", "corrections=[tg_range", "selector_options.corrections: line ",
                     id="bad-yaml"),
        pytest.param("compare", "margin=-1", "selector_options.margin", id="compare"),
        pytest.param("run", "horizon=Sensing", "selector_options.horizon: must be a number of "
                     "seconds in (0, 1e6], null or 'sensing', got 'Sensing'", id="horizon-text"),
    ],
)
def test_bad_selector_options_exit_2_naming_the_key(small, command, option, fragment):
    res = vo3d(command, small, "--json", "-o", option)
    assert res.returncode == 2 and res.stdout == ""
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and fragment in lines[0], res.stderr


def test_compare_unknown_name_exits_2(small):
    res = vo3d("compare", small, "--formulations", "plane_qp", "magic")
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1


def test_list_shows_every_bundled_scenario():
    res = vo3d("list")
    assert res.returncode == 0, res.stderr
    assert "warning" not in res.stderr  # a listing; rvo2-sphere-812's close starts warn in a run
    assert any(load_scenario(p).warnings() for p in bundled_files())
    lines = res.stdout.strip().splitlines()
    files = bundled_files()
    assert len(lines) == len(files) + 1
    for path in files:
        sc = load_scenario(path)
        (line,) = [ln for ln in lines if ln.split()[0] == sc.name]
        assert line.split()[1] == str(sc.n_agents)
    listed = json.loads(vo3d("list", "--json").stdout)
    assert {r["name"] for r in listed} == {load_scenario(p).name for p in files}


def test_usage_errors_exit_2():
    res = vo3d("run")
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1


# ---------------------------------------------------------------- bad input: one line, status 2


@pytest.mark.parametrize("kind", ["file", "proc"])
def test_bad_out_path_exits_2_before_the_run(small, tmp_path, kind):
    if kind == "file":
        out = tmp_path / "afile.txt"
        out.write_text("not a directory")
    else:
        out = Path("/proc/x")
    res = vo3d("run", small, "--json", "--out", out)
    assert res.returncode == 2 and res.stdout == "", res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"vo3d: --out {out}"), res.stderr
    assert "running" not in res.stderr  # refused before the simulation


def test_compare_runs_a_solverless_formulation_once(small):
    res = vo3d("compare", small, "--formulations", "sampled", "plane_qp", "--solvers", "osqp",
               "clarabel", "--json")
    assert res.returncode == 0, res.stderr
    rows = json.loads(res.stdout)
    assert [(r["formulation"], r["solver"]) for r in rows] == [
        ("sampled", "none"), ("plane_qp", "osqp"), ("plane_qp", "clarabel")]


def test_json_floats_carry_no_rounding_noise(tmp_path):
    # One UAV arriving at step 156: its arrival time 156 x 0.2 is 31.200000000000003 in binary.
    path = tmp_path / "long.yaml"
    path.write_text(yaml.safe_dump({
        "name": "long", "dt": 0.2, "max_time": 40.0, "limits": {"speed": [0.0, 4.0]},
        "agents": [{"id": "u0", "start": [0.0, 0.0, 20.0], "goal": [125.5, 0.0, 20.0]}],
    }))
    res = vo3d("run", path, "--json", "-q")
    assert res.returncode == 0, res.stderr
    assert 156 * 0.2 != 31.2 and "31.200000000000003" not in res.stdout
    summary = json.loads(res.stdout)
    assert summary["arrival_time_max"] == 31.2 and summary["time"] == 31.2
    assert all(v == float(f"{v:.12g}") for v in summary.values() if isinstance(v, float))


def test_version_and_quiet_and_verbose(small):
    import vo3d_opt

    res = vo3d("--version")
    assert res.returncode == 0 and res.stdout.strip() == f"vo3d {vo3d_opt.__version__}"
    quiet = vo3d("run", "paper-flight-test", "--json", "-q")
    assert quiet.returncode == 0 and quiet.stderr == "" and json.loads(quiet.stdout)
    loud = vo3d("list", "-v")
    assert loud.returncode == 0 and loud.stdout


def test_warnings_go_to_stderr_and_quiet_keeps_them(tmp_path):
    path = tmp_path / "coarse.yaml"
    path.write_text(yaml.safe_dump({**SMALL, "dt": 2.0}))  # 8 m per step, r_pz 5 m
    res = vo3d("run", path, "--json", "-q")
    assert res.returncode == 0, res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 2 and all(ln.startswith("warning: cli-small: u") for ln in lines), lines
    assert json.loads(res.stdout)["scenario"] == "cli-small"


def test_every_option_of_every_subcommand_is_described():
    from vo3d_opt.cli import build_parser
    from vo3d_opt.selector import DEFAULT_QP_SOLVER

    parser = build_parser()
    (sub,) = [a for a in parser._actions if a.choices and isinstance(a.choices, dict)]
    assert set(sub.choices) >= {"run", "compare", "list"}
    for name, subparser in sub.choices.items():
        text = subparser.format_help()  # what `vo3d NAME --help` prints
        for action in subparser._actions:
            assert action.help and action.help.strip(), (name, action.dest)
            for flag in action.option_strings:
                assert flag in text, (name, flag)
    for name in ("run", "compare"):
        text = " ".join(vo3d(name, "--help").stdout.split())  # as a process prints it
        assert text == " ".join(sub.choices[name].format_help().split()), name
        assert f"else {DEFAULT_QP_SOLVER}" in text, name


# ------------------------------------------------------------------ a large swarm's flags
TIMING = {"decision_time_median_us", "decision_time_p99_us", "decision_time_max_us", "wall_time"}


@pytest.fixture
def here(cli, capsys):
    """``vo3d ARGS`` through ``main`` in this process, as a finished process (status, stdout,
    stderr)."""

    def run(*args: str | Path) -> subprocess.CompletedProcess:
        capsys.readouterr()
        code = cli.main([str(a) for a in args])
        out = capsys.readouterr()
        return subprocess.CompletedProcess(list(args), code, out.out, out.err)

    return run


@pytest.fixture
def cli(monkeypatch):
    """``vo3d_opt.cli`` to call ``main`` in this process; the package logger's handlers, level
    and propagation (which ``main`` sets) as they were afterwards."""
    import logging

    from vo3d_opt import cli as module

    logger = logging.getLogger("vo3d_opt")
    monkeypatch.setattr(logger, "handlers", list(logger.handlers))
    monkeypatch.setattr(logger, "propagate", logger.propagate)
    monkeypatch.setattr(logger, "level", logger.level)
    return module


def test_run_hands_threads_neighbours_and_spill_to_the_simulator(cli, small, tmp_path,
                                                                 monkeypatch, capsys, run_json):
    """--threads, --max-neighbors, --spill, --spill-dir reach the simulator and its run; with
    one thread and one neighbour of two vehicles, spilled, the summary is the default run's."""
    from vo3d_opt.cli import flight
    from vo3d_opt.cli import run as run_command
    from vo3d_opt.sim import record as record_module

    seen: dict = {}
    real = flight.Simulator

    class Spy(real):
        def __init__(self, *args, **kwargs):
            seen.update(kwargs)
            super().__init__(*args, **kwargs)

        def run(self, **kwargs):
            seen.update(kwargs)
            record = super().run(**kwargs)
            seen["spilled"] = record.spill is not None
            return record

    monkeypatch.setattr(flight, "Simulator", Spy)
    for module in (run_command, record_module):  # wherever the test's temporary directory is
        monkeypatch.setattr(module, "in_memory_fs", lambda *a, **k: False)
    status = cli.main(["run", str(small), "--json", "--threads", "1", "--max-neighbors", "1",
                       "--spill", "--spill-dir", str(tmp_path)])
    assert status == 0
    assert (seen["threads"], seen["max_neighbors"]) == (1, 1)
    assert (seen["spill"], seen["spill_dir"], seen["spilled"]) == (True, str(tmp_path), True)
    summary, default = json.loads(capsys.readouterr().out), json.loads(run_json.stdout)
    assert {k: v for k, v in summary.items() if k not in TIMING} == {
        k: v for k, v in default.items() if k not in TIMING}


@pytest.mark.parametrize("args, flag", [
    (["--threads", "0"], "--threads"),
    (["--threads", "-1"], "--threads"),
    (["--threads", "9999"], "--threads"),  # above the cores this process may use
    (["--max-neighbors", "two"], "--max-neighbors"),
    (["--spill-dir", "/no/such/dir"], "--spill-dir"),
    (["--no-spill", "--spill-dir", "."], "--spill-dir"),
])
def test_bad_swarm_flags_exit_2_naming_them(small, tmp_path, args, flag):
    out = tmp_path / "out"
    res = vo3d("run", small, "--json", "--out", out, *args)
    assert res.returncode == 2 and res.stdout == "", res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and flag in lines[0], res.stderr
    assert "-1" not in args or ">= 1" in lines[0]
    assert not out.exists()  # refused before --out is made


def test_max_neighbors_needs_noiseless_immediate_sensing(tmp_path):
    noisy = {**SMALL, "sensing": {**SMALL["sensing"], "position_noise": 0.1, "seed": 1}}
    path = tmp_path / "noisy.yaml"
    path.write_text(yaml.safe_dump(noisy, sort_keys=False))
    res = vo3d("run", path, "--json", "--max-neighbors", "3")
    assert res.returncode == 2 and res.stdout == ""
    assert res.stderr.strip() == "vo3d: --max-neighbors: only with noiseless, immediate sensing"


def test_an_unwritable_spill_dir_is_refused_before_the_run(cli, small, tmp_path, monkeypatch,
                                                            capsys):
    from vo3d_opt.cli import run as run_command

    monkeypatch.setattr(run_command, "in_memory_fs", lambda *a, **k: False)
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o500)
    if os.access(locked, os.W_OK):  # root writes anywhere: make the probe fail instead
        def refuse(*args, **kwargs):
            raise PermissionError(13, "Permission denied")
        monkeypatch.setattr(run_command.tempfile, "TemporaryFile", refuse)
    assert cli.main(["run", str(small), "--json", "--spill-dir", str(locked)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("vo3d: --spill-dir: cannot write in "), err


@pytest.mark.parametrize("args", [["--spill"], ["--spill-dir", "."]])
def test_spilling_into_memory_is_refused_before_the_run(cli, small, monkeypatch, capsys, args):
    from vo3d_opt.cli import run as run_command

    monkeypatch.setattr(run_command, "in_memory_fs", lambda *a, **k: True)
    assert cli.main(["run", str(small), "--json", *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"vo3d: {args[0]}: ") and "held in memory" in err[0]
    # --no-spill keeps the record in memory: nothing to refuse
    assert cli.main(["run", str(small), "--json", "--no-spill"]) == 0


def test_a_large_run_deciding_in_python_is_warned_about(cli, small, monkeypatch, capsys):
    from vo3d_opt.cli import flight

    monkeypatch.setattr(flight, "SLOW_SWARM", 2)  # the small scenario's two agents count as many
    assert cli.main(["run", str(small), "--json", "--formulation", "sampled"]) == 0
    assert "warning: sampled / none decides in Python" in capsys.readouterr().err
    assert cli.main(["run", str(small), "--json"]) == 0  # compiled: no warning
    assert "decides in Python" not in capsys.readouterr().err
