"""The ahead-of-time decision kernel (``vo3d compile``, formulations/aot.py): bitwise the JIT
kernel's answers, never loaded when built from other code or for another machine, and never
handed arguments it would crash on."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from collections.abc import Callable, Iterator
from pathlib import Path

import numba
import numpy as np
import pytest
from encounters import encounters
from hypothesis import given, settings
from test_fallback import _crowd
from test_swarm import LIMITS, OBSTACLES, SPHERES, random_swarm

from vo3d_opt import VelocitySelector, cli, selector, swarm
from vo3d_opt.formulations import aot, kernel
from vo3d_opt.formulations.common import Options, bounds_array, neighbor_rows
from vo3d_opt.formulations.swarm import MANY_OUT_SIZE, Swarm
from vo3d_opt.geometry.pyramid import prism_rows
from vo3d_opt.types import AgentState, Limits


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """A directory holding a current module: the package's own when ``make`` built it for
    this code, else one built here (about 40 s, once per test worker). VO3D_AOT is cleared
    for the module's tests (they turn it on and off themselves)."""
    saved = os.environ.pop("VO3D_AOT", None)
    try:
        if aot.load()[0] is not None:
            yield aot.HERE
        else:
            directory = tmp_path_factory.mktemp("aot")
            aot.build(directory)
            yield directory
    finally:
        if saved is not None:
            os.environ["VO3D_AOT"] = saved


@pytest.fixture(scope="module")
def compiled(built: Path) -> aot.Kernels:
    fn, note = aot.load(built)
    assert fn is not None, note
    return fn


def _arrays(kw: dict, options: Options) -> tuple:
    return (
        kw["own"].position,
        kw["own"].velocity,
        np.asarray(kw["preferred_velocity"], dtype=float),
        neighbor_rows(kw["neighbors"]),
        prism_rows(kw["obstacles"]),
        bounds_array(kw["limits"], kw["dt"]),
        *options.packed,
    )


def _both(compiled: aot.Kernels, args: tuple) -> tuple[np.ndarray, np.ndarray]:
    a, b = np.empty(kernel.OUT_SIZE), np.empty(kernel.OUT_SIZE)
    compiled.decide.compiled(*args, a)  # the module itself, not the checked call around it
    kernel.decide(*args, b)
    return a, b


@settings(max_examples=150, deadline=None)
@given(kw=encounters())
def test_the_compiled_module_answers_bitwise_as_the_jit_kernel(
    compiled: aot.Kernels, kw: dict
) -> None:
    a, b = _both(compiled, _arrays(kw, Options()))
    assert np.array_equal(a, b, equal_nan=True), (a, b)


@pytest.mark.parametrize("seed", range(24))
def test_the_compiled_module_answers_bitwise_in_crowds(compiled: aot.Kernels, seed: int) -> None:
    """Crowds reach every step of the kernel (QP rounds, the sampled grid, the least-bad
    fallback), with the options and limits that change them."""
    kw = _crowd(500 + seed, n=20 + seed, closing=3.0 if seed % 2 else 0.0, inside=seed % 5 == 0)
    if seed % 3 == 0:
        kw["limits"] = Limits(speed=(0.0, 4.0), altitude=(0.0, 60.0), acceleration=3.0)
    options = Options(reciprocal=True, pz_buffer=1.6) if seed % 4 == 1 else Options()
    a, b = _both(compiled, _arrays(kw, options))
    assert np.array_equal(a, b, equal_nan=True), (a, b)


def test_the_crowds_reach_the_fallbacks(compiled: aot.Kernels) -> None:
    """The crowds above are not all easy: some end on the grid or the least-bad velocity."""
    rounds = set()
    for seed in range(24):
        kw = _crowd(500 + seed, n=20 + seed, closing=3.0 if seed % 2 else 0.0)
        a, _ = _both(compiled, _arrays(kw, Options()))
        rounds.add(kernel.ROUND_NAMES[int(a[5])])
    assert "least_bad" in rounds and rounds & {"near", "left", "right"}, rounds


