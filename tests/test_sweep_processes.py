"""``vo3d sweep`` as real processes: interrupted (Ctrl-C, the client killed, a worker killed
mid-encounter) and resumed, and on a real Dask scheduler with worker processes that come and
go. Every run must end with the rows of the same encounters flown in this process.

Each test starts its own processes and stops every one of them, also when it fails."""
from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import psutil
import pytest

from vo3d_opt.sweep import Method
from vo3d_opt.sweep.flight import run_encounters
from vo3d_opt.sweep.runner import rows_equal
from vo3d_opt.sweep.store import rows_frame

BIN = Path(sys.executable).parent
N, SEED = 240, 5
#: Summary keys that say when, where and how fast, not what.
SITTING_KEYS = {"wall_time", "setup_time", "encounters_per_second", "workers", "scheduler"}


@pytest.fixture(scope="module")
def flown_here() -> dict[str, pd.DataFrame]:
    """The rows of encounters 0..N-1, flown in this process, per method."""
    return {m: rows_frame(run_encounters("pair", SEED, range(N), Method(name=m)))
            for m in ("vo3d", "none")}


class Processes:
    """Processes a test started, all stopped by its finalizer (by pid, group included)."""

    def __init__(self) -> None:
        self.started: list[subprocess.Popen] = []

    def start(self, *args: str | Path, **kw) -> subprocess.Popen:
        env = {**os.environ, "PYTHONWARNINGS": "ignore"}
        proc = subprocess.Popen([str(a) for a in args], stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True, start_new_session=True,
                                env=env, **kw)
        self.started.append(proc)
        return proc

    def stop_all(self) -> None:
        for proc in self.started:
            for sig in (signal.SIGTERM, signal.SIGKILL):
                try:
                    os.killpg(proc.pid, sig)  # its own session: its group is its own
                except ProcessLookupError:
                    break
                try:
                    proc.wait(timeout=10)
                    break
                except subprocess.TimeoutExpired:
                    continue
            for pipe in (proc.stdout, proc.stderr):
                if pipe is not None:
                    pipe.close()


@pytest.fixture
def procs(request):
    p = Processes()
    request.addfinalizer(p.stop_all)
    return p


def sweep_args(out: Path, *extra: str, method: str = "vo3d") -> list[str | Path]:
    return [BIN / "vo3d", "sweep", "pair", "--n", str(N), "--seed", str(SEED), "--method",
            method, "--out", out, "--json", *extra]


def finish(proc: subprocess.Popen, timeout: float = 240) -> tuple[int, str, str]:
    out, err = proc.communicate(timeout=timeout)
    return proc.returncode, out, err


def wait_for_part(out: Path, proc: subprocess.Popen, timeout: float = 120) -> None:
    """Until the sweep has written its first part (it is flying)."""
    end = time.monotonic() + timeout
    while not list((out / "parts").glob("part-*.parquet")):
        if proc.poll() is not None:
            pytest.fail(f"the sweep ended before it could be interrupted: {proc.communicate()}")
        assert time.monotonic() < end, "no part written"
        time.sleep(0.05)


def rows_of(out: Path) -> pd.DataFrame:
    return pd.read_parquet(out / "encounters.parquet")


def files_of(out: Path) -> dict[str, bytes]:
    """Every file under ``out`` but the summary, by relative path, with its bytes."""
    return {str(p.relative_to(out)): p.read_bytes() for p in sorted(out.rglob("*"))
            if p.is_file() and p.name != "summary.json"}


def summary_of(out: Path) -> dict:
    s = json.loads((out / "summary.json").read_text())
    return {k: v for k, v in s.items() if k not in SITTING_KEYS}


def assert_clean_stop(out: Path, killed: bool = False) -> None:
    """Nothing that looks complete: no summary, no table, every part whole, and no file under
    a temporary name (but after a SIGKILL, which no process can clean up after: the part being
    written then stays under its temporary name, hidden, and --resume removes it)."""
    assert not (out / "summary.json").exists() and not (out / "encounters.parquet").exists()
    left = [p for p in out.rglob(".*")]
    if killed:
        assert all(p.parent == out / "parts" and p.name.endswith(".partial") for p in left), left
    else:
        assert not left, "a temporary file was left behind"
    for part in (out / "parts").glob("part-*.parquet"):
        pd.read_parquet(part)  # whole


def test_ctrl_c_then_resume_ends_as_an_uninterrupted_sweep(tmp_path, procs, flown_here):
    """Ctrl-C (SIGINT to the whole process group, as a terminal sends it): exit 130, no
    traceback, the rows flown so far kept; --resume then ends with the very rows, summary and
    files of a sweep that ran straight through (failure scenarios included: without
    avoidance, pair encounters planned closer than r_pz intrude)."""
    straight = tmp_path / "straight"
    code, _, err = finish(procs.start(*sweep_args(straight, method="none")))
    assert code == 0, err
    cut = tmp_path / "cut"
    proc = procs.start(*sweep_args(cut, "--batch", "1", "--in-flight", "2", "--flush-every",
                                   "0.2", method="none"))
    wait_for_part(cut, proc)
    os.killpg(proc.pid, signal.SIGINT)
    code, out, err = finish(proc, timeout=60)
    assert code == 130, err
    assert "Traceback" not in err and out == ""
    assert "--resume" in err.strip().splitlines()[-1]
    assert_clean_stop(cut)
    kept = sum(len(pd.read_parquet(p)) for p in (cut / "parts").glob("part-*.parquet"))
    assert 0 < kept < N
    code, out, err = finish(procs.start(*sweep_args(cut, "--resume", method="none")))
    assert code == 0, err
    assert rows_equal(rows_of(cut), rows_of(straight))
    assert rows_equal(rows_of(cut), flown_here["none"])
    assert summary_of(cut) == summary_of(straight)
    assert json.loads(out)["encounters"] == N
    files = files_of(cut)
    assert files.keys() == files_of(straight).keys()
    assert any(name.startswith("failures/") for name in files)
    for name, data in files.items():
        if name != "encounters.parquet":  # its timing columns differ
            assert data == files_of(straight)[name], name


