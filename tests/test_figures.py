"""The figures a reviewer would accept: labels that cross nothing, one curve per vehicle pair,
the protected prism as the square the planner turns, every obstacle named as the summary names
it, a swarm's occupancy and closest pairs, a side view that shows no vehicle inside an obstacle
it is beside, and sizes and units for print."""
from __future__ import annotations

import copy
import itertools
import math

import numpy as np
import pytest
from matplotlib.collections import LineCollection, QuadMesh
from matplotlib.lines import Line2D
from matplotlib.patches import Polygon
from matplotlib.text import Text
from test_cli import SMALL

from vo3d_opt.animation import build_replay, show_frame, write_frame
from vo3d_opt.figures import (
    PRISM_LABEL,
    closest_pairs,
    coinciding,
    crossings,
    figure_obstacle_distance,
    figure_top_view,
    figure_trajectories_3d,
    figure_vehicle_distance,
)
from vo3d_opt.figures.distances import PAIR_CURVES
from vo3d_opt.figures.labels import text_box
from vo3d_opt.figures.sections import side_sections
from vo3d_opt.figures.swarm import SAMPLE_PATHS, pair_points
from vo3d_opt.geometry import vo_pyramids
from vo3d_opt.sim.metrics import (
    closest_vehicle_approach,
    pair_min_distances,
    physical_obstacle_names,
    summarize,
)
from vo3d_opt.sim.scenario import bundled_dir, prism_contains, scenario_from_dict
from vo3d_opt.sim.simulator import run_scenario

FIGURES = (figure_top_view, figure_trajectories_3d, figure_vehicle_distance,
           figure_obstacle_distance)


def _bundled(name: str, **kw):
    return run_scenario(bundled_dir() / f"{name}.yaml", progress=False, **kw)


@pytest.fixture(scope="module")
def case2():
    return _bundled("paper-case2-two-uav-six-obstacles")


@pytest.fixture(scope="module")
def case1():
    return _bundled("paper-case1-ten-uav-crossing")


@pytest.fixture(scope="module")
def crossing():
    """1,000 vehicles, the first 40 steps of the bundled crossing."""
    return _bundled("random-crossing-1000", max_steps=40)


def _texts(fig) -> list[tuple[object, Text]]:
    return [(ax, t) for ax in fig.axes for t in ax.texts if t.get_visible() and t.get_text()]


def _legend_texts(fig) -> list[str]:
    legends = [ax.get_legend() for ax in fig.axes if ax.get_legend()] + list(fig.legends)
    return [t.get_text() for leg in legends for t in leg.get_texts()]


# ------------------------------------------------------------- 1. labels cross nothing


@pytest.mark.parametrize("figure", FIGURES, ids=lambda f: f.__name__)
def test_labels_cross_no_line_no_shape_and_no_other_label(case2, figure):
    fig = figure(case2)
    texts = _texts(fig)
    assert texts
    renderer = fig.canvas.get_renderer()
    for ax, text in texts:
        assert crossings(ax, text) == 0, text.get_text()
    for (_, a), (_, b) in itertools.combinations(texts, 2):
        assert not text_box(a, renderer).overlaps(text_box(b, renderer)), (a, b)


def test_min_label_is_clear_of_the_margin_line(case2):
    """The case where "min 3.100 m" was struck through by the prism-margin line."""
    ax = figure_obstacle_distance(case2).axes[0]
    label = next(t for t in ax.texts if t.get_text().startswith("min "))
    assert label.get_text() == f"min {summarize(case2)['min_obstacle_distance']:.3f} m"
    box = text_box(label, ax.figure.canvas.get_renderer())
    margins = [line for line in ax.get_lines() if line.get_label().startswith("_child")
               and len(set(line.get_ydata())) == 1 and line.get_linestyle() != "None"]
    assert margins
    for line in margins:
        y = ax.transData.transform((0.0, line.get_ydata()[0]))[1]
        assert not box.y0 <= y <= box.y1


# ------------------------------------------------------------- 2. one curve per pair


def _pair_lines(ax) -> list[Line2D]:
    return [line for line in ax.get_lines() if "–" in str(line.get_gid())]


def test_two_vehicles_have_one_pair_curve(case2):
    fig = figure_vehicle_distance(case2)
    lines = _pair_lines(fig.axes[0])
    assert [line.get_gid() for line in lines] == ["u0–u1"]
    p = case2.positions
    np.testing.assert_allclose(lines[0].get_ydata(), np.linalg.norm(p[:, 0] - p[:, 1], axis=1))
    texts = _legend_texts(fig)
    assert "u0–u1" in texts and "u0" not in texts and "u1" not in texts