def test_arguments_it_cannot_take_go_to_the_jit_kernel() -> None:
    """The module does not check its arguments' types (a list where an array belongs would
    crash the process): the checked call sends anything but float64 C arrays and a writable
    output to the JIT kernel, which dispatches on them (and raises where it must)."""
    calls: list[str] = []
    checked = aot._checked(
        lambda *a: calls.append("compiled"), lambda *a: calls.append("jit"), aot._decide_args_ok
    )
    args = [*_arrays(_crowd(7, n=12), Options()), np.empty(kernel.OUT_SIZE)]
    checked(*args)
    assert calls == ["compiled"]
    frozen = np.empty(kernel.OUT_SIZE)
    frozen.flags.writeable = False
    odd = [
        (2, [float(x) for x in args[2]]),  # a list
        (2, args[2].astype(np.float32)),  # another dtype
        (3, np.asfortranarray(args[3])),  # not C-contiguous
        (4, np.zeros((0, 4), dtype=np.int64)),  # integers
        (0, args[0][None, :]),  # another dimension
        (1, args[1].astype(">f8")),  # byte-swapped
        (1, np.frombuffer(bytearray(25), dtype=np.float64, count=3, offset=1)),  # unaligned
        (5, args[5].view(np.ndarray.__class__("Sub", (np.ndarray,), {}))),  # a subclass
        (9, frozen),  # a read-only output
    ]
    for k, value in odd:
        calls.clear()
        checked(*args[:k], value, *args[k + 1 :])
        assert calls == ["jit"], k
    for wrong in (args[:-1], [*args, args[-1]]):  # too few, too many
        calls.clear()
        checked(*wrong)
        assert calls == ["jit"]


#: The selector's module-level state that loading a kernel sets (``warm_up``).
_SELECTOR_STATE = (
    "_warm",
    "_warm_many",
    "_module_tried",
    "_decide_kernel",
    "_decide_unchecked",
    "_range_kernel",
    "_kernel_note",
)


def _keep_selector_state(mp: pytest.MonkeyPatch) -> None:
    """Warm the selector up (as any selector's constructor does) and have ``mp`` put its
    module-level state back as it is now when it undoes its changes."""
    selector.warm_up()
    for name in _SELECTOR_STATE:
        mp.setattr(selector, name, getattr(selector, name))
    mp.setattr(swarm, "_neighbor_lists", swarm._neighbor_lists)
    mp.setattr(swarm, "_nearest_lists", swarm._nearest_lists)


def _spy_on_unchecked(mp: pytest.MonkeyPatch) -> list[bool]:
    """Whether each call of ``selector._decide_unchecked`` had arguments that the module's
    check lets through (then the JIT kernel decides)."""
    seen: list[bool] = []

    def unchecked(*args: object) -> None:
        seen.append(aot._decide_args_ok(args))
        kernel.decide(*args)

    _keep_selector_state(mp)
    mp.setattr(selector, "_decide_unchecked", unchecked)
    return seen


@settings(max_examples=60, deadline=None)
@given(kw=encounters())
def test_select_passes_the_unchecked_module_only_arguments_it_would_pass(kw: dict) -> None:
    """``select`` calls the module's entry without its check (``selector._decide_unchecked``):
    every argument it builds must be one the check would let through."""
    with pytest.MonkeyPatch.context() as mp:
        seen = _spy_on_unchecked(mp)
        VelocitySelector().select(**kw)
    assert seen == [True]


def _read_only_unaligned(values: tuple[float, ...]) -> np.ndarray:
    """float64s at an odd offset of a bytes object (as from a socket): read-only, unaligned."""
    a = np.frombuffer(b"\0" * 4 + np.array(values).tobytes(), dtype=np.float64, offset=4)
    assert not a.flags.aligned and not a.flags.writeable
    return a


