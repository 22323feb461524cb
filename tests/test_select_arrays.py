"""``VelocitySelector.select_arrays``: ``select``'s answer from numpy arrays, bit for bit, over the
recorded encounters (crowds with no safe velocity, vehicles inside zones, ceilings, obstacles,
traffic that does not avoid, acceleration limits), on the compiled path and the Python one; and
a ValueError naming the argument (row and column for an array) for anything malformed. Also:
``select`` takes every form of its inputs it took before its fast path, with the same answers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from golden_cases import encounter, select_kwargs
from vo3d_opt import AgentState, Cylinder, Limits, Neighbor, VelocitySelector
from vo3d_opt.geometry.pyramid import prism_rows

SEEDS = range(0, 480, 2)


def arrays_of(kw: dict) -> dict:
    """``select``'s arguments as ``select_arrays`` takes them (writable arrays, as a control loop
    holds them)."""
    nbrs = kw["neighbors"]
    return dict(
        position=np.array(kw["own"].position),
        velocity=np.array(kw["own"].velocity),
        preferred_velocity=np.array(kw["preferred_velocity"], dtype=float),
        neighbors=np.array([[*nb.position, *nb.velocity, nb.r_pz] for nb in nbrs]).reshape(-1, 7),
        cooperative=np.array([nb.cooperative for nb in nbrs], dtype=bool),
        obstacles=prism_rows(kw["obstacles"]),
        limits=kw["limits"],
        dt=kw["dt"],
    )


def same(a, b) -> bool:
    plane_a = math.nan if a.plane is None else a.plane
    plane_b = math.nan if b.plane is None else b.plane
    return (
        a.velocity.tobytes() == b.velocity.tobytes()  # -0.0 and 0.0 apart
        and a.status == b.status
        and (plane_a == plane_b or (math.isnan(plane_a) and math.isnan(plane_b)))
        and a.info.keys() == b.info.keys()
        and all(np.array_equal(a.info[k], b.info[k]) for k in a.info)
    )


@pytest.mark.parametrize("preset", ["safe", "paper", "fast"])
def test_select_arrays_is_select_bit_for_bit(preset: str) -> None:
    sel = VelocitySelector(preset=preset)
    rounds, statuses = set(), set()
    for seed in SEEDS:
        kw = select_kwargs(encounter(seed))
        want = sel.select(**kw)
        assert same(sel.select_arrays(**arrays_of(kw)), want), seed
        rounds.add(want.info["round"])
        statuses.add(str(want.status))
    # the fallbacks and the hard statuses are among the cases
    assert {"preferred", "sampled", "least_bad"} <= rounds
    assert {"optimal", "inside_protected_zone", "infeasible_min_violation"} <= statuses


@pytest.mark.parametrize(
    "formulation,solver,every", [("sampled", None, 40), ("plane_qp", "daqp", 4), ("nlp", None, 40)]
)
def test_select_arrays_is_select_on_the_python_path(formulation, solver, every) -> None:
    sel = VelocitySelector(formulation, solver)
    for seed in SEEDS[::every]:
        kw = select_kwargs(encounter(seed))
        assert same(sel.select_arrays(**arrays_of(kw)), sel.select(**kw)), seed


def test_select_arrays_takes_obstacle_objects_and_no_neighbours() -> None:
    sel = VelocitySelector()
    kw = select_kwargs(encounter(4))
    args = arrays_of(kw)
    assert same(sel.select_arrays(**{**args, "obstacles": kw["obstacles"]}), sel.select(**kw))
    alone = {**args, "neighbors": None, "cooperative": None}
    want = sel.select(**{**kw, "neighbors": []})
    assert same(sel.select_arrays(**alone), want)
    assert same(sel.select_arrays(**{**alone, "neighbors": []}), want)
    # all cooperative unless told
    coop = {**args, "cooperative": None}
    all_coop = [nb.model_copy(update={"cooperative": True}) for nb in kw["neighbors"]]
    assert same(sel.select_arrays(**coop), sel.select(**{**kw, "neighbors": all_coop}))


def _bad(args: dict) -> list[tuple[str, object, str]]:
    nbrs, obs = args["neighbors"], args["obstacles"]

    def put(a: np.ndarray, index: tuple, value: float) -> np.ndarray:
        a = np.array(a, dtype=float)
        a[index] = value
        return a

    return [
        ("position", np.zeros(2), "position: expected shape"),
        ("position", put(args["position"], (2,), 1e8), r"position\[2\]: must be finite"),
        ("velocity", put(args["velocity"], (0,), np.nan), r"velocity\[0\]"),
        ("preferred_velocity", put(args["preferred_velocity"], (1,), np.inf), "preferred_velocity"),
        ("preferred_velocity", np.array(["a", "b", "c"]), "preferred_velocity: expected real"),
        ("neighbors", nbrs[:, :6], r"neighbors: expected shape \(N, 7\)"),
        ("neighbors", put(nbrs, (1, 4), np.nan), r"neighbors\[1, 4\] \(vy\)"),
        ("neighbors", put(nbrs, (0, 6), 0.0), r"neighbors\[0, 6\] \(r_pz\): must be positive"),
        ("neighbors", nbrs > 0, "neighbors: expected real numbers"),
        ("cooperative", np.ones(nbrs.shape[0] + 1, bool), "cooperative: expected shape"),
        ("cooperative", np.full(nbrs.shape[0], 2), "cooperative: expected booleans"),
        ("obstacles", obs[:, :3], r"obstacles: expected shape \(N, 6\) .* or \(N, 4\)"),
        ("obstacles", put(obs, (1, 4), 0.0), r"obstacles\[1, 4\] \(height\): must be positive"),
        ("obstacles", obs[0], r"obstacles: expected shape \(N, 6\) .* or \(N, 4\) .*got \(6,\)"),
        ("obstacles", [list(obs[0]), list(obs[1, :4])], r"obstacles: .* got rows of different"),
        ("obstacles", put(obs, (0, 5), np.nan), r"obstacles\[0, 5\] \(rim\)"),
        ("obstacles", put(obs[:, :4], (1, 3), np.inf), r"obstacles\[1, 3\] \(h_pz\)"),
        ("obstacles", put(obs, (0, 2), -1.0), r"obstacles\[0, 2\] \(L_pz\)"),
        ("obstacles", put(obs, (1, 3), np.inf), r"obstacles\[1, 3\] \(h_pz\)"),
        ("limits", (0.0, 4.0), "limits: expected Limits"),
        ("dt", -0.2, "dt"),
    ]


def test_bad_arrays_raise_a_value_error_naming_the_field() -> None:
    sel = VelocitySelector()
    args = arrays_of(select_kwargs(encounter(36)))  # obstacles and neighbours
    assert args["neighbors"].shape[0] >= 2 and args["obstacles"].shape[0] >= 2
    for name, value, match in _bad(args):
        with pytest.raises(ValueError, match=match):
            sel.select_arrays(**{**args, name: value})


def test_select_takes_every_form_of_its_inputs_with_the_same_answer() -> None:
    sel = VelocitySelector()
    kw = select_kwargs(encounter(10))
    want = sel.select(**kw)
    pref = np.array(kw["preferred_velocity"], dtype=float)
    frozen = pref.copy()
    frozen.setflags(write=False)
    for form in (tuple(pref.tolist()), pref.tolist(), pref, frozen, pref[::-1].copy()[::-1]):
        assert same(sel.select(**{**kw, "preferred_velocity": form}), want)
    single = pref.astype(np.float32)  # other numbers: the same answer as they are as floats
    assert same(sel.select(**{**kw, "preferred_velocity": single}),
                sel.select(**{**kw, "preferred_velocity": tuple(single.tolist())}))
    assert same(sel.select(**{**kw, "neighbors": iter(kw["neighbors"])}), want)
    assert same(sel.select(**{**kw, "obstacles": tuple(kw["obstacles"])}), want)
    ints = sel.select(**{**kw, "preferred_velocity": (1, 0, 0)})
    assert same(ints, sel.select(**{**kw, "preferred_velocity": (1.0, 0.0, 0.0)}))


@pytest.mark.parametrize(
    "change,match",
    [
        ({"preferred_velocity": (1.0, math.nan, 0.0)}, "preferred_velocity: must be finite"),
        ({"preferred_velocity": (1.0, True, 0.0)}, "preferred_velocity"),
        ({"preferred_velocity": (1.0, 2.0)}, "preferred_velocity: must be 3 numbers"),
        ({"preferred_velocity": (1e8, 0.0, 0.0)}, "preferred_velocity: must be at most"),
        ({"neighbors": [Neighbor(position=(9, 0, 20), r_pz=2.0), (1, 2)]}, r"neighbors\[1\]"),
        ({"obstacles": [Cylinder(center=(9, 0), radius=1, height=5), "box"]}, r"obstacles\[1\]"),
        ({"own": (0.0, 0.0, 20.0)}, "own: expected AgentState"),
        ({"limits": {"speed": (0, 4)}}, "limits: expected Limits"),
        ({"dt": 0.0}, "dt"),
        ({"dt": math.inf}, "dt"),
    ],
)
def test_select_names_what_is_malformed(change: dict, match: str) -> None:
    kw = dict(own=AgentState(position=(0.0, 0.0, 20.0)), preferred_velocity=(1.0, 0.0, 0.0),
              limits=Limits(), dt=0.2)
    with pytest.raises(ValueError, match=match):
        VelocitySelector().select(**{**kw, **change})


@pytest.mark.parametrize("bad", [math.nan, -1.0, 0.0, 1e300, "40", True])
@pytest.mark.parametrize("formulation", ["plane_qp", "cone_qp"])
def test_a_bad_sensing_range_is_a_value_error_naming_it(bad, formulation):
    """The swarm preset derives its horizon from ``sensing_range``: the error names it, not
    the horizon derived from it."""
    sel = VelocitySelector(formulation=formulation, preset="swarm")
    own = AgentState(position=(0.0, 0.0, 20.0), velocity=(1.0, 0.0, 0.0))
    nb = Neighbor(position=(12.0, 0.0, 20.0), velocity=(-1.0, 0.0, 0.0), r_pz=3.0)
    with pytest.raises(ValueError, match="sensing_range"):
        sel.select(own, (1.0, 0.0, 0.0), [nb], sensing_range=bad)
    with pytest.raises(ValueError, match="sensing_range"):
        sel.select_arrays(np.array(own.position), np.array(own.velocity), np.array([1.0, 0, 0]),
                          np.array([[12.0, 0, 20, -1, 0, 0, 3]]), sensing_range=bad)
    far = sel.select(own, (1.0, 0.0, 0.0), [nb], sensing_range=math.inf)
    assert far.velocity.shape == (3,) and np.all(np.isfinite(far.velocity))


# ------------------------------------------------- select() of plain inputs in one compiled call


def _counting(monkeypatch) -> list[int]:
    """Counts the calls of select()'s Python check of the neighbours."""
    from vo3d_opt.formulations import inputs

    calls, real = [0], inputs.neighbor_tuples

    def counted(neighbors):
        calls[0] += 1
        return real(neighbors)

    monkeypatch.setattr(inputs, "neighbor_tuples", counted)
    return calls


