"""Hostile and careless input: a file from elsewhere, a mistyped option, a huge number or a
Ctrl-C never hangs the machine, exhausts its memory, reads a number wrong or leaves output that
looks complete and is not. Each reproducer runs the real command line under a memory limit and
a timeout (a guard against a hang, not a measure of speed)."""

from __future__ import annotations

import json
import os
import resource
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from test_cli import SMALL
from vo3d_opt import AgentState, Limits, Neighbor, VelocitySelector
from vo3d_opt.sim.scenario import ScenarioError, load_scenario, scenario_from_dict
from vo3d_opt.sim.scenario.reading import MAX_BYTES, MAX_DEPTH, YAMLProblem, parse

VO3D = Path(sys.executable).with_name("vo3d")
#: Address space a refused input may take (bytes): the package's imports and nothing more.
MEMORY_LIMIT = 3 * 2**30
TIMEOUT = 120


def _limited() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))


def vo3d(*args: str | Path, timeout: float = TIMEOUT) -> subprocess.CompletedProcess:
    """``vo3d ARGS`` in a process that may take at most :data:`MEMORY_LIMIT` of memory."""
    return subprocess.run(
        [str(VO3D), *map(str, args)],
        capture_output=True,
        text=True,
        timeout=timeout,
        preexec_fn=_limited,
    )


def refused(res: subprocess.CompletedProcess, *fragments: str) -> str:
    """The one line of an exit-2 refusal, checked to name each fragment."""
    assert res.returncode == 2, (res.returncode, res.stderr[-2000:])
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in res.stderr, res.stderr[-2000:]
    for fragment in fragments:
        assert fragment in lines[0], lines[0]
    return lines[0]