def test_the_closest_pairs_are_drawn_each_its_own_way(case1):
    """Ten vehicles: the PAIR_CURVES closest pairs (brute force over all 45) in colour and
    pattern of their own, each the pair's distance; the other 40 together, grey."""
    ax = figure_vehicle_distance(case1).axes[0]
    lines = _pair_lines(ax)
    ii, jj, dmin = pair_min_distances(case1.positions)
    order = np.argsort(dmin, kind="stable")
    expected = [f"{case1.ids[ii[k]]}–{case1.ids[jj[k]]}" for k in order[:PAIR_CURVES]]
    assert [line.get_gid() for line in lines] == expected
    p = case1.positions
    for line, k in zip(lines, order[:PAIR_CURVES], strict=True):
        np.testing.assert_allclose(line.get_ydata(), np.linalg.norm(p[:, ii[k]] - p[:, jj[k]],
                                                                    axis=1))
    looks = {(line.get_color(), str(line.get_linestyle())) for line in lines}
    assert len(looks) == PAIR_CURVES
    (others,) = [c for c in ax.collections if isinstance(c, LineCollection)]
    assert len(others.get_segments()) == len(dmin) - PAIR_CURVES


def test_coinciding_curves_are_dashed_over_and_said():
    d = np.array([[1.0, 1.0, 5.0], [2.0, 2.001, 4.0], [3.0, 3.0, 3.0]])
    assert coinciding(d) == [None, 0, None]
    mirrored = copy.deepcopy(SMALL)
    mirrored["agents"] = [
        {"id": "north", "start": [-20.0, 8.0, 20.0], "goal": [20.0, 8.0, 20.0]},
        {"id": "south", "start": [-20.0, -8.0, 20.0], "goal": [20.0, -8.0, 20.0]},
    ]
    mirrored["obstacles"][0]["center"] = [0.0, 0.0]
    rec = run_scenario(scenario_from_dict(mirrored), progress=False)
    fig = figure_obstacle_distance(rec)
    north, south = (line for line in fig.axes[0].get_lines() if line.get_gid() in rec.ids)
    np.testing.assert_allclose(north.get_ydata(), south.get_ydata(), atol=1e-6)
    assert north.get_linestyle() == "-" and south.get_linestyle() == "--"  # OVER_DASH
    assert "south (on north)" in _legend_texts(fig)


# --------------------------------------------------- 3. the prism as the planner's square


def test_prism_is_the_planned_square_facing_the_nearest_pass(case2):
    fig = figure_top_view(case2)
    ax = fig.axes[0]
    squares = [p for p in ax.patches if isinstance(p, Polygon) and p.get_gid() == "prism"]
    bodies = case2.scenario.bodies
    assert len(squares) == len(bodies) == int(case2.scenario.sensed.sum())
    p = case2.positions.reshape(-1, 3)
    for square, body in zip(squares, bodies, strict=True):
        corners = square.get_xy()[:4]
        # the planner's prism (section 4.1) seen from the vehicle position nearest the axis
        seen = p[np.argmin(np.linalg.norm(p[:, :2] - body.center, axis=1))]
        planned = vo_pyramids(seen, [body]).corners[0][:, :2] + seen[:2]
        assert sorted(map(tuple, corners.round(6))) == sorted(set(map(tuple, planned.round(6))))
        sides = np.linalg.norm(np.diff(np.vstack([corners, corners[:1]]), axis=0), axis=1)
        np.testing.assert_allclose(sides, body.side)
    assert PRISM_LABEL in _legend_texts(fig)


# --------------------------------------------------------- 4. obstacles named on the map


def test_every_obstacle_is_named_on_the_map_as_in_the_summary(case2):
    names = physical_obstacle_names(case2)
    ax = figure_top_view(case2).axes[0]
    labels = {t.get_text(): t for t in ax.texts if t.get_text().startswith("obstacles")}
    assert sorted(labels) == sorted(names)
    centres = np.array([ax.transData.transform(b.center) for b in case2.scenario.bodies])
    renderer = ax.figure.canvas.get_renderer()
    for k, name in enumerate(names):  # each name nearer its own obstacle than any other
        box = text_box(labels[name], renderer)
        gaps = [math.dist(c, np.clip(c, box.min, box.max)) for c in centres]
        assert int(np.argmin(gaps)) == k, name
    shown_3d = {t.get_text() for t in figure_trajectories_3d(case2).axes[0].texts}
    assert shown_3d and shown_3d <= set(names)


# --------------------------------------------------------------------------- 5. swarms


