"""What the compiled core (``vo3d_opt._core``, vo3d_opt/algorithm/) promises beyond its answers
(tests/test_golden.py holds those to the last bit): it takes every array ``select`` and
``select_many`` hand it, whatever their strides or write flags; it refuses any other array with
a ValueError naming the argument, never a crash; its answers do not depend on the threads;
its type stub names what it exports."""

from __future__ import annotations

import ast
import math
import threading
from pathlib import Path

import numpy as np
import pytest

from vo3d_opt import AgentState, Box, Cylinder, Limits, Neighbor, VelocitySelector, _core
from vo3d_opt.formulations import inputs, kernel
from vo3d_opt.formulations.common import (
    FINE_HEADING_STEP,
    FINE_SPEED_LEVELS,
    KERNEL_OPTIONS,
    Bounds,
    Options,
    bounds_array,
    neighbor_rows,
    prepare,
    py_decision_planes,
)
from vo3d_opt.geometry.pyramid import prism_rows

ROOT = Path(__file__).resolve().parents[1]


def _encounter(rng: np.random.Generator, n: int = 6) -> dict:
    p = np.array([0.0, 0.0, 20.0])
    nbs = []
    for _ in range(n):
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        nbs.append(Neighbor(position=p + rng.uniform(8.0, 40.0) * d, velocity=-d * 3.0, r_pz=6.0,
                            cooperative=bool(rng.random() < 0.7)))
    return dict(own=AgentState(position=p, velocity=(3.0, 0.0, 0.0)), preferred_velocity=(4.0, 0.0, 0.0),
                neighbors=nbs, obstacles=[Cylinder(center=(15.0, 2.0), radius=2.0, height=30.0),
                                          Box(center=(25.0, -6.0), size=(3.0, 2.0), height=40.0, yaw=0.4)],
                limits=Limits(speed=(0.0, 4.0), altitude=(0.0, 40.0), acceleration=6.0), dt=0.2)


def _arrays(kw: dict) -> list[np.ndarray]:
    """``decide``'s arrays as ``select`` builds them."""
    return [kw["own"].position, kw["own"].velocity, np.asarray(kw["preferred_velocity"], dtype=float),
            neighbor_rows(kw["neighbors"]), prism_rows(kw["obstacles"]), bounds_array(kw["limits"], kw["dt"])]


def _decide(args: list[np.ndarray], cfg) -> np.ndarray:
    out = np.empty(kernel.OUT_SIZE)
    kernel.decide(*args, cfg, out)
    return out


def test_decide_is_select_and_takes_any_strides_and_read_only_arrays():
    rng = np.random.default_rng(1)
    sel, cfg = VelocitySelector(preset="paper"), Options().config
    for _ in range(20):
        kw = _encounter(rng)
        args = _arrays(kw)
        want = _decide(args, cfg)
        d = sel.select(**kw)
        assert np.array_equal(d.velocity, want[:3])
        assert d.info == {"round": kernel.ROUND_NAMES[int(want[5])], "solved": int(want[6])}
        # strided views (every other element of a larger array), Fortran order, read-only
        odd = []
        for a in args:
            wide = np.zeros(a.shape[:-1] + (2 * a.shape[-1],))
            wide[..., ::2] = a
            odd.append(wide[..., ::2])
        assert not odd[0].flags.c_contiguous
        fortran = [np.asfortranarray(a) for a in args]
        frozen = [a.copy() for a in args]
        for a in frozen:
            a.setflags(write=False)
        for variant in (odd, fortran, frozen):
            assert np.array_equal(_decide(variant, cfg), want, equal_nan=True)


def _bad_arguments(args: list[np.ndarray]):
    """(name, argument index, bad value): another dtype, another shape, not an array at all (a
    list; None is a TypeError, as for any Python function that takes no None)."""
    names = ["p", "v_now", "v_pref", "nbrs", "prisms", "limits"]
    for i, a in enumerate(args):
        yield names[i], i, a.astype(np.float32)
        yield names[i], i, a.astype(np.int64)
        yield names[i], i, a.tolist()
        yield names[i], i, np.zeros(a.shape[:-1] + (a.shape[-1] + 1,))
        yield names[i], i, a[None]


