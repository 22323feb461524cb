"""Near something that does not avoid, the default planes (``fine_planes``) and the default
grid (``fine_fallback``); and the fallbacks' grid of its own (``fallback_heading_step_deg``,
``fallback_speed_levels``) that leaves the sampled selection's grid alone."""
from __future__ import annotations

import numpy as np
import pytest

from encounters import COARSE, crowd
from vo3d_opt import AgentState, Limits, Neighbor, VelocitySelector
from vo3d_opt.formulations.common import Bounds, Options
from vo3d_opt.formulations.fallback import grid_of, py_polar_grid


def _hazard_decisions(n=120):
    """Decisions near the ground under an acceleration limit (as in the lagged sweep family),
    with cooperative neighbours and, in turn, obstacles in reach, a non-cooperative neighbour,
    or neither."""
    from vo3d_opt import Cylinder

    rng = np.random.default_rng(7)
    out = []
    for t in range(n):
        kind = ("obstacle", "noncoop", "none")[t % 3]
        p = np.array([0.0, 0.0, rng.uniform(1.0, 10.0)])
        v = rng.uniform(-4.0, 4.0, 3) * (1.0, 1.0, 0.3)
        nbrs = [Neighbor(position=tuple(p + rng.uniform(-15.0, 15.0, 3)),
                         velocity=tuple(rng.uniform(-3.0, 3.0, 3)), r_pz=6.0,
                         cooperative=not (kind == "noncoop" and k == 0)) for k in range(4)]
        obs = [Cylinder(center=tuple(rng.uniform(-12.0, 12.0, 2)), radius=rng.uniform(2.0, 5.0),
                        height=40.0) for _ in range(3)] if kind == "obstacle" else []
        limits = Limits(speed=(0.0, 5.0), altitude=(0.0, 40.0), acceleration=9.6)
        out.append((kind, dict(own=AgentState(position=p, velocity=v), neighbors=nbrs,
                               preferred_velocity=(4.5, 0.0, 0.0), obstacles=obs, dt=0.2,
                               limits=limits)))
    return out


@pytest.mark.parametrize("solver", ["exact2d", "daqp"])
def test_fine_fallback_is_the_default_grid_where_something_does_not_avoid(solver):
    """With the fast preset's coarse grid, a decision with an obstacle in reach or a non-cooperative
    neighbour falls back on the default grid (the same answer as the coarse planes with the
    default grid); one with cooperative neighbours only keeps the coarse grid (the same answer
    as ``fine_fallback=False``). The compiled kernel and a Python formulation alike. Among the
    decisions of each kind, some fall back and the two grids answer differently, so that
    either rule applied to the wrong kind would fail."""
    fast = VelocitySelector("plane_qp", solver, preset="paper", **COARSE)
    coarse = VelocitySelector("plane_qp", solver, preset="paper", **COARSE, fine_fallback=False)
    fine_grid = VelocitySelector("plane_qp", solver, preset="paper",
                                 **{**COARSE, "heading_step_deg": 10.0, "speed_levels": 9})
    fell_back = {"obstacle": 0, "noncoop": 0, "none": 0}
    grids_differ = dict(fell_back)
    for kind, kw in _hazard_decisions(60 if solver == "daqp" else 120):
        got = fast.select(**kw)
        want = (coarse if kind == "none" else fine_grid).select(**kw)
        np.testing.assert_array_equal(got.velocity, want.velocity)
        assert got.status == want.status
        if got.info.get("round") in ("sampled", "least_bad"):
            fell_back[kind] += 1
        grids_differ[kind] += not np.array_equal(coarse.select(**kw).velocity,
                                                  fine_grid.select(**kw).velocity)
    assert min(fell_back.values()) > 0 and min(grids_differ.values()) > 0, (fell_back,
                                                                            grids_differ)


@pytest.mark.parametrize("solver", ["exact2d", "daqp"])
def test_fine_planes_are_the_default_planes_where_something_does_not_avoid(solver):
    """Under the safe preset, a decision with an obstacle in reach or a non-cooperative
    neighbour plans on the default planes and tangent samples (the same answer, status and
    plane as safe on those planes); one with cooperative neighbours only keeps the coarse
    planes (as ``fine_planes=False``). The compiled kernel and a Python formulation alike; in
    each kind the two sets of planes answer differently somewhere, so that either rule applied
    to the wrong kind would fail."""
    safe = VelocitySelector("plane_qp", solver)
    coarse = VelocitySelector("plane_qp", solver, fine_planes=False)
    fine = VelocitySelector("plane_qp", solver, plane_step_deg=10.0, qp_samples=36)
    differ = {"obstacle": 0, "noncoop": 0, "none": 0}
    for kind, kw in _hazard_decisions(60 if solver == "daqp" else 120):
        got = safe.select(**kw)
        want = (coarse if kind == "none" else fine).select(**kw)
        np.testing.assert_array_equal(got.velocity, want.velocity)
        assert (got.status, got.plane) == (want.status, want.plane)
        differ[kind] += not np.array_equal(coarse.select(**kw).velocity,
                                           fine.select(**kw).velocity)
    assert min(differ.values()) > 0, differ


