"""Run records kept in a temporary file (vo3d_opt.sim.spill): the same numbers as in memory,
the same summary and files, and a clear way out when the file cannot be had."""
from __future__ import annotations

import dataclasses
import mmap
import pickle

import numpy as np
import pandas as pd
import pytest

from vo3d_opt import report
from vo3d_opt.sim import record, simulator, spill
from vo3d_opt.sim.deciders import SwarmSelect
from vo3d_opt.sim.metrics import summarize
from vo3d_opt.sim.scenario import load_scenario
from vo3d_opt.sim.simulator import StepDecision, fly, scenario_selector


def swap(**update):
    sc = load_scenario("sphere-swap-16")
    return sc.model_copy(update={"max_time": 12.0, **update})


def flown(sc, **kw):
    sel, formulation, solver = scenario_selector(sc)
    return fly(sc, SwarmSelect(sc, sel, formulation=formulation, solver=solver), progress=False, **kw)


def same_summary(a: dict, b: dict) -> bool:
    timing = {"wall_time", "decision_time_median_us", "decision_time_p99_us", "decision_time_max_us"}
    return {k: v for k, v in a.items() if k not in timing} == {
        k: v for k, v in b.items() if k not in timing
    }


@pytest.mark.parametrize("tau", [None, 0.6], ids=["kinematic", "first_order"])
def test_a_spilled_run_is_the_run_in_memory(tau, tmp_path):
    sc = swap(velocity_response_tau=tau)
    kept = flown(sc, spill=False)
    spilled = flown(sc, spill=True, spill_dir=tmp_path)
    assert kept.spill is None and spilled.spill is not None
    assert spilled.same_trajectory(kept) and kept.same_trajectory(spilled)
    assert np.array_equal(spilled.preferred, kept.preferred)
    assert np.array_equal(spilled.decided, kept.decided)
    assert np.array_equal(spilled.decision_times, spilled.solve_times, equal_nan=True)
    assert np.array_equal(np.isnan(spilled.decision_times), np.isnan(kept.decision_times))
    assert same_summary(summarize(spilled), summarize(kept))
    spilled.drop_resident()  # the pages go, the numbers stay
    assert spilled.same_trajectory(kept)
    assert list(tmp_path.iterdir()) == []  # the file is unlinked from the start


def test_spilled_files_and_pickles_are_the_in_memory_ones(tmp_path):
    sc = swap()
    kept, spilled = flown(sc, spill=False), flown(sc, spill=True)
    for name, rec in (("kept", kept), ("spilled", spilled)):
        report.write_parquet(rec, tmp_path / f"{name}.parquet")
        report.write_csv(rec, tmp_path / f"{name}.csv")
    a, b = (pd.read_parquet(tmp_path / f"{n}.parquet") for n in ("kept", "spilled"))
    pd.testing.assert_frame_equal(a.drop(columns="decision_time_us"), b.drop(columns="decision_time_us"))
    a, b = (pd.read_csv(tmp_path / f"{n}.csv") for n in ("kept", "spilled"))
    pd.testing.assert_frame_equal(a.drop(columns="decision_time_us"), b.drop(columns="decision_time_us"))
    back = pickle.loads(pickle.dumps(spilled))
    assert back.spill is None and back.same_trajectory(kept)


def test_large_allotments_spill_by_default(monkeypatch):
    sc = swap()
    assert flown(sc, max_steps=3).spill is None  # small: in memory
    assert simulator.run_scenario(sc, max_steps=3, spill=True).spill is not None
    monkeypatch.setattr(record, "SPILL_BYTES", 0)
    assert flown(sc, max_steps=3).spill is not None
    assert simulator.run_scenario(sc, max_steps=3).spill is not None
    assert simulator.run_scenario(sc, max_steps=3, spill=False).spill is None