@pytest.mark.parametrize("preset", ["safe", "paper", "fast"])
def test_plain_inputs_decide_in_one_call_as_the_checked_path(preset, monkeypatch) -> None:
    """Lists of the user's own objects, a float dt and a tuple, list or array for the preferred
    velocity are read and decided in one compiled call, without select()'s Python checks (each
    neighbour's fields read as they lie, or its row once cached; the obstacles' prisms once
    cached); any other form of the same numbers takes those checks: the same Decision, bit for
    bit, over the recorded encounters."""
    calls = _counting(monkeypatch)
    sel = VelocitySelector(preset=preset)
    for seed in SEEDS[::3]:
        kw = select_kwargs(encounter(seed))
        kw["neighbors"], kw["obstacles"] = list(kw["neighbors"]), list(kw["obstacles"])
        pref = tuple(float(x) for x in kw["preferred_velocity"])
        first = sel.select(**{**kw, "preferred_velocity": pref})  # caches the obstacles' prisms
        assert calls[0] == (len(kw["obstacles"]) > 0), seed  # a prism not cached: the checks
        calls[0] = 0
        fast = [sel.select(**{**kw, "preferred_velocity": form})
                for form in (pref, list(pref), np.array(pref))]
        assert calls[0] == 0, seed
        fast.append(first)
        checked = sel.select(**{**kw, "preferred_velocity": pref, "neighbors": iter(kw["neighbors"])})
        assert calls[0] == 1, seed
        fast.append(sel.select(**{**kw, "preferred_velocity": pref}))  # rows cached by now
        assert calls[0] == 1, seed
        calls[0] = 0
        assert all(same(d, checked) for d in fast), seed
        assert all(type(d.velocity) is np.ndarray and d.velocity.shape == (3,) for d in fast)
        assert (fast[0].formulation, fast[0].solver) == (checked.formulation, checked.solver)
        assert 0.0 < fast[0].solve_time < 1.0