def test_fine_fallback_changes_nothing_with_the_default_grid():
    """The default grid is the fine one: ``fine_fallback`` off gives the same answers (the
    safe preset's rules, the fallbacks on the sampled grid's defaults)."""
    default_grid = {"fallback_heading_step_deg": None, "fallback_speed_levels": None}
    on = VelocitySelector(**default_grid)
    off = VelocitySelector(**default_grid, fine_fallback=False)
    fell_back = 0
    for _, kw in _hazard_decisions(60):
        got = on.select(**kw)
        np.testing.assert_array_equal(got.velocity, off.select(**kw).velocity)
        fell_back += got.info.get("round") in ("sampled", "least_bad")
    assert fell_back > 0


def test_a_lagged_vehicle_at_the_floor_stays_out_of_a_box_with_either_grid():
    """Encounter 5573 of the lagged sweep (seed 0): a vehicle pinned to the altitude floor beside
    a box. While a ray under the floor counted as a way past the box (the prism's bottom at the
    ground), it drifted into the prism on the fast preset's coarse grid and stayed out only
    with the default grid near obstacles (``fine_fallback``); with the prism reaching below the
    ground, it stays out with either grid."""
    from vo3d_opt.sim.scenario import scenario_variant
    from vo3d_opt.sim.simulator import run_scenario
    from vo3d_opt.sim.metrics import summarize
    from vo3d_opt.sweep import make_encounter
    sc = make_encounter("lagged", 0, 5573).load()
    intrusions = {}
    for fine in (False, True):
        fast = scenario_variant(sc, selector_options={"preset": "fast", "fine_fallback": fine})
        s = summarize(run_scenario(fast, progress=False))
        intrusions[fine] = s["obstacle_pz_intrusions"]
        assert s["collisions"] == 0
    assert intrusions == {False: 0, True: 0}, intrusions


def test_the_fallbacks_grid_of_their_own_leaves_the_sampled_grid_alone():
    """``fallback_heading_step_deg`` and ``fallback_speed_levels`` set the grid the fallbacks
    search (the sampled grid's own when none), not the sampled selection's grid: plane_qp
    answers with them as with the same values on the sampled grid, fallbacks included, and
    the safe preset's sampled grid is the default one while its fallbacks' is 8 x 3."""
    coarse = {"plane_step_deg": 45.0, "qp_samples": 12, "fine_planes": False}
    own = VelocitySelector(**coarse, fallback_heading_step_deg=45.0, fallback_speed_levels=3,
                           fine_fallback=False)
    shared = VelocitySelector(**coarse, heading_step_deg=45.0, speed_levels=3,
                              fallback_heading_step_deg=None, fallback_speed_levels=None,
                              fine_fallback=False)
    fine = VelocitySelector(**coarse, fallback_heading_step_deg=None, fallback_speed_levels=None,
                            fine_fallback=False)
    fell_back = differ = 0
    for _, kw in _hazard_decisions(60):
        got = own.select(**kw)
        np.testing.assert_array_equal(got.velocity, shared.select(**kw).velocity)
        fell_back += got.info.get("round") in ("sampled", "least_bad")
        differ += not np.array_equal(got.velocity, fine.select(**kw).velocity)
    assert fell_back > 0 and differ > 0
    bounds = Bounds(v_min=0.0, v_max=5.0, z_min=0.0, z_max=40.0, acceleration=float("nan"), dt=0.2)
    cfg = Options(fallback_heading_step_deg=45.0, fallback_speed_levels=3).config
    assert len(py_polar_grid(bounds, cfg)) == 36 * 8 + 1  # 10 degrees by 9 speeds, 0 once
    assert len(grid_of(bounds, cfg, False).points) == 8 * 2 + 1  # 45 degrees by 3 speeds
    assert len(grid_of(bounds, cfg, True).points) == 36 * 8 + 1  # near a hazard: the fine one


def test_the_sampled_selection_falls_back_on_its_own_grid():
    """The sampled formulation's least-bad velocity is one of its own candidates: under the
    safe preset (whose fallbacks' grid is 8 x 3) it answers as with no grid of the fallbacks'
    own, in crowds where nothing is safe; a coarse sampled grid answers otherwise."""
    safe = VelocitySelector("sampled")
    one_grid = VelocitySelector("sampled", fallback_heading_step_deg=None,
                                fallback_speed_levels=None)
    coarse = VelocitySelector("sampled", heading_step_deg=45.0, speed_levels=3)
    least_bad = differ = 0
    for case in range(12):
        kw = crowd(4000 + case, n=30, inside=True, closing=3.0)
        got = safe.select(**kw)
        np.testing.assert_array_equal(got.velocity, one_grid.select(**kw).velocity)
        least_bad += got.status == "infeasible_min_violation"
        differ += not np.array_equal(got.velocity, coarse.select(**kw).velocity)
    assert least_bad > 0 and differ > 0, (least_bad, differ)