def test_without_a_file_the_run_stays_in_memory_or_says_why(monkeypatch, tmp_path):
    sc = swap()

    def full_disk(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(record, "SPILL_BYTES", 0)
    monkeypatch.setattr(record, "Spill", full_disk)
    with pytest.warns(RuntimeWarning, match="spill: kept in memory"):
        rec = flown(sc, max_steps=3)
    assert rec.spill is None and rec.steps == 3
    with pytest.raises(OSError, match="No space"):
        flown(sc, max_steps=3, spill=True)
    monkeypatch.undo()
    monkeypatch.setattr(record, "SPILL_BYTES", 0)
    for spill_flag in (None, True, False):  # a directory given must be one
        with pytest.raises(ValueError, match="spill_dir: .*missing is not a directory"):
            flown(sc, max_steps=3, spill=spill_flag, spill_dir=tmp_path / "missing")
    with pytest.raises(ValueError, match="held in memory .*choose one on disk"):
        with monkeypatch.context() as m:
            m.setattr(record, "in_memory_fs", lambda where: True)
            flown(sc, max_steps=3, spill_dir=tmp_path)
    monkeypatch.setattr(record, "in_memory_fs", lambda where: True)  # e.g. /tmp on tmpfs
    with pytest.warns(RuntimeWarning, match="tmpfs"):
        assert flown(sc, max_steps=3).spill is None
    with pytest.raises(ValueError, match="spill_dir: .* held in memory.*set TMPDIR"):
        flown(sc, max_steps=3, spill=True)
    monkeypatch.setattr(record, "spill_supported", lambda: False)
    with pytest.raises(ValueError, match="spill: .*Linux"):
        flown(sc, max_steps=3, spill=True)
    assert flown(sc, max_steps=3).spill is None


MOUNTS = """/dev/vda / ext4 rw,relatime 0 0
tmpfs /tmp tmpfs rw,nosuid 0 0
/dev/vdb /tmp/disk ext4 rw 0 0
tmpfs /run/my\\040dir tmpfs rw 0 0
"""


@pytest.mark.parametrize(
    "directory, held",
    [("/tmp", True), ("/tmp/x/y", True), ("/tmp/disk/x", False), ("/tmpfoo", False),
     ("/work", False), ("/run/my dir/a", True)],
)
def test_directories_in_memory_are_found_by_their_mount(directory, held):
    assert spill.in_memory_fs(directory, MOUNTS) is held


def test_dropping_lets_go_of_the_pages_and_keeps_the_numbers():
    def rss_file_kb() -> int:
        with open("/proc/self/status") as fh:
            return next(int(line.split()[1]) for line in fh if line.startswith("RssFile:"))

    s = spill.Spill({"a": ((8 << 20,), np.float64)})  # 64 MiB
    a = s.arrays["a"]
    before = rss_file_kb()
    a[:] = np.arange(a.size)
    touched = rss_file_kb()
    s.drop()
    dropped = rss_file_kb()
    assert touched - before > 60_000 and touched - dropped > 60_000
    assert a[-1] == a.size - 1 and a[12345] == 12345


def test_statuses_are_spelt_out_from_the_codes():
    rec = flown(swap(), max_steps=4)
    st = rec.statuses
    assert st.dtype == object and st.shape == rec.status_codes.shape
    assert all(st[k, i] == rec.status_names[rec.status_codes[k, i]] for k in range(4) for i in range(3))
    st[:] = "changed"  # a copy each time
    assert "changed" not in set(rec.statuses.ravel())
    with pytest.raises(ValueError, match="status_names"):
        dataclasses.replace(rec, status_names=rec.status_names[1:] + ("",))


class TimedStep:
    """Everyone hovers; the solve times equal the decision times for ``same`` steps, then not."""

    formulation = solver = "timed"

    def __init__(self, same: int) -> None:
        self.same = same

    def decide(self, snap):
        n = snap.positions.shape[0]
        dec = np.full(n, 1e-3 * (snap.k + 1))
        solve = dec.copy() if snap.k < self.same else dec / 2  # equal values, another array
        return StepDecision(np.zeros((n, 3)), np.full(n, "optimal"), dec, solve)

    def extra(self):
        return {}


@pytest.mark.parametrize("use_spill", [False, True])
def test_solve_times_kept_apart_once_they_differ(use_spill):
    sc = swap()
    same = flown(sc, max_steps=5)
    rec = fly(sc, TimedStep(same=3), progress=False, max_steps=6, spill=use_spill)
    dec = 1e-3 * np.arange(1, 7)[:, None] * np.ones(sc.n_agents)
    np.testing.assert_array_equal(rec.decision_times, dec)
    np.testing.assert_array_equal(rec.solve_times[:3], dec[:3])
    np.testing.assert_array_equal(rec.solve_times[3:], dec[3:] / 2)
    assert rec.solve_times is not rec.decision_times
    assert np.shares_memory(same.solve_times, same.decision_times)  # equal all along: one array
    equal = fly(sc, TimedStep(same=10), progress=False, max_steps=6, spill=use_spill)
    assert np.shares_memory(equal.solve_times, equal.decision_times)  # equal values: one array


def test_spill_arrays_start_zeroed_on_pages_of_their_own():
    s = spill.Spill({"a": ((3, 5), np.float64), "b": ((7,), np.bool_), "c": ((2, 2), np.uint16)})
    a, b, c = s.arrays["a"], s.arrays["b"], s.arrays["c"]
    assert not a.any() and not b.any() and not c.any() and a.flags.writeable
    a[:], b[:], c[:] = 1.5, True, 7
    s.drop()
    assert a.sum() == 22.5 and b.all() and (c == 7).all()
    starts = [x.__array_interface__["data"][0] for x in (a, b, c)]
    assert all(p % mmap.PAGESIZE == 0 for p in starts)