def test_bad_arrays_raise_a_value_error_naming_them():
    args, cfg = _arrays(_encounter(np.random.default_rng(2))), Options().config
    for name, i, bad in _bad_arguments(args):
        with pytest.raises(ValueError, match=name):
            _decide(args[:i] + [bad] + args[i + 1 :], cfg)
    for out in (np.empty(6), np.empty(7, dtype=np.float32), np.empty(7)[None]):
        with pytest.raises(ValueError, match="out"):
            kernel.decide(*args, cfg, out)
    frozen = np.empty(7)
    frozen.setflags(write=False)
    with pytest.raises(ValueError, match="out"):
        kernel.decide(*args, cfg, frozen)


def test_prism_rows_of_four_or_six_as_tuples_or_arrays_decide_alike():
    """``decide_rows`` reads the prism tuples as ``decide`` reads the arrays, of 4 columns (no
    roof) or 6; tuples of another width, or of mixed widths, are refused naming the row."""
    rng, cfg = np.random.default_rng(4), Options().config
    for _ in range(10):
        kw = _encounter(rng)
        args = _arrays(kw)
        bounds = inputs.bounds_row(kw["limits"], kw["dt"])
        for width in (4, 6):
            rows = args[4][:, :width]
            want = _decide([*args[:4], np.ascontiguousarray(rows), args[5]], cfg)
            got = np.empty(kernel.OUT_SIZE)
            kernel.decide_rows(*args[:3], neighbor_rows(kw["neighbors"]),
                               [tuple(r) for r in rows.tolist()], bounds, cfg, got)
            assert np.array_equal(got, want, equal_nan=True)
    prisms = [tuple(r) for r in args[4].tolist()]
    for bad in ([prisms[0], prisms[1][:4]], [p[:5] for p in prisms], [list(p) for p in prisms]):
        with pytest.raises(ValueError, match=r"prisms\[[01]\]: expected tuples of 4 or 6"):
            kernel.decide_rows(*args[:3], neighbor_rows(kw["neighbors"]), bad, bounds, cfg,
                               np.empty(kernel.OUT_SIZE))


def test_bad_shapes_of_the_python_side_raise_value_errors():
    kw = _encounter(np.random.default_rng(3))
    enc = prepare(kw["own"], np.asarray(kw["preferred_velocity"], float), kw["neighbors"], kw["obstacles"],
                  kw["limits"], kw["dt"], Options())
    cfg = enc.options.config
    planes = py_decision_planes(enc.vos, enc.v_now, cfg)
    cones = enc.vos.cones
    with pytest.raises(ValueError, match="cones.R"):
        _core.in_vos(cones._replace(R=cones.R[:, :2]), enc.vos.pyramids, np.zeros((1, 3)), -1.0, 0.0)
    with pytest.raises(ValueError, match="cones.inside"):
        _core.in_vos(cones._replace(inside=cones.inside.astype(float)), enc.vos.pyramids, np.zeros((1, 3)),
                     -1.0, 0.0)
    with pytest.raises(ValueError, match="cones"):
        _core.in_vos(tuple(cones)[:5], enc.vos.pyramids, np.zeros((1, 3)), -1.0, 0.0)
    with pytest.raises(ValueError, match="bounds"):
        _core.vz_range(1.0, (0.0, 4.0))
    with pytest.raises(ValueError, match="bounds"):
        _core.vz_range(1.0, ("a",) * 6)
    with pytest.raises(ValueError, match="planes.to_plane"):
        _core.lift(planes._replace(to_plane=planes.to_plane[:1]), np.zeros(2), 0, np.empty(3))
    with pytest.raises(ValueError, match="p"):
        _core.lift(planes, np.zeros(2), len(planes.phi), np.empty(3))
    G3, h3 = enc.linear_bounds()
    qps = kernel.py_plane_qps(enc.vos, planes, G3, h3, enc.pref_in | enc.inside, cfg, True)
    for call in (lambda: qps.solve(3, 0, enc.bounds), lambda: qps.gather(0, -1),
                 lambda: qps.add_rows(len(enc.inside), 0), lambda: qps.search(enc.bounds, np.empty((1, 3)))):
        with pytest.raises(ValueError):
            call()
    with pytest.raises(ValueError, match="initial"):
        kernel.py_plane_qps(enc.vos, planes, G3, h3, np.ones(len(enc.inside) + 1, bool), cfg, True)