def test_other_forms_of_the_inputs_take_the_checks(monkeypatch) -> None:
    """A subclass, an int dt, a NumPy scalar, a generator, limits=None: select()'s checks decide
    (or, for None limits, the default limits in one call), with the same answer."""
    calls = _counting(monkeypatch)
    sel = VelocitySelector()
    kw = select_kwargs(encounter(12))
    kw["neighbors"] = list(kw["neighbors"])
    want = sel.select(**kw)

    class Mine(Neighbor):
        pass

    mine = [Mine(**nb.model_dump()) for nb in kw["neighbors"]]
    for change in ({"neighbors": mine}, {"dt": np.float64(kw["dt"])},
                   {"neighbors": (nb for nb in kw["neighbors"])}):
        before = calls[0]
        assert same(sel.select(**{**kw, **change}), want), change
        assert calls[0] == before + 1, change
    assert len(kw["neighbors"]) > 0
    default = dict(kw, limits=Limits())
    before = calls[0]
    assert same(sel.select(**{**default, "limits": None}), sel.select(**default))
    assert calls[0] == before
    assert same(sel.select(**{**kw, "dt": 1}), sel.select(**{**kw, "dt": 1.0}))


def test_one_selector_decides_for_many_threads_at_once() -> None:
    """Threads deciding with one selector (with periods of their own) get each its own
    answer."""
    from concurrent.futures import ThreadPoolExecutor

    sel = VelocitySelector()
    cases = [select_kwargs(encounter(seed)) for seed in SEEDS[:60]]
    for i, kw in enumerate(cases):
        kw["dt"] = (0.1, 0.2)[i % 2]
    want = [VelocitySelector().select(**kw) for kw in cases]
    with ThreadPoolExecutor(4) as pool:
        for _ in range(3):
            got = list(pool.map(lambda kw: sel.select(**kw), cases))
            assert all(same(g, w) for g, w in zip(got, want, strict=True))