def test_read_only_unaligned_vectors_are_copied_before_the_unchecked_call(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """``check_vector`` keeps a read-only float64 vector as it is only when it is also aligned:
    an unaligned one (a view into a received packet) is copied, so ``select`` still hands the
    module aligned arrays."""
    seen = _spy_on_unchecked(monkeypatch)
    kw = _crowd(5, n=6)
    own = AgentState(
        position=_read_only_unaligned((0.0, 0.0, 30.0)),
        velocity=_read_only_unaligned(tuple(kw["own"].velocity)),
    )
    assert own.position.flags.aligned and own.velocity.flags.aligned
    pref = _read_only_unaligned(tuple(kw["preferred_velocity"]))
    VelocitySelector().select(**{**kw, "own": own, "preferred_velocity": pref})
    assert seen == [True]


def test_an_agent_state_built_without_validation_goes_through_the_check(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """pydantic's ``model_construct`` skips ``check_vector``: such a position reaches the
    checked entry (which sends a list to the JIT kernel), never the unchecked one."""
    _keep_selector_state(monkeypatch)
    calls: list[str] = []
    monkeypatch.setattr(selector, "_decide_unchecked", lambda *a: calls.append("unchecked"))
    monkeypatch.setattr(selector, "_decide_kernel", lambda *a: calls.append("checked"))
    kw = _crowd(3, n=4)
    VelocitySelector().select(**kw)
    velocity = kw["own"].velocity
    odd = [
        [0.0, 0.0, 30.0],  # a list
        np.zeros(6)[::2],  # strided
        _read_only_unaligned((0.0, 0.0, 30.0)),  # unaligned
    ]
    for position in odd:
        state = AgentState.model_construct(position=position, velocity=velocity)
        VelocitySelector().select(**{**kw, "own": state})
    assert calls == ["unchecked", "checked", "checked", "checked"]


def _swarm(seed: int, n: int = 40) -> Swarm:
    P, V, W, R = random_swarm(seed, n=n)
    return swarm.SwarmInputs.checked(
        P, V, W, R, OBSTACLES, LIMITS, 0.2, 55.0, 6 if seed % 2 else None, None, spheres=SPHERES
    ).arrays()


@pytest.mark.parametrize("seed", range(6))
def test_the_swarm_entry_answers_bitwise_as_the_jit_kernel_on_two_threads(
    compiled: aot.Kernels, seed: int
) -> None:
    """``select_many``'s entry, run by ``decide_all`` on two threads (the module's wrapper
    releases the GIL, as the JIT's nogil one does)."""
    sw, packed = _swarm(seed), Options().packed
    got = swarm.decide_all(sw, packed, 2, compiled.decide_range.compiled)
    want = swarm.decide_all(sw, packed, 1)
    assert np.array_equal(got, want, equal_nan=True)


def test_swarm_arguments_it_cannot_take_go_to_the_jit_kernel() -> None:
    calls: list[str] = []
    checked = aot._checked(
        lambda *a: calls.append("compiled"), lambda *a: calls.append("jit"), aot._range_args_ok
    )
    sw = _swarm(1, n=8)
    args = [sw, 0, 8, *Options().packed, np.empty((8, MANY_OUT_SIZE))]
    checked(*args)
    checked(sw, np.int64(0), np.int64(8), *args[3:])
    assert calls == ["compiled", "compiled"]
    odd = [
        (0, tuple(sw)),  # a plain tuple
        (0, sw._replace(who=sw.who.astype(np.int32))),  # another dtype in a field
        (0, sw._replace(agents=np.asfortranarray(sw.agents))),  # not C-contiguous
        (1, 0.0),  # a float index
        (2, True),
        (6, np.empty((8, MANY_OUT_SIZE), dtype=np.float32)),
        (6, np.empty((8, MANY_OUT_SIZE))[:, :]),  # a view: still C, still writable: compiled
        (6, _frozen(np.empty((8, MANY_OUT_SIZE)))),  # a read-only output
    ]
    for k, value in odd:
        calls.clear()
        checked(*args[:k], value, *args[k + 1 :])
        assert calls == (
            ["compiled"]
            if value.__class__ is np.ndarray and value.flags.writeable and value.dtype == np.float64
            else ["jit"]
        ), k


def _pairs(seed: int, n: int) -> tuple:
    """``neighbor_lists``' arguments for n vehicles on a coarse lattice (tied distances), some
    not deciding: every pair within reach, as ``vehicle_links`` gets them from the tree."""
    rng = np.random.default_rng(seed)
    P = rng.integers(0, 6, size=(n, 3)).astype(float) * 4.0
    a, b = (np.ascontiguousarray(x, dtype=np.int64) for x in np.triu_indices(n, 1))
    dist = np.linalg.norm(P[a] - P[b], axis=-1)
    who = np.flatnonzero(rng.random(n) < 0.8)
    place = np.full(n, -1, dtype=np.int64)
    place[who] = np.arange(who.shape[0])
    return a, b, dist, 9.0 + 4.0 * (seed % 4), place


@pytest.mark.parametrize("seed", range(8))
@pytest.mark.parametrize("k", [-1, 0, 3, 10, 60])
def test_the_neighbour_lists_entry_answers_as_the_jit(
    compiled: aot.Kernels, seed: int, k: int
) -> None:
    """The k-d tree's pairs as neighbour lists: the module's and the JIT's are the same, with
    tied distances, rows past the insertion sort's 48 (seeds >= 4: 200 vehicles in a small
    lattice, ranges 9 to 21 m) and every k (-1: all within range)."""
    a, b, dist, reach, place = _pairs(seed, 200 if seed >= 4 else 30)
    D = int(np.count_nonzero(place >= 0))
    got_span, want_span = np.empty((D, 2), dtype=np.int64), np.empty((D, 2), dtype=np.int64)
    got = compiled.neighbor_lists.compiled(a, b, dist, reach, place, k, got_span)
    want = swarm.neighbor_lists(a, b, dist, reach, place, k, want_span)
    assert np.array_equal(got, want) and np.array_equal(got_span, want_span)
    if seed >= 5 and k in (-1, 60):  # the crowds' path (a row of more than 48) is taken
        assert np.max(want_span[:, 1] - want_span[:, 0]) > 48


def _goes_to_the_jit(ok: Callable[[tuple[object, ...]], bool], args: list, odd: list) -> None:
    """Behind ``aot._checked`` with the check ``ok``: ``args`` reach the module; each of ``odd``
    ((position, value) put into ``args``), and ``args`` short of the last, reach the JIT."""
    calls: list[str] = []
    checked = aot._checked(lambda *a: calls.append("compiled"), lambda *a: calls.append("jit"), ok)
    checked(*args)
    assert calls == ["compiled"]
    for k, value in odd:
        calls.clear()
        checked(*args[:k], value, *args[k + 1 :])
        assert calls == ["jit"], k
    calls.clear()
    checked(*args[:-1])
    assert calls == ["jit"]


def test_neighbour_list_arguments_it_cannot_take_go_to_the_jit() -> None:
    a, b, dist, reach, place = _pairs(0, 10)
    span = np.empty((int(np.count_nonzero(place >= 0)), 2), dtype=np.int64)
    odd = [
        (0, a.astype(np.int32)),  # another dtype
        (2, dist.astype(np.float32)),
        (3, 9),  # an int range
        (5, 4.0),  # a float k
        (5, True),
        (4, list(place)),  # a list
        (6, np.asfortranarray(np.empty((span.shape[0], 3), dtype=np.int64))[:, :2]),  # strided
        (6, _frozen(span.copy())),  # a read-only output
    ]
    _goes_to_the_jit(aot._lists_args_ok, [a, b, dist, reach, place, 4, span], odd)


def _proposals(seed: int, n: int, k: int) -> tuple:
    """``nearest_lists``' arguments for n vehicles on a coarse lattice (tied distances), some
    not deciding, as ``vehicle_links`` gets them from one k-nearest query of the tree, with
    ``chosen`` for the k nearest."""
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(seed)
    P = rng.integers(0, 6, size=(n, 3)).astype(float) * 4.0
    who = np.flatnonzero(rng.random(n) < 0.8).astype(np.int64)
    reach = 9.0 + 4.0 * (seed % 4)
    far, near = cKDTree(P).query(P[who], k=k + 1 + swarm._SPARE, distance_upper_bound=reach)
    chosen = np.empty((who.shape[0], k), dtype=np.int64)
    return P, who, near, far, reach, chosen


@pytest.mark.parametrize("seed", range(8))
@pytest.mark.parametrize("k", [1, 3, 10])
def test_the_nearest_lists_entry_answers_as_the_jit(
    compiled: aot.Kernels, seed: int, k: int
) -> None:
    """Each vehicle's k nearest from the tree's proposals: the module's lists and settled flags
    are the JIT's, with tied distances (some lists unsettled) and ranges of 9 to 21 m."""
    P, who, near, far, reach, got = _proposals(seed, 30 if seed < 4 else 120, k)
    want = got.copy()
    got_settled = compiled.nearest_lists.compiled(P, who, near, far, reach, got)
    want_settled = swarm.nearest_lists(P, who, near, far, reach, want)
    assert np.array_equal(got, want) and np.array_equal(got_settled, want_settled)
    if seed >= 4:  # 120 vehicles: ties at the edge leave lists the tree cannot settle
        assert not want_settled.all()


def test_nearest_list_arguments_it_cannot_take_go_to_the_jit() -> None:
    P, who, near, far, reach, chosen = _proposals(0, 20, 3)
    odd = [
        (0, P.astype(np.float32)),  # another dtype
        (0, np.ascontiguousarray(P[:, :2])),  # not three coordinates
        (1, who.astype(np.int32)),
        (1, who[:-1]),  # fewer vehicles than proposals
        (2, near[:, :-1]),  # strided, and not far's shape
        (3, far[:, :3].copy()),  # not near's shape
        (4, 9),  # an int range
        (5, np.empty((who.shape[0], near.shape[1] + 1), dtype=np.int64)),  # k beyond proposals
        (5, _frozen(chosen.copy())),  # a read-only output
    ]
    _goes_to_the_jit(aot._nearest_args_ok, [P, who, near, far, reach, chosen], odd)


def _frozen(a: np.ndarray) -> np.ndarray:
    a.flags.writeable = False
    return a


def _copy(built: Path, to: Path) -> Path:
    for path in (aot.module_path(built), aot.stamp_path(built)):
        shutil.copy(path, to / path.name)
    return to


@pytest.mark.parametrize(
    "key", ["sources", "numba", "numpy", "cpu", "cpu_features", "python", "machine"]
)
def test_a_module_built_from_other_code_or_for_another_machine_is_not_used(
    built: Path, tmp_path: Path, key: str
) -> None:
    directory = _copy(built, tmp_path)
    assert aot.load(directory)[0] is not None
    stamp = json.loads(aot.stamp_path(directory).read_text())
    stamp[key] = "something else"
    aot.stamp_path(directory).write_text(json.dumps(stamp))
    fn, note = aot.load(directory)
    assert fn is None and "stale" in note and key in note


def test_no_stamp_a_broken_stamp_or_vo3d_aot_0_means_the_jit_kernel(
    built: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    directory = _copy(built, tmp_path)
    monkeypatch.setenv("VO3D_AOT", "0")
    assert aot.load(directory) == (None, "the ahead-of-time kernel is turned off (VO3D_AOT=0)")
    monkeypatch.delenv("VO3D_AOT")
    aot.stamp_path(directory).write_text("{not json")
    assert aot.load(directory)[0] is None
    aot.stamp_path(directory).unlink()
    fn, note = aot.load(directory)
    assert fn is None and "vo3d compile" in note
    assert aot.load(tmp_path / "nowhere")[0] is None


def test_select_runs_the_module_when_it_is_current(
    built: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A selector loads it once per process (``warm_up``) and its answers are the JIT's."""
    _keep_selector_state(monkeypatch)
    for name, value in [
        ("_warm", False),
        ("_module_tried", False),
        ("_decide_kernel", kernel.decide),
        ("_decide_unchecked", kernel.decide),
        ("_range_kernel", selector.decide_range),
    ]:
        monkeypatch.setattr(selector, name, value)
    monkeypatch.setattr(swarm, "_neighbor_lists", swarm.neighbor_lists)
    monkeypatch.setattr(swarm, "_nearest_lists", swarm.nearest_lists)
    load = aot.load
    monkeypatch.setattr(aot, "load", lambda: load(built))
    kw = _crowd(11, n=15)
    got = VelocitySelector(preset="paper").select(**kw)
    assert selector.decision_kernel().startswith("ahead-of-time kernel")
    assert selector._decide_kernel is not kernel.decide
    assert selector._decide_unchecked is selector._decide_kernel.compiled  # type: ignore[attr-defined]
    want = np.empty(kernel.OUT_SIZE)
    kernel.decide(*_arrays(kw, Options()), want)
    assert np.array_equal(got.velocity, want[:3])
    assert selector._range_kernel is not selector.decide_range
    assert swarm._neighbor_lists is not swarm.neighbor_lists
    assert swarm._nearest_lists is not swarm.nearest_lists
    P, V, W, R = random_swarm(3, n=30)
    many = VelocitySelector(preset="paper").select_many(P, V, W, R, limits=LIMITS, sensing_range=55.0)
    monkeypatch.setattr(selector, "_range_kernel", selector.decide_range)
    monkeypatch.setattr(swarm, "_neighbor_lists", swarm.neighbor_lists)
    monkeypatch.setattr(swarm, "_nearest_lists", swarm.nearest_lists)
    jit = VelocitySelector(preset="paper").select_many(P, V, W, R, limits=LIMITS, sensing_range=55.0)
    assert np.array_equal(many.velocities, jit.velocities)


def test_a_looped_selector_takes_the_neighbour_lists_from_the_module(
    built: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``select_many`` of a selector that loops over ``select`` (here ``sampled``) lists the
    neighbours with the module too: its constructor loads it, outside every reported time."""
    _keep_selector_state(monkeypatch)
    monkeypatch.setattr(selector, "_module_tried", False)
    monkeypatch.setattr(selector, "_warm_paths", set())
    monkeypatch.setattr(swarm, "_neighbor_lists", swarm.neighbor_lists)
    monkeypatch.setattr(swarm, "_nearest_lists", swarm.nearest_lists)
    load = aot.load
    monkeypatch.setattr(aot, "load", lambda: load(built))
    VelocitySelector("sampled")
    assert swarm._neighbor_lists is not swarm.neighbor_lists
    assert swarm._nearest_lists is not swarm.nearest_lists


def test_vo3d_compile_check_says_which_kernel_select_would_run(
    compiled: aot.Kernels, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(aot, "load", lambda: (None, "stale, say"))
    assert cli.main(["compile", "--check"]) == 1
    assert capsys.readouterr().out.strip() == "stale, say"
    monkeypatch.setattr(aot, "load", lambda: (compiled, "current, say"))
    assert cli.main(["compile", "--check"]) == 0
    assert capsys.readouterr().out.strip() == "current, say"


@pytest.mark.parametrize(
    "error", [RuntimeError("numba.pycc could not compile"), OSError("read-only")]
)
def test_vo3d_compile_says_why_it_failed_in_one_line(
    error: Exception, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    def fail() -> None:
        raise error

    monkeypatch.setattr(aot, "build", fail)
    assert cli.main(["compile"]) == 1
    last = capsys.readouterr().err.strip().splitlines()[-1]  # after the "compiling..." notice
    assert last == f"vo3d: {error}"


def _fake_compiler(monkeypatch: pytest.MonkeyPatch, stamps: list[dict]) -> None:
    """``build`` without numba: the child writes an empty 'module', ``stamp`` returns
    ``stamps`` in turn."""

    def run(cmd: list[str], **kwargs: object) -> subprocess.CompletedProcess:
        directory = Path(cmd[-1].split("_export(")[1].rstrip(")").strip("'"))
        aot.module_path(directory).write_bytes(b"not a module")
        return subprocess.CompletedProcess(cmd, 0, "", "")

    monkeypatch.setattr(aot.subprocess, "run", run)
    monkeypatch.setattr(aot, "stamp", lambda: stamps.pop(0))


def test_build_puts_the_module_then_its_stamp_in_place(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    _fake_compiler(monkeypatch, [{"sources": "a"}, {"sources": "a"}])
    path, _ = aot.build(tmp_path)
    assert path == aot.module_path(tmp_path) and path.read_bytes() == b"not a module"
    assert json.loads(aot.stamp_path(tmp_path).read_text()) == {"sources": "a"}
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        [path.name, aot.stamp_path(tmp_path).name]
    )  # the scratch folder is gone


def test_a_build_during_which_the_sources_changed_is_thrown_away(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    _fake_compiler(monkeypatch, [{"sources": "before"}, {"sources": "after"}])
    with pytest.raises(RuntimeError, match="changed during the build"):
        aot.build(tmp_path)
    assert list(tmp_path.iterdir()) == []


def test_a_module_that_does_not_load_means_the_jit(built: Path, tmp_path: Path) -> None:
    directory = _copy(built, tmp_path)
    aot.module_path(directory).write_bytes(b"not a module")
    fn, note = aot.load(directory)
    assert fn is None and "does not load" in note


def test_sources_edited_after_import_or_numba_debugging_mean_the_jit(
    built: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    assert aot.load(built)[0] is not None
    monkeypatch.setattr(aot, "SOURCES_AT_IMPORT", "edited since")
    fn, note = aot.load(built)
    assert fn is None and "sources" in note
    monkeypatch.undo()
    monkeypatch.setattr(numba.config, "BOUNDSCHECK", 1)
    fn, note = aot.load(built)
    assert fn is None and "NUMBA_BOUNDSCHECK" in note


def test_the_source_hash_skips_editor_files(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "a.py").write_text("x = 1\n")
    monkeypatch.setattr(aot, "PACKAGE", tmp_path)
    clean = aot._source_hash()
    (tmp_path / ".#a.py").symlink_to(tmp_path / "nowhere")  # an emacs lock: a dangling link
    (tmp_path / ".a.py").write_text("backup")
    assert aot._source_hash() == clean
    (tmp_path / "a.py").write_text("x = 2\n")
    assert aot._source_hash() != clean