def test_a_thousand_vehicles_show_occupancy_and_the_closest_pairs(crossing):
    summary = summarize(crossing)
    closest = closest_vehicle_approach(crossing)
    pairs = closest_pairs(crossing)
    assert pairs[0].distance == summary["min_vehicle_distance"]
    assert pairs[0].time == closest.time
    assert [a.distance for a in pairs] == sorted(a.distance for a in pairs)

    fig = figure_top_view(crossing)
    ax = fig.axes[0]
    (mesh,) = [c for c in ax.collections if isinstance(c, QuadMesh)]
    cell = np.diff(mesh.get_coordinates()[0, :2, 0])[0]
    flying = (~crossing.arrived).sum() * crossing.dt  # vehicle-seconds, every sample one step
    assert float(mesh.get_array().sum()) * cell**2 == pytest.approx(flying, rel=0.02)
    rings = [c for c in ax.collections if len(c.get_offsets()) == len(pairs)]
    assert any(np.allclose(c.get_offsets(), pair_points(crossing, pairs)[:, :2]) for c in rings)
    assert {t.get_text() for t in ax.texts} >= {str(k + 1) for k in range(len(pairs))}
    ids = crossing.ids
    first = f"1: {ids[pairs[0].agent]}–{ids[pairs[0].other]}, {pairs[0].distance:.2f} m"
    assert any(t.startswith(first) for t in _legend_texts(fig))
    paths = [line for line in ax.get_lines() if len(line.get_xdata()) > 1]
    assert len(paths) == SAMPLE_PATHS
    assert {ids[pairs[0].agent], ids[pairs[0].other]} <= {line.get_gid() for line in paths}

    dist = figure_vehicle_distance(crossing).axes[0]
    marked = np.vstack([line.get_xydata() for line in dist.get_lines()
                        if line.get_marker() == "o"])
    assert np.any(np.all(np.isclose(marked, [closest.time, summary["min_vehicle_distance"]]),
                         axis=1))
    assert {t.get_text() for t in dist.texts} >= {"1", f"min {closest.distance:.3f} m"}


# ---------------------------------------------------------------- 6. the replay's side view


def _inside(record, section, p: np.ndarray) -> np.ndarray:
    """Whether points p (N, 3) are inside the obstacle part a section cuts (3D, brute)."""
    sc = record.scenario
    names = physical_obstacle_names(record)
    if section.kind == "sphere":
        s = sc.spheres[int(section.name.split("[")[1][:-1])]
        return np.linalg.norm(p - s.center, axis=1) < s.radius
    body = sc.bodies[names.index(section.name)]
    if section.kind == "prism":
        return prism_contains(body, p)
    return body.surface_distance(p) == 0.0


def test_side_view_draws_no_obstacle_over_a_vehicle_outside_it(case2):
    p = case2.positions
    drawn = 0
    fooled = 0  # samples where the whole silhouette would cover a vehicle beside a pillar
    for k in range(p.shape[0]):
        cuts = side_sections(case2, p[k])
        drawn += len(cuts)
        for cut in cuts:
            covered = cut.covers(p[k, :, 0], p[k, :, 2])
            assert np.all(_inside(case2, cut, p[k])[covered]), (k, cut)
        for body in case2.scenario.bodies:
            whole = (np.abs(p[k, :, 0] - body.center[0]) < body.radius) & (
                p[k, :, 2] < body.height)
            fooled += int(np.any(whole & (body.surface_distance(p[k]) > 0)))
    assert drawn > 0 and fooled > 0


def test_replay_frame_draws_the_side_sections(case2, tmp_path):
    replay = build_replay(case2)
    for k in (0, 40, 120):
        cuts = show_frame(replay, case2, k)
        shown = {key for key, patch in replay.cuts.items() if patch.get_visible()}
        assert shown == {(c.kind, c.name) for c in cuts}
        for c in cuts:
            if c.kind != "sphere":
                x, z = replay.cuts[c.kind, c.name].get_xy()
                assert (x, z) == pytest.approx((c.x0, c.z0))
    path = write_frame(case2, tmp_path / "frame.png", time=24.4, dpi=60)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


# ------------------------------------------------------------------------------ print


@pytest.mark.parametrize("figure", FIGURES, ids=lambda f: f.__name__)
def test_print_sizes_and_units(case2, crossing, figure):
    for rec in (case2, crossing):
        fig = figure(rec)
        if fig is None:
            continue
        for text in fig.findobj(Text):
            if text.get_visible() and text.get_text().strip():
                assert text.get_fontsize() >= 7.5, text.get_text()
        for ax in fig.axes:
            for label in (ax.get_xlabel(), ax.get_ylabel()):
                assert not label or "(" in label and label.endswith(")"), label
            if ax.axison and ax.name != "3d" and ax.get_label() != "<colorbar>":
                assert ax.get_xlabel() and ax.get_ylabel(), ax