def test_a_bad_swarm_raises_a_value_error():
    sel = VelocitySelector()
    P = np.array([[0.0, 0.0, 20.0], [20.0, 0.0, 20.0]])
    V = np.array([[2.0, 0.0, 0.0], [-2.0, 0.0, 0.0]])
    from vo3d_opt import swarm as swarm_module

    inputs = swarm_module.SwarmInputs.checked(P, V, V, 5.0, [], None, 0.2, 55.0, None, None)
    sw = inputs.arrays(1)
    cfg = sel.options_for(4.0, 0.2).config
    out = np.empty((2, _core.MANY_OUT_SIZE))
    _core.decide_many(sw, cfg, 1, out)
    for field, bad in (("nb_idx", np.array([0, 5])), ("who", np.array([0, 9])), ("agents", sw.agents[:, :10])):
        with pytest.raises(ValueError, match=field):
            _core.decide_many(sw._replace(**{field: bad}), cfg, 1, out)
    with pytest.raises(ValueError, match="threads"):
        _core.decide_many(sw, cfg, 0, out)
    with pytest.raises(ValueError, match="out"):
        _core.decide_many(sw, cfg, 1, np.empty((2, _core.MANY_OUT_SIZE))[:, ::2])


def _crowd(n: int, seed: int) -> dict:
    rng = np.random.default_rng(seed)
    P = rng.uniform(-60.0, 60.0, (n, 3))
    P[:, 2] = rng.uniform(5.0, 35.0, n)
    W = -P.copy()
    W[:, 2] = 0.0
    W *= 4.0 / np.maximum(np.linalg.norm(W, axis=1, keepdims=True), 1e-9)
    return dict(positions=P, velocities=W, preferred_velocities=W, r_pz=5.0,
                obstacles=[Cylinder(center=(0.0, 0.0), radius=3.0, height=25.0)],
                limits=Limits(speed=(0.0, 4.0), altitude=(0.0, 40.0)), dt=0.2, max_neighbors=8)


@pytest.mark.parametrize("seed", [0, 1])
def test_swarm_answers_do_not_depend_on_the_threads(seed: int):
    kw, sel = _crowd(300, seed), VelocitySelector(reciprocal=True, closing_guard=True)
    one = sel.select_many(**kw, threads=1)
    assert one.compiled and one.threads == 1
    for threads in (2, 7):  # more threads than cores too: the core takes any number
        sw = _swarm_arrays(kw)
        out = np.empty((sw.who.shape[0], _core.MANY_OUT_SIZE))
        cfg = sel.options_for(kw["limits"].speed[1], kw["dt"], 55.0).config
        _core.decide_many(sw, cfg, threads, out)
        assert np.array_equal(out[:, :3], one.velocities[sw.who])
        assert np.array_equal(out[:, 6], one.solved[sw.who])
    two = sel.select_many(**kw, threads=min(2, __import__("vo3d_opt").swarm.cores()))
    assert np.array_equal(two.velocities, one.velocities)
    assert np.array_equal(two.statuses, one.statuses) and np.array_equal(two.rounds, one.rounds)


def _swarm_arrays(kw: dict):
    from vo3d_opt import swarm as swarm_module

    inputs = swarm_module.SwarmInputs.checked(
        kw["positions"], kw["velocities"], kw["preferred_velocities"], kw["r_pz"], kw["obstacles"],
        kw["limits"], kw["dt"], 55.0, kw["max_neighbors"], None)
    return inputs.arrays(1)