def test_a_selector_is_collected_when_dropped() -> None:
    """The compiled path holds its selector's method: the cycle is the collector's to free."""
    import gc
    import weakref

    sel = VelocitySelector()
    sel.select(AgentState(position=(0.0, 0.0, 20.0)), (1.0, 0.0, 0.0))
    ref = weakref.ref(sel)
    del sel
    gc.collect()
    assert ref() is None


def test_arrays_decide_in_one_call_as_the_checked_path(monkeypatch) -> None:
    """float64 arrays of the usual shapes (any strides), boolean flags and obstacle rows of six
    or four columns (or the objects) are checked and decided in one compiled call; lists, ints
    and 0/1 flags take select_arrays' Python checks: the same Decision, bit for bit."""
    from vo3d_opt.formulations import inputs

    calls, real = [0], inputs.neighbor_array

    def counted(neighbors, cooperative):
        calls[0] += 1
        return real(neighbors, cooperative)

    monkeypatch.setattr(inputs, "neighbor_array", counted)
    sel = VelocitySelector()
    some = 0
    for seed in SEEDS[::4]:
        kw = select_kwargs(encounter(seed))
        args = arrays_of(kw)
        some += args["neighbors"].shape[0] > 0 and args["obstacles"].shape[0] > 0
        nb = args["neighbors"]
        fast = [
            sel.select_arrays(**args),
            sel.select_arrays(**{**args, "neighbors": np.asfortranarray(nb)}),
            sel.select_arrays(**{**args, "neighbors": np.hstack([nb, nb])[:, :7]}),
            sel.select_arrays(**{**args, "neighbors": np.repeat(nb, 2, axis=0)[::2]}),
        ]
        short = sel.select_arrays(**{**args, "obstacles": args["obstacles"][:, :4]})
        assert calls[0] == 0, seed
        checked = sel.select_arrays(**{**args, "neighbors": nb.tolist(),
                                       "cooperative": args["cooperative"].astype(int)})
        short_checked = sel.select_arrays(**{**args, "obstacles": args["obstacles"][:, :4].tolist()})
        assert calls[0] == 1 + (args["obstacles"].shape[0] > 0), seed  # [] is no obstacle
        calls[0] = 0
        assert all(same(d, checked) for d in fast), seed
        assert same(short, short_checked), seed
    assert some > 10