def test_client_killed_then_resume_flies_only_what_is_missing(tmp_path, procs, flown_here):
    out = tmp_path / "killed"
    proc = procs.start(*sweep_args(out, "--batch", "2", "--in-flight", "2", "--flush-every",
                                   "0.2"))
    wait_for_part(out, proc)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=30)
    assert_clean_stop(out, killed=True)
    # what a SIGKILL in the middle of writing a part leaves, whenever this one did not
    (out / "parts" / ".part-999999.parquet.cut.partial").write_bytes(b"half a part")
    code, _, err = finish(procs.start(*sweep_args(out, "--resume", "-v")))
    assert code == 0, err
    rows = rows_of(out)
    assert list(rows["index"]) == list(range(N)) and rows["error"].isna().all()
    assert rows_equal(rows, flown_here["vo3d"])
    assert not (out / "parts").exists() and not list(out.rglob(".*"))


def worker_pids(client: int) -> list[int]:
    """The Dask worker processes of a local cluster the client ``client`` started."""
    kids = psutil.Process(client).children(recursive=True)
    return [p.pid for p in kids if "spawn_main" in " ".join(p.cmdline())]


def test_a_worker_killed_mid_encounter_costs_a_rerun_not_a_row(tmp_path, procs, flown_here):
    out = tmp_path / "worker"
    proc = procs.start(*sweep_args(out, "--batch", "2", "--in-flight", "4", "--flush-every",
                                   "0.2", "--workers", "2"))
    wait_for_part(out, proc)
    victims = worker_pids(proc.pid)
    assert len(victims) == 2
    os.kill(victims[0], signal.SIGKILL)
    code, _, err = finish(proc)
    assert code == 0, err
    rows = rows_of(out)
    assert rows["error"].isna().all()
    assert rows_equal(rows, flown_here["vo3d"])
    assert rows["worker"].nunique() >= 2


def test_refused_resumes_name_what_differs(tmp_path, procs):
    out = tmp_path / "other"
    proc = procs.start(*sweep_args(out, "--batch", "2", "--in-flight", "2", "--flush-every",
                                   "0.2"))
    wait_for_part(out, proc)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=30)
    cases = [
        (["--seed", "6"], "seed: 5 there, 6 now"),
        (["-o", "margin=0.2"], 'selector_options: {"preset": "safe"} there'),
        (["--method", "none"], 'method: "vo3d" there, "none" now'),
        (["--n", "241"], "encounters: 240 there, 241 now"),
    ]
    for extra, why in cases:
        code, out_text, err = finish(procs.start(*sweep_args(out, "--resume"), *extra))
        assert code == 2 and out_text == "", err
        assert len(err.strip().splitlines()) == 1, err  # the refusal alone, said first
        line = err.strip()
        assert "holds another sweep" in line and why in line, line
    code, _, err = finish(procs.start(*sweep_args(out)))  # no --resume: kept, not overwritten
    assert code == 2 and "holds an unfinished sweep" in err and "--resume" in err
    assert list((out / "parts").glob("part-*.parquet"))


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def wait_for_workers(address: str, count: int, timeout: float = 90) -> None:
    from distributed import Client

    with Client(address, timeout=timeout) as client:
        client.wait_for_workers(count, timeout=timeout)


def test_a_real_scheduler_with_workers_that_come_and_go(tmp_path, procs, flown_here):
    """``dask scheduler`` and two ``dask worker`` processes on 127.0.0.1; one worker killed
    by its pid mid-sweep and another started: the rows of the encounters flown here."""
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    procs.start(BIN / "dask", "scheduler", "--host", "127.0.0.1", "--port", str(port),
                "--no-dashboard")

    def worker() -> subprocess.Popen:
        return procs.start(BIN / "dask", "worker", address, "--host", "127.0.0.1",
                           "--nthreads", "1", "--no-nanny", "--no-dashboard")

    first = [worker(), worker()]
    wait_for_workers(address, 2)
    out = tmp_path / "remote"
    proc = procs.start(BIN / "vo3d", "sweep", "pair", "--n", str(N), "--seed", str(SEED),
                       "--scheduler", address, "--batch", "2", "--in-flight", "4",
                       "--flush-every", "0.2", "--out", out, "--json")
    wait_for_part(out, proc)
    os.kill(first[0].pid, signal.SIGKILL)
    first[0].wait(timeout=30)
    worker()
    code, text, err = finish(proc)
    assert code == 0, err
    assert json.loads(text)["scheduler"] == address
    rows = rows_of(out)
    assert rows["error"].isna().all()
    assert rows_equal(rows, flown_here["vo3d"])
    assert rows["worker"].nunique() >= 2
    assert {"run_time", "worker", "wall_time"} <= set(rows.columns)
