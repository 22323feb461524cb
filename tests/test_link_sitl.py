"""``vo3d sitl`` end to end: every vehicle, every link and the router a process of its own,
over real UDP sockets on 127.0.0.1, three times faster than real time (faster, a 2-core
machine running another test beside them could not keep the links' 10 Hz on its clock). The crossing
with a non-cooperative intruder, then one fault per test: nothing crashes, no protected zone
is entered, and every refused packet is counted by every link."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("pymavlink")
pytest.importorskip("pyproj")

from vo3d_opt.sim.metrics import CONTRACT_KEYS  # noqa: E402

DATA = Path(__file__).parent / "data"
CROSSING, THREE = DATA / "link-crossing.yaml", DATA / "link-three.yaml"
SCALE = "3"


def sitl(scenario: Path, *args: str | Path) -> dict:
    cmd = [sys.executable, "-m", "vo3d_opt.cli", "sitl", "-q", str(scenario), "--json",
           "--time-scale", SCALE, *[str(a) for a in args]]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=300,
                         env={**os.environ, "PYTHONWARNINGS": "ignore"})
    assert res.returncode == 0, res.stderr[-3000:]
    lines = res.stdout.strip().splitlines()
    assert len(lines) == 1, res.stdout[-2000:]
    return json.loads(lines[0])


def safe(s: dict) -> None:
    assert s["pz_intrusions"] == 0 and s["collisions"] == 0, {k: s[k] for k in CONTRACT_KEYS}
    assert s["obstacle_pz_intrusions"] == 0


def test_four_crossing_and_an_intruder_all_arrive_without_intrusion(tmp_path):
    s = sitl(CROSSING, "--out", tmp_path)
    assert set(CONTRACT_KEYS) <= set(s)
    assert s["agents"] == 5 and s["all_reached"] and s["reached"] == 5
    safe(s)
    assert s["altitude_violations"] == 0 and s["speed_violations"] == 0
    assert s["setpoint_latency_p99_ms"] > 0 and s["setpoint_latency_median_ms"] > 0
    assert s["decisions"] > 4 * 50 and s["rejected_total"] == 0
    assert {name for name in s["links"]} == {"a0", "a1", "a2", "a3"}  # x avoids: false
    for link in s["links"].values():
        assert link["end"] == "arrived" and link["autopilot"] == "px4"
        assert link["acks"]["176:0"] >= 1  # MAV_CMD_DO_SET_MODE accepted
        assert link["neighbors_passive"].get("x") is None  # traffic is not a peer
    written = {p.name for p in tmp_path.iterdir()}
    assert {"trajectories.parquet", "trajectories.csv", "summary.json"} <= written
    assert json.loads((tmp_path / "summary.json").read_text())["all_reached"]


def test_telemetry_cut_brakes_its_link_and_the_others_grow_then_drop_it():
    s = sitl(THREE, "--fault", "cut:a0:0.5:2.0")
    safe(s)
    assert s["all_reached"]
    a0 = s["links"]["a0"]
    assert a0["status_counts"].get("hover: own state stale", 0) > 0
    for other in ("a1", "a2"):
        link = s["links"][other]
        assert link["neighbors_late"].get("a0", 0) > 0
        assert link["neighbors_dropped"].get("a0", 0) >= 1


def test_a_killed_link_leaves_its_vehicle_holding_and_the_others_avoid_it(tmp_path):
    pd = pytest.importorskip("pandas")
    s = sitl(THREE, "--fault", "kill:a0:3.0", "--out", tmp_path)
    safe(s)
    assert s["links"]["a0"]["end"] == "killed" and s["reached"] == 2
    for other in ("a1", "a2"):
        assert s["links"][other]["end"] == "arrived"
        assert s["links"][other]["neighbors_passive"].get("a0", 0) > 0
    df = pd.read_parquet(tmp_path / "trajectories.parquet")
    a0 = df[df["agent"] == "a0"].sort_values("time")
    held = a0[a0["time"] >= 3.0 + 0.5 + 0.5]  # the set-point timeout, and a tick to spare
    assert len(held) > 10
    moved = (held[["x", "y", "z"]] - held[["x", "y", "z"]].iloc[0]).abs().to_numpy().max()
    assert moved < 0.05


def test_garbage_and_malformed_packets_are_counted_and_harmless():
    s = sitl(THREE, "--fault", "garbage:1.0:20", "--fault", "malformed:1.5:10")
    safe(s)
    assert s["all_reached"] and s["faults"] == {"garbage:1:20": 20, "malformed:1.5:10": 30}
    for link in s["links"].values():
        assert link["end"] == "arrived"
        r = link["rejected"]
        assert (r.get("bad_prefix"), r.get("bad_crc"), r.get("truncated"), r.get("impossible")) \
            == (20, 10, 10, 10), r


def test_spoofed_and_foreign_system_ids_are_ignored_and_counted():
    s = sitl(THREE, "--fault", "spoof:a1:1.0:10", "--fault", "foreign:1.5:10")
    safe(s)
    assert s["all_reached"]
    for link in s["links"].values():  # a1's own link included: its own state is checked too
        assert link["rejected"] == {"foreign_system": 10, "implausible_jump": 10}, link["rejected"]


def test_with_signing_unsigned_and_wrongly_signed_packets_are_refused(tmp_path):
    key = tmp_path / "key"
    key.write_text(os.urandom(32).hex())
    s = sitl(THREE, "--signing-key", key, "--autopilot", "ardupilot",
             "--fault", "unsigned:1.0:10", "--fault", "badsig:1.5:10")
    safe(s)
    assert s["all_reached"] and s["signed"]
    for link in s["links"].values():
        assert link["autopilot"] == "ardupilot" and link["end"] == "arrived"
        assert link["rejected"] == {"bad_signature": 10, "unsigned": 10}, link["rejected"]


def test_ctrl_c_stops_every_process_and_still_prints_the_summary():
    import signal
    import time

    cmd = [sys.executable, "-m", "vo3d_opt.cli", "sitl", str(THREE), "--json", "--time-scale",
           SCALE]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONWARNINGS": "ignore"})
    try:
        for line in proc.stderr:  # the orchestrator says when the mission starts
            if "the mission starts" in line:
                break
        time.sleep(0.5)
        children = subprocess.run(["ps", "-o", "pid=", "--ppid", str(proc.pid)],
                                  capture_output=True, text=True).stdout.split()
        assert len(children) == 1 + 3 + 3  # the router, the vehicles, the links
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 130
    summary = json.loads(out.strip().splitlines()[-1])
    assert summary["agents"] == 3 and summary["pz_intrusions"] == 0
    for pid in map(int, children):
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)