def scenario_file(tmp_path: Path, text: str, name: str = "s.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def small_with(**keys: object) -> dict:
    return {**SMALL, **keys}


# ------------------------------------------------------------------------ the YAML of a file

ALIAS_BOMB = "l0: &l0 [x, x, x, x, x, x, x, x, x, x]\n" + "".join(
    f"l{k}: &l{k} [{', '.join([f'*l{k - 1}'] * 10)}]\n" for k in range(1, 10)
)


def test_an_alias_bomb_is_refused_at_once_in_a_file_and_on_the_command_line(tmp_path):
    bomb = scenario_file(tmp_path, ALIAS_BOMB + "name: *l9\n")
    assert bomb.stat().st_size < 2000
    refused(vo3d("run", bomb), str(bomb), "aliases")
    option = "horizon=" + "{" + ALIAS_BOMB.replace("\n", ", ").rstrip(", ") + ", h: *l9}"
    refused(vo3d("run", scenario_file(tmp_path, yaml.safe_dump(SMALL), "ok.yaml"), "-o", option),
            "selector_options.horizon", "aliases")


@pytest.mark.parametrize("text, key, value", [
    ("start: [-020, 0, 20]", "start", -20),  # YAML 1.1: octal, -16
    ("start: [0o17, 0, 20]", "start", 15),  # YAML 1.2's octal
    ("start: [1e1, 0, 20]", "start", 10.0),
])
def test_numbers_are_read_as_yaml_1_2_reads_them(text, key, value):
    assert parse(text)[key][0] == value


@pytest.mark.parametrize("key, text", [
    ("max_time", "1:30"),  # YAML 1.1: sexagesimal, 90
    ("max_time", "0b101"),  # YAML 1.1: binary, 5
    ("dt", "0x"),
])
def test_yaml_1_1_number_forms_are_refused_naming_the_key(tmp_path, key, text):
    data = yaml.safe_dump(SMALL).replace(f"{key}: ", f"{key}: {text} #", 1)
    line = refused(vo3d("run", scenario_file(tmp_path, data)), key)
    assert "number" in line


def test_booleans_are_true_and_false_only(tmp_path):
    agents = [dict(a, avoids="no") for a in SMALL["agents"]]
    with pytest.raises(ScenarioError, match=r"agents\[0\]\.avoids"):
        scenario_from_dict(parse(yaml.safe_dump(small_with(agents=agents)).replace("'no'", "no")))


def test_deep_nesting_is_refused_in_a_file_and_on_the_command_line(tmp_path):
    deep = "[" * 1000 + "]" * 1000
    refused(vo3d("run", scenario_file(tmp_path, f"name: {deep}\n")), "nest")
    small = scenario_file(tmp_path, yaml.safe_dump(SMALL), "ok.yaml")
    refused(vo3d("run", small, "-o", f"margin={deep}"), "selector_options.margin", "nested")
    with pytest.raises(YAMLProblem, match=f"deeper than {MAX_DEPTH}"):
        parse("a: " + "[" * (MAX_DEPTH + 1) + "]" * (MAX_DEPTH + 1))


def test_duplicate_keys_are_found_among_many_in_linear_time(tmp_path):
    keys = "".join(f"  k{i}: {i}\n" for i in range(32_000))
    with pytest.raises(YAMLProblem, match="duplicate key 'k7'"):
        parse("a:\n" + keys + "  k7: 0\n")
    line = refused(vo3d("run", scenario_file(tmp_path, "selector_options:\n" + keys)))
    assert "selector_options.k0: unknown key" in line


def test_merge_keys_are_read_as_yaml_defines_them(tmp_path):
    text = yaml.safe_dump(small_with(agents=[])).replace("agents: []", "")
    text += "base: &base {goal: [10.0, 0.0, 20.0]}\n"
    data = parse(text.replace("base: &base", "x-base: &base") + "agents:\n"
                 "  - {<<: *base, id: a, start: [0.0, 0.0, 20.0]}\n"
                 "  - {<<: *base, id: b, start: [20.0, 0.0, 20.0], goal: [-10.0, 0.0, 20.0]}\n")
    assert data["agents"][0]["goal"] == [10.0, 0.0, 20.0]
    assert data["agents"][1]["goal"] == [-10.0, 0.0, 20.0]


def test_a_huge_or_endless_file_is_not_read_whole(tmp_path):
    refused(vo3d("run", "/dev/zero"), "/dev/zero", "larger than")
    big = tmp_path / "big.yaml"
    with big.open("wb") as fh:
        fh.truncate(MAX_BYTES + 1)
    refused(vo3d("run", big), "larger than")


# ------------------------------------------------------------------------ what a run would take

@pytest.mark.parametrize("keys, key", [
    ({"max_time": 1e9}, "max_time"),
    ({"dt": 1e-5, "max_time": 1e3}, "max_time"),
    ({"sensing": {"vehicle_range": 55.0, "obstacle_range": 55.0, "latency": 1e6}},
     "sensing.latency"),
    ({"dynamics": {"model": "rotorpy", "substep_rate": 1e9}}, "dynamics.substep_rate"),
    ({"dynamics": {"model": "rotorpy"}, "wind": {"type": "constant", "velocity": [1e300, 0, 0]}},
     "wind.velocity"),
])
def test_a_run_beyond_bounds_is_refused_at_load_naming_the_key(tmp_path, keys, key):
    refused(vo3d("run", scenario_file(tmp_path, yaml.safe_dump(small_with(**keys)))), key)


def test_a_run_beyond_the_machine_is_refused_before_anything_is_reserved(tmp_path):
    agents = [{"id": f"a{i}", "start": [30.0 * i, 0.0, 20.0], "goal": [30.0 * i, 90.0, 20.0]}
              for i in range(2000)]
    data = small_with(agents=agents, max_time=1.9e6, obstacles=[])
    refused(vo3d("run", scenario_file(tmp_path, yaml.safe_dump(data))), "max_time", "GiB")


@pytest.mark.parametrize("value", ["1e309", str(10**400), "1e300"])
def test_numbers_beyond_range_are_one_line_naming_the_key(tmp_path, value):
    text = yaml.safe_dump(small_with(obstacles=[{"type": "cylinder", "center": [0.0, 30.0],
                                                 "radius": 2.0, "height": 30.0}]))
    text = text.replace("- 0.0\n  - 30.0", f"- {value}\n  - 30.0", 1)
    refused(vo3d("run", scenario_file(tmp_path, text)), "obstacles[0].center")


# ------------------------------------------------------------------------ options and arguments

@pytest.mark.parametrize("option, key", [
    ("qp_samples=1000000000", "qp_samples"),
    ("plane_step_deg=1e-9", "plane_step_deg"),
    ("plane_step_deg=0.001", "plane_step_deg"),
    ("n_samples=100000000", "n_samples"),
    ("polygon_sides=100000000", "polygon_sides"),
    ("speed_levels=100000", "speed_levels"),
    ("horizon=1e300", "horizon"),
])
def test_every_option_has_a_range(tmp_path, option, key):
    small = scenario_file(tmp_path, yaml.safe_dump(SMALL))
    refused(vo3d("run", small, "-o", option), f"selector_options.{key}")
    with pytest.raises(ValueError, match=rf"^{key}: "):
        VelocitySelector(**{key: yaml.safe_load(option.partition("=")[2])})


def test_command_line_numbers_and_addresses_are_checked(tmp_path):
    small = scenario_file(tmp_path, yaml.safe_dump(SMALL))
    res = vo3d("run", small, "--json", "-q", "--max-neighbors", str(2**63))
    assert res.returncode == 0 and json.loads(res.stdout)["agents"] == 2, res.stderr
    refused(vo3d("sweep", "pair", "--n", "2", "--scheduler", "ucx://127.0.0.1:1"), "--scheduler")
    refused(vo3d("sweep", "pair", "--n", "2", "--scheduler", "tcp://[::1"), "--scheduler")
    refused(vo3d("sweep", "pair", "--n", "2", "--scheduler", "tcp://127.0.0.1:70000"),
            "--scheduler", "PORT 1 to 65535")
    with socket.socket() as s:  # bound, not listening: connections are refused, at once
        s.bind(("127.0.0.1", 0))
        closed = s.getsockname()[1]
        refused(vo3d("sweep", "pair", "--n", "2", "--scheduler", f"tcp://127.0.0.1:{closed}"),
                "--scheduler", "cannot connect")
    refused(vo3d("sweep", "pair", "--n", "0"), "--n", ">= 1")
    refused(vo3d("sweep", "pair", "--n", "2", "--overwrite"), "--overwrite", "--out")
    refused(vo3d("sweep", "pair", "--n", "2", "--out", tmp_path / "o", "--resume",
                 "--overwrite"), "--resume, --overwrite")
    refused(vo3d("run", small, "--out", ""), "--out")


def test_python_integers_beyond_a_float_are_value_errors():
    huge = 2**1100
    sel = VelocitySelector()
    own = AgentState(position=(0.0, 0.0, 10.0))
    with pytest.raises(ValueError, match="^dt: "):
        sel.select(own, (1.0, 0.0, 0.0), dt=huge)
    with pytest.raises(ValueError, match="position"):
        Neighbor(position=(huge, 0, 0), r_pz=1.0)
    with pytest.raises(ValueError, match="speed"):
        Limits(speed=(0.0, huge))
    with pytest.raises(ValueError, match="r_pz"):
        Neighbor(position=(1.0, 0, 0), r_pz=huge)


def test_sampled_memory_is_bounded_whatever_the_number_of_neighbours():
    """The sampled selection tests its grid against the VO shapes in chunks: a crowd of 240
    neighbours once built arrays of about 1.2 GB; its peak stays that of a few chunks, and
    the answer is the one of the whole set (what the chunks' union must give)."""
    import tracemalloc

    from vo3d_opt.formulations import sampled

    rng = np.random.default_rng(7)
    crowd = [Neighbor(position=rng.uniform(-150.0, 150.0, 3) + (0.0, 0.0, 250.0),
                      velocity=rng.uniform(-3.0, 3.0, 3), r_pz=5.0) for _ in range(240)]
    call = dict(own=AgentState(position=(0.0, 0.0, 250.0), velocity=(3.0, 0.0, 0.0)),
                preferred_velocity=(4.0, 0.0, 0.0), neighbors=crowd,
                limits=Limits(speed=(0.0, 5.0), altitude=(0.0, 500.0)), dt=0.2)
    sel = VelocitySelector(formulation="sampled")
    tracemalloc.start()
    try:
        chunked = sel.select(**call)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 150e6, f"peak {peak / 1e6:.0f} MB"
    whole = sampled.CHUNK
    try:
        sampled.CHUNK = 1000  # every shape at once, as one block
        sel_whole = VelocitySelector(formulation="sampled").select(**call)
    finally:
        sampled.CHUNK = whole
    assert np.array_equal(chunked.velocity, sel_whole.velocity)
    assert chunked.status == sel_whole.status


def test_a_sampled_grid_beyond_its_budget_is_refused_when_the_selector_is_made():
    with pytest.raises(ValueError, match="^plane_step_deg, heading_step_deg.*sampled grid"):
        VelocitySelector(formulation="sampled", plane_step_deg=1, n_samples=720)
    VelocitySelector(formulation="plane_qp", plane_step_deg=1, n_samples=720)  # no grid there
    refused(vo3d("run", "paper-case2-two-uav-six-obstacles", "--formulation", "sampled",
                 "-o", "plane_step_deg=1", "-o", "n_samples=720", "-q"), "sampled grid")


# ------------------------------------------------------------------------ output

def test_out_replaces_a_planted_link_and_an_earlier_runs_figures(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    victim = tmp_path / "victim.txt"
    victim.write_text("keep me")
    (out / "summary.json").symlink_to(victim)
    (out / "obstacle_distance.png").write_text("an earlier run's")
    (out / "mine.png").write_text("not ours")
    small = scenario_file(tmp_path, yaml.safe_dump(small_with(obstacles=[])))
    res = vo3d("run", small, "--out", out, "--format", "svg", "-q")
    assert res.returncode == 0, res.stderr
    assert victim.read_text() == "keep me" and not (out / "summary.json").is_symlink()
    assert json.loads((out / "summary.json").read_text())["agents"] == 2
    assert not (out / "obstacle_distance.png").exists() and (out / "mine.png").exists()
    assert sorted(p.suffix for p in out.glob("*_*.*") if p.stem != "mine") == [".svg"] * 3
    assert not list(out.glob(".*"))  # no temporary file left


def test_an_interrupted_write_leaves_no_summary_and_no_half_file(tmp_path, monkeypatch):
    from vo3d_opt import report
    from vo3d_opt.sim.metrics import summarize
    from vo3d_opt.sim.simulator import run_scenario

    record = run_scenario(scenario_from_dict(SMALL), progress=False)
    out = tmp_path / "out"
    report.write_outputs(record, summarize(record), out)
    assert (out / "summary.json").exists()

    def interrupted(record: object, path: Path) -> Path:
        with report.atomic(path) as tmp:
            tmp.write_text("step,time\n0,0\n")
            raise KeyboardInterrupt

    monkeypatch.setattr(report, "write_csv", interrupted)
    with pytest.raises(KeyboardInterrupt):
        report.write_outputs(record, summarize(record), out)
    assert not (out / "summary.json").exists()  # the earlier run's went first
    assert not (out / "trajectories.csv").exists()
    assert not list(out.glob(".*"))


#: When to interrupt a run that writes its output, by what its --out directory holds (names
#: under a temporary name included): as soon as the directory exists (it is made and tried
#: before the run: the simulation), at the first file (the Parquet table being written), once
#: the table is in place (the CSV), at the first figure.
MOMENTS = {
    "simulating": lambda names: True,
    "writing the table": lambda names: bool(names),
    "writing the CSV": lambda names: "trajectories.parquet" in names,
    "drawing": lambda names: any(".png" in name for name in names),
}


def _interrupt_when(out: Path, proc: subprocess.Popen, moment) -> None:
    """SIGINT to the run's process group as soon as ``moment`` holds of ``out`` (or never, if
    the run ends first)."""
    while proc.poll() is None:
        if out.is_dir() and moment(set(os.listdir(out))):
            os.killpg(proc.pid, signal.SIGINT)
            return
        time.sleep(0.002)


def test_ctrl_c_of_a_run_writing_its_output_leaves_it_complete_or_visibly_not(tmp_path):
    """SIGINT at several moments of a run of 1,000 agents that writes its output: the
    directory then holds either everything with its summary, or no summary and no half
    file under a final name."""
    seen = set()
    for name, moment in MOMENTS.items():
        out = tmp_path / name.replace(" ", "-")
        proc = subprocess.Popen(
            [str(VO3D), "run", "random-crossing-1000", "--out", str(out), "-q"],
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
            start_new_session=True,
        )
        _interrupt_when(out, proc, moment)
        _, err = proc.communicate(timeout=TIMEOUT)
        assert "Traceback" not in err, (name, err[-2000:])
        names = {p.name for p in out.glob("*")} if out.exists() else set()
        # a SIGINT while the interpreter shuts down, everything written, ends it by the signal
        late = "summary.json" in names and proc.returncode == -signal.SIGINT
        assert proc.returncode in (0, 130) or late, (name, proc.returncode, err)
        assert not any(name.startswith(".") for name in names), names
        if "summary.json" in names:
            import pandas as pd

            summary = json.loads((out / "summary.json").read_text())
            rows = len(pd.read_parquet(out / "trajectories.parquet"))
            assert rows == summary["agents"] * (summary["steps"] + 1)
        seen.add("summary.json" in names)
    assert False in seen  # some interrupt came before the end


def test_ctrl_c_of_a_sweep_exits_130_without_tracebacks(tmp_path):
    out = tmp_path / "sweep"
    proc = subprocess.Popen(
        [str(VO3D), "sweep", "pair", "--n", "5000", "--workers", "2", "--no-progress",
         "--out", str(out), "--flush-every", "0.2"],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, start_new_session=True,
    )
    # once the sweep flies (its first rows kept), not while its cluster starts
    _interrupt_when(out, proc, lambda names: "parts" in names and bool(os.listdir(out / "parts")))
    _, err = proc.communicate(timeout=TIMEOUT)
    assert proc.returncode == 130, err[-2000:]
    last = err.strip().splitlines()[-1]
    assert "Traceback" not in err and last.startswith("vo3d: interrupted"), err
    assert str(out) in last and "--resume" in last  # where the rows are, and how to go on
    assert not (tmp_path / "sweep" / "summary.json").exists()


# ------------------------------------------------------------------------ the library

def test_a_scenario_loads_or_is_one_line_naming_the_key(tmp_path):
    """Every key of a valid scenario replaced by values of the wrong kind: a ScenarioError of
    one line naming the file, never another exception."""
    path = scenario_file(tmp_path, yaml.safe_dump(SMALL))
    base = load_scenario(path)
    assert base.n_agents == 2
    wrong = [None, True, "x", [], {}, -1, 0, 1e300, [1.0], {"a": 1}, 2**64]
    for key in SMALL:
        for value in wrong:
            data = {**SMALL, key: value}
            try:
                scenario_from_dict(data, str(path))
            except ScenarioError as exc:
                text = str(exc)
                assert "\n" not in text and text.startswith(str(path)), text


# ------------------------------------------------------------------------ property-based fuzzing

from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

FUZZ = settings(max_examples=150, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.too_slow])
#: Numbers a careless caller passes: fine ones, zero, negative, NaN, infinities, huge floats
#: and ints, booleans, text, complex numbers, None.
ANY_NUMBER = st.one_of(
    st.floats(-60.0, 60.0), st.just(0.0), st.floats(allow_nan=True, allow_infinity=True),
    st.integers(-(2**70), 2**1100), st.booleans(), st.text(max_size=3),
    st.complex_numbers(max_magnitude=10), st.none(),
)
VECTOR = st.one_of(
    st.lists(ANY_NUMBER, min_size=0, max_size=4),
    st.lists(st.floats(-60.0, 60.0), min_size=3, max_size=3),
    st.just(np.array([1.0, 2.0, 3.0])), st.just(np.array([1, 2, 3], dtype=complex)),
    st.just(np.array([True, False, True])), st.just("1,2,3"),
)


@FUZZ
@given(position=VECTOR, velocity=VECTOR, preferred=VECTOR, r_pz=ANY_NUMBER, dt=ANY_NUMBER,
       speed=st.lists(ANY_NUMBER, min_size=2, max_size=2))
def test_select_answers_or_names_the_bad_field(position, velocity, preferred, r_pz, dt, speed):
    """Whatever the input: a decision within the limits, or one ValueError line."""
    try:
        own = AgentState(position=(0.0, 0.0, 20.0), velocity=velocity)
        nbr = Neighbor(position=position, velocity=(0.0, 0.0, 0.0), r_pz=r_pz)
        limits = Limits(speed=speed, altitude=(0.0, 40.0))
        d = VelocitySelector().select(own, preferred, [nbr], [], limits, dt)
    except ValueError as exc:
        assert "\n" not in str(exc) and ":" in str(exc)
        return
    assert np.all(np.isfinite(d.velocity)) and np.linalg.norm(d.velocity) <= limits.v_max + 1e-6
    z = 20.0 + d.velocity[2] * dt
    assert -1e-6 <= z <= 40.0 + 1e-6


ARRAY = st.one_of(
    st.just(np.zeros((3, 3))), st.just(np.ones((3, 3), dtype=bool)),
    st.just(np.ones((3, 3), dtype=complex)), st.just(np.full((3, 3), "1")),
    st.just(np.full((3, 3), np.nan)), st.just(np.zeros((3, 2))), st.just([[1, 2, 3]] * 3),
    st.just([[2**1100, 0, 0]] * 3), st.just(np.full((3, 3), 1e300)), st.none(),
    st.lists(st.lists(st.floats(-50, 50), min_size=3, max_size=3), min_size=3, max_size=3),
)


@FUZZ
@given(positions=ARRAY, velocities=ARRAY, r_pz=ANY_NUMBER, dt=ANY_NUMBER,
       sensing=ANY_NUMBER, k=st.one_of(st.none(), st.integers(-3, 2**64), st.booleans()))
def test_select_many_answers_or_names_the_bad_argument(positions, velocities, r_pz, dt, sensing, k):
    """``select_many`` refuses what ``select`` refuses: strings, booleans, complex numbers,
    huge numbers, wrong shapes; a ValueError naming the argument, never another exception."""
    good = np.array([[0.0, 0.0, 20.0], [30.0, 0.0, 20.0], [0.0, 30.0, 20.0]])
    try:
        out = VelocitySelector().select_many(
            positions if positions is not None else good, velocities, np.zeros((3, 3)), r_pz,
            dt=dt, sensing_range=sensing, max_neighbors=k,
        )
    except ValueError as exc:
        assert "\n" not in str(exc) and ":" in str(exc)
        return
    assert np.all(np.isfinite(out.velocities))