def test_select_many_from_two_python_threads_at_once_is_select_many_alone():
    """The core releases the GIL: two calls run at once and neither disturbs the other."""
    kw, sel = _crowd(200, 3), VelocitySelector()
    want = sel.select_many(**kw, threads=1).velocities
    got: list[np.ndarray] = []

    def run() -> None:
        got.append(sel.select_many(**kw, threads=1).velocities)

    threads = [threading.Thread(target=run) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(got) == 2 and all(np.array_equal(g, want) for g in got)


def test_the_config_is_set_by_name_and_checked_where_the_core_reads_it():
    opts = Options(reciprocal=True, pz_buffer=1.5, margin=0.01, speed_levels=5, closing_guard=True,
                   least_bad_escape=False, fine_fallback=False, horizon=3.0,
                   corrections=frozenset({"triangle"}), plane_step_deg=30.0, qp_samples=12)
    cfg = opts.config
    derived = {"horizon", "obstacle_horizon", "corrections", "fallback_speed_levels"}
    for name in set(KERNEL_OPTIONS) - derived:
        assert getattr(cfg, name) == getattr(opts, name), name
    # the fallbacks' grid is the sampled one's unless it is given its own
    assert (cfg.fallback_speed_levels, cfg.fallback_heading_step) == (5, cfg.heading_step)
    own = Options(speed_levels=5, fallback_speed_levels=3, fallback_heading_step_deg=45.0).config
    assert (own.speed_levels, own.fallback_speed_levels) == (5, 3)
    assert own.fallback_heading_step == math.radians(45.0) != own.heading_step
    assert cfg.horizon == 3.0 and Options().config.horizon < 0  # none: NO_HORIZON
    assert cfg.obstacle_horizon < 0 and Options(obstacle_horizon=9.0).config.obstacle_horizon == 9.0
    assert cfg.corrections.triangle and not cfg.corrections.tg_range
    assert len(cfg.phi) == len(cfg.cos_phi) == 7 and len(cfg.t) == 12
    assert cfg.heading_step == math.radians(opts.heading_step_deg)
    args = _arrays(_encounter(np.random.default_rng(4)))
    for field, bad in (("cos_phi", [1.0]), ("t", []), ("speed_levels", 1), ("heading_step", 0.0),
                       ("fallback_speed_levels", 1), ("fallback_heading_step", 0.0)):
        partial = _core.Config()
        for name, value in opts.kernel_fields().items():
            setattr(partial, name, value)
        setattr(partial, field, bad)
        with pytest.raises(ValueError, match=f"cfg.{field}"):
            _decide(args, partial)
    with pytest.raises(ValueError, match="cfg.phi"):
        _decide(args, _core.Config())  # nothing set
    fine = Options(plane_step_deg=30.0).config
    assert fine.fine is not None and len(fine.fine.phi) == 19 and fine.fine.fine is None
    nested = _core.Config()
    for name, value in opts.kernel_fields().items():
        setattr(nested, name, value)
    nested.fine = fine  # whose own fine planes are set: one level only
    with pytest.raises(ValueError, match="cfg.fine.fine"):
        _decide(args, nested)


def test_the_core_constants_are_the_options_defaults():
    assert FINE_SPEED_LEVELS == Options.model_fields["speed_levels"].default
    assert FINE_HEADING_STEP == math.radians(Options.model_fields["heading_step_deg"].default)
    assert Bounds._fields == ("v_min", "v_max", "z_min", "z_max", "acceleration", "dt")


def test_the_type_stub_names_what_the_module_exports():
    tree = ast.parse((ROOT / "vo3d_opt" / "_core.pyi").read_text())
    stubbed = {n.name for n in tree.body if isinstance(n, (ast.FunctionDef, ast.ClassDef))}
    stubbed |= {t.id for n in tree.body if isinstance(n, ast.AnnAssign) for t in [n.target]
                if isinstance(t, ast.Name) and not t.id.startswith("_")}
    exported = {name for name in dir(_core) if not name.startswith("_")}
    assert stubbed == exported