def test_none_for_any_argument_is_none_or_a_value_error_naming_it() -> None:
    """None where a list or the limits may be None means none (the default limits); anywhere
    else it is a ValueError naming the argument, as before select() had its one-call path."""
    sel = VelocitySelector()
    own = AgentState(position=(0.0, 0.0, 20.0), velocity=(1.0, 0.0, 0.0))
    kw = dict(own=own, preferred_velocity=(1.0, 0.0, 0.0), neighbors=[], obstacles=[],
              limits=Limits(), dt=0.2)
    want = sel.select(**kw)
    for name in ("neighbors", "obstacles", "limits"):
        assert same(sel.select(**{**kw, name: None}), want), name
    for name in ("own", "preferred_velocity", "dt"):
        with pytest.raises(ValueError, match=name):
            sel.select(**{**kw, name: None})
    args = dict(position=np.array([0.0, 0.0, 20.0]), velocity=np.array([1.0, 0.0, 0.0]),
                preferred_velocity=np.array([1.0, 0.0, 0.0]), neighbors=np.zeros((0, 7)),
                obstacles=np.zeros((0, 6)), limits=Limits(), dt=0.2)
    assert same(sel.select_arrays(**args), want)
    for name in ("neighbors", "obstacles", "limits", "cooperative"):
        assert same(sel.select_arrays(**{**args, name: None}), want), name
    for name in ("position", "velocity", "preferred_velocity", "dt"):
        with pytest.raises(ValueError, match=name):
            sel.select_arrays(**{**args, name: None})


def test_another_numpy_major_takes_the_checked_path(monkeypatch) -> None:
    """The one-call path reads numpy 1's and 2's array struct: under another major version the
    selector decides through the Python checks, to the same answer."""
    kw = select_kwargs(encounter(14))
    want = VelocitySelector().select(**kw)
    calls = _counting(monkeypatch)
    monkeypatch.setattr(np, "__version__", "3.0.0")
    assert same(VelocitySelector().select(**kw), want)
    assert calls[0] == 1
