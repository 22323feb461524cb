"""Figures and the replay GIF: formats, legends, the summary's figures on the plots, reference
lines, cropping, the frame rule; and the CLI options that ask for them."""
from __future__ import annotations

import copy
import re
from pathlib import Path

import numpy as np
import pytest
import yaml
from matplotlib.patches import Circle
from PIL import Image
from test_cli import SMALL, vo3d

from vo3d_opt.animation import MAX_FRAMES, frame_indices, write_animation
from vo3d_opt.figures import (
    figure_obstacle_distance,
    figure_top_view,
    figure_trajectories_3d,
    parse_zones,
    plot_obstacle_distance,
    plot_vehicle_distance,
    positions_at,
    prism_margin,
    scene_bounds,
    skipped_plots,
    write_plots,
)
from vo3d_opt.sim.metrics import nearest_obstacle_distance, nearest_vehicle_distance, summarize
from vo3d_opt.sim.scenario import scenario_from_dict
from vo3d_opt.sim.simulator import run_scenario

COMMON = {k: SMALL[k] for k in ("goal_tolerance", "limits", "sensing")}
MAGIC = {"png": b"\x89PNG\r\n\x1a\n", "pdf": b"%PDF-", "gif": b"GIF89a"}

#: One vehicle past a cylinder whose prism is larger than the default: 3 m from the body on
#: every side and on top (the default margin is 2 m); the vehicle's radius is 0.5 m.
LONE = {
    **COMMON,
    "name": "plots-lone",
    "dt": 0.2,
    "max_time": 14.0,
    "defaults": {"r_pz": 5.0, "radius": 0.5, "max_speed": 4.0},
    "agents": [{"id": "solo", "start": [-20.0, 0.0, 10.0], "goal": [20.0, 0.0, 10.0]}],
    "obstacles": [{"type": "cylinder", "center": [0.0, 6.0], "radius": 1.0, "height": 30.0,
                   "L_pz": 8.0, "h_pz": 33.0}],
}


def _crowd(n: int) -> dict:
    """n vehicles on a circle flying a short way towards its centre (13 > the legend limit)."""
    angles = np.linspace(0, 2 * np.pi, n, endpoint=False)
    agents = [{"id": f"c{i:02d}", "start": [60 * np.cos(a), 60 * np.sin(a), 20.0],
               "goal": [-60 * np.cos(a), -60 * np.sin(a), 20.0]} for i, a in enumerate(angles)]
    return {**COMMON, "name": "plots-crowd", "dt": 0.2, "max_time": 2.0,
            "defaults": {"r_pz": 5.0, "radius": 0.5, "max_speed": 4.0}, "agents": agents}


def _run(spec: dict):
    return run_scenario(scenario_from_dict(copy.deepcopy(spec)), progress=False)


@pytest.fixture(scope="module")
def pair():
    return _run(SMALL)


@pytest.fixture(scope="module")
def lone():
    return _run(LONE)


@pytest.fixture(scope="module")
def crowd():
    return _run(_crowd(13))


def _min_label(path: Path) -> str:
    """The "min X m" label of a distance plot, read from its SVG (as text, or as the comment
    matplotlib writes beside text drawn as paths)."""
    found = set(re.findall(r"min (\d+\.\d+) m", path.read_text()))
    assert len(found) == 1, found
    return found.pop()


# ---------------------------------------------------------------------- the summary's figures


def test_min_labels_are_the_summary_figures(pair, tmp_path):
    summary = summarize(pair)
    for plot, key, sampled in (
        (plot_vehicle_distance, "min_vehicle_distance", nearest_vehicle_distance),
        (plot_obstacle_distance, "min_obstacle_distance", nearest_obstacle_distance),
    ):
        expected = f"{summary[key]:.3f}"
        # the case is one where the samples alone would give another figure
        assert f"{sampled(pair).min():.3f}" != expected, key
        assert _min_label(plot(pair, tmp_path / f"{key}.svg")) == expected, key


def test_obstacle_reference_line_is_the_prism_margin(lone):
    body = lone.scenario.bodies[0]
    margin = body.side / 2.0 - body.radius
    assert margin == body.prism_height - body.height == pytest.approx(prism_margin(body)) == 3.0
    ax = figure_obstacle_distance(lone).axes[0]
    flat = [line for line in ax.get_lines() if len(set(line.get_ydata())) == 1
            and line.get_linestyle() == "--"]
    assert [line.get_ydata()[0] for line in flat] == [pytest.approx(margin)]
    texts = [t.get_text() for t in ax.get_legend().get_texts()]
    assert "prism margin = 3 m" in texts and not any("radius" in t for t in texts)


def test_one_vehicle_has_no_vehicle_distance_plot_and_says_so(lone, tmp_path):
    written = write_plots(lone, tmp_path)
    assert {p.name for p in written} == {"trajectories_3d.png", "top_view.png",
                                         "obstacle_distance.png"}
    assert not (tmp_path / "vehicle_distance.png").exists()
    assert "one vehicle" in skipped_plots(lone)["vehicle_distance"]


# --------------------------------------------------------------------------- formats, dpi


@pytest.mark.parametrize("fmt", ["png", "pdf", "svg"])
def test_every_figure_in_every_format(pair, tmp_path, fmt):
    written = write_plots(pair, tmp_path, fmt=fmt, dpi=60)
    assert sorted(p.name for p in written) == sorted(
        f"{n}.{fmt}" for n in ("trajectories_3d", "top_view", "vehicle_distance",
                               "obstacle_distance"))
    for path in written:
        head = path.read_bytes()[:200]
        if fmt == "svg":
            assert head.startswith(b"<?xml") and b"<svg" in head, path.name
        else:
            assert head.startswith(MAGIC[fmt]), path.name


def test_dpi_scales_png_pixels(lone, tmp_path):
    sizes = []
    for dpi in (50, 100):
        path = write_plots(lone, tmp_path / str(dpi), dpi=dpi)[1]  # top_view.png
        sizes.append(np.array(Image.open(path).size))
    assert np.allclose(sizes[1] / sizes[0], 2.0, atol=0.03)


@pytest.mark.parametrize("bad, field", [
    ({"fmt": "jpg"}, "fmt"), ({"dpi": 0}, "dpi"), ({"dpi": True}, "dpi"),
    ({"zones": "soon"}, "zones"), ({"zones": (-1.0,)}, "zones"), ({"zones": ["5"]}, "zones"),
])
def test_bad_figure_options_name_the_field(lone, tmp_path, bad, field):
    with pytest.raises(ValueError, match=field):
        write_plots(lone, tmp_path, **bad)
    assert not any(tmp_path.iterdir())


# ------------------------------------------------------------------- legends, colour bars


def _legend_texts(fig) -> list[str]:
    legends = [ax.get_legend() for ax in fig.axes if ax.get_legend()] + list(fig.legends)
    return [t.get_text() for leg in legends for t in leg.get_texts()]


def test_legends_explain_markers_outlines_and_zones(pair):
    for fig in (figure_top_view(pair), figure_trajectories_3d(pair)):
        texts = _legend_texts(fig)
        assert {"u0", "u1", "start", "goal"} <= set(texts), texts
        assert any(t.startswith("obstacle") for t in texts), texts
        assert any(t.startswith("protected zone r_pz") and "closest approach" in t
                   for t in texts), texts
    assert any(t.startswith("protected prism C_pz") for t in _legend_texts(figure_top_view(pair)))


def test_above_twelve_vehicles_a_named_sample_of_paths(crowd, pair):
    """13 vehicles are a swarm: the key names a sample of them, not all; 12 or fewer are all
    named, each in its own colour and pattern."""
    from vo3d_opt.figures.swarm import SAMPLE_PATHS

    for fig in (figure_top_view(crowd), figure_trajectories_3d(crowd)):
        named = {t.split()[0] for t in _legend_texts(fig)} & set(crowd.ids)
        assert len(named) == SAMPLE_PATHS, named
        assert not any(ax.get_ylabel().startswith("agent") for ax in fig.axes)
    assert {"u0", "u1"} <= set(_legend_texts(figure_top_view(pair)))


# ------------------------------------------------------------------------ protected zones


def _zone_circles(fig, r_pz: float) -> list[Circle]:
    return [p for p in fig.axes[0].patches if isinstance(p, Circle) and p.radius == r_pz]


def test_zones_at_chosen_times_and_none(pair):
    r_pz = float(pair.scenario.r_pz[0])
    circles = _zone_circles(figure_top_view(pair, zones=(1.0, 2.5)), r_pz)
    expected = np.vstack([positions_at(pair, 1.0)[:, :2], positions_at(pair, 2.5)[:, :2]])
    assert np.allclose(sorted(map(tuple, (c.center for c in circles))),
                       sorted(map(tuple, expected)))
    mid = 0.5 * (pair.positions[5] + pair.positions[6])
    assert np.allclose(positions_at(pair, 0.5 * (pair.times[5] + pair.times[6])), mid)
    assert _zone_circles(figure_top_view(pair, zones="none"), r_pz) == []
    assert len(_zone_circles(figure_top_view(pair), r_pz)) == 2  # the closest pair


def test_parse_zones():
    assert parse_zones("closest") == "closest" and parse_zones(" None ") == "none"
    assert parse_zones("10,20.5") == (10.0, 20.5)
    for bad in ("later", "1,,2", "-3", "nan"):
        with pytest.raises(ValueError, match="zones"):
            parse_zones(bad)


# ------------------------------------------------------------------------------- 3D view


def test_3d_view_is_to_scale_on_the_scene(pair):
    ax = figure_trajectories_3d(pair, zones="none").axes[0]
    lims = np.array([ax.get_xlim3d(), ax.get_ylim3d(), ax.get_zlim3d()])
    spans = lims[:, 1] - lims[:, 0]
    lo, hi = scene_bounds(pair)
    assert np.all(lims[:, 0] <= lo + 1e-9) and np.all(lims[:, 1] >= hi - 1e-9)
    # horizontally the limits hug the scene (a flat scene's z range is widened on purpose)
    assert np.all(spans[:2] <= 1.1 * (hi - lo)[:2])
    aspect = np.asarray(ax.get_box_aspect())
    assert np.allclose(aspect / aspect[0], spans / spans[0])  # equal scale on x, y, z


@pytest.mark.parametrize("name", ["trajectories_3d.png", "top_view.png"])
def test_saved_figures_have_no_wide_empty_margin(pair, tmp_path, name):
    write_plots(pair, tmp_path, dpi=100)
    ink = np.asarray(Image.open(tmp_path / name).convert("L")) < 250
    rows, cols = np.flatnonzero(ink.any(axis=1)), np.flatnonzero(ink.any(axis=0))
    h, w = ink.shape
    margins = [rows[0], h - 1 - rows[-1], cols[0], w - 1 - cols[-1]]
    assert max(margins) <= 0.03 * max(h, w), margins


# ----------------------------------------------------------------------------- animation


def test_frame_rule():
    assert list(frame_indices(5)) == [0, 1, 2, 3, 4]
    idx = frame_indices(1001)
    assert len(idx) == MAX_FRAMES and idx[0] == 0 and idx[-1] == 1000
    assert np.all(np.diff(idx) > 0) and np.ptp(np.diff(idx)) <= 1


def test_animation_gif_has_one_frame_per_sample(pair, tmp_path):
    path = write_animation(pair, tmp_path / "animation.gif")
    assert path.read_bytes()[:6] == MAGIC["gif"]
    gif = Image.open(path)
    assert gif.n_frames == len(pair.times) <= MAX_FRAMES


def test_long_run_is_subsampled_and_capped(tmp_path):
    long = dict(LONE, name="plots-long", max_time=120.0, obstacles=[],
                agents=[{"id": "far", "start": [0.0, 0.0, 10.0], "goal": [400.0, 30.0, 12.0]}])
    rec = _run(long)
    assert len(rec.times) > 500
    path = write_animation(rec, tmp_path / "a.gif")
    assert Image.open(path).n_frames == MAX_FRAMES
    size = path.stat().st_size
    capped = write_animation(rec, tmp_path / "b.gif", max_bytes=size // 3)
    frames = Image.open(capped).n_frames
    assert 10 <= frames < MAX_FRAMES
    assert capped.stat().st_size <= size // 3 or frames == 10


# ------------------------------------------------------------------------------------ CLI


@pytest.fixture(scope="module")
def small_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("plots") / "small.yaml"
    path.write_text(yaml.safe_dump(SMALL, sort_keys=False))
    return path


def test_cli_format_dpi_zones_animate(small_file, tmp_path):
    out = tmp_path / "out"
    res = vo3d("run", small_file, "--out", out, "--format", "pdf", "--dpi", "80", "--zones",
               "2,4", "--animate")
    assert res.returncode == 0, res.stderr
    for name in ("trajectories_3d", "top_view", "vehicle_distance", "obstacle_distance"):
        assert (out / f"{name}.pdf").read_bytes()[:5] == MAGIC["pdf"], name
    assert not list(out.glob("*.png"))
    gif = Image.open(out / "animation.gif")
    assert gif.format == "GIF" and gif.n_frames == len(frame_indices(
        len(list((out / "trajectories.csv").open())) // 2))
    assert f"wrote {out / 'animation.gif'}" in res.stderr


def test_cli_says_which_plot_it_leaves_out(tmp_path):
    lone = tmp_path / "lone.yaml"
    lone.write_text(yaml.safe_dump(LONE, sort_keys=False))
    res = vo3d("run", lone, "--out", tmp_path / "out")
    assert res.returncode == 0, res.stderr
    assert "not drawn: vehicle_distance (one vehicle" in res.stderr
    assert not (tmp_path / "out" / "vehicle_distance.png").exists()


@pytest.mark.parametrize("args, fragment", [
    (["--animate"], "--animate"),
    (["--format", "svg"], "--format"),
    (["--out", "X", "--format", "jpg"], "--format"),
    (["--out", "X", "--dpi", "ten"], "--dpi"),
    (["--out", "X", "--zones", "soon"], "--zones"),
])
def test_cli_rejects_bad_figure_options_before_running(small_file, tmp_path, args, fragment):
    res = vo3d("run", small_file, *[str(tmp_path / a) if a == "X" else a for a in args])
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and fragment in lines[0], res.stderr
    assert "running" not in res.stderr


# ----------------------------------------------------------------------------- swarms
@pytest.fixture(scope="module")
def swarm():
    return _run(_crowd(120))  # more than plots.SWARM_AGENTS


def test_drawn_samples_spread_evenly_and_keep_both_ends():
    from vo3d_opt.figures import drawn_samples

    assert drawn_samples(7, 10).tolist() == list(range(7))
    for n, budget in ((1001, 10), (2634, 200), (11, 4)):
        idx = drawn_samples(n, budget)
        assert idx[0] == 0 and idx[-1] == n - 1 and len(idx) <= budget
        assert np.all(np.diff(idx) > 0) and np.ptp(np.diff(idx)) <= 1


def test_a_swarms_paths_are_drawn_through_samples_of_its_record(swarm, monkeypatch):
    from vo3d_opt.figures import scene
    from vo3d_opt.figures.swarm import SAMPLE_PATHS

    assert swarm.n_agents > scene.SWARM_AGENTS and swarm.positions.shape[0] > 4
    monkeypatch.setattr(scene, "PLOT_POINTS", 4 * swarm.n_agents)  # four points per path
    ax = figure_top_view(swarm).axes[0]
    paths = [line for line in ax.get_lines() if len(line.get_xdata()) > 1]
    assert len(paths) == SAMPLE_PATHS and {len(line.get_xdata()) for line in paths} == {4}
    for line in paths:
        i = swarm.ids.index(line.get_gid())
        assert np.array_equal(line.get_xydata()[0], swarm.positions[0, i, :2])
        assert np.array_equal(line.get_xydata()[-1], swarm.positions[-1, i, :2])
    # the view still holds every position, not only the drawn ones
    flat = swarm.positions.reshape(-1, 3)
    lo, hi = scene_bounds(swarm)
    assert np.all(lo <= flat.min(axis=0)) and np.all(hi >= flat.max(axis=0))


def test_position_bounds_read_in_chunks_are_the_exact_extremes(swarm, monkeypatch):
    from vo3d_opt.figures import scene

    monkeypatch.setattr(scene, "CHUNK_ELEMENTS", 3 * swarm.n_agents * 2)  # two samples a chunk
    flat = swarm.positions.reshape(-1, 3)
    assert np.array_equal(scene.position_bounds(swarm),
                          np.stack([flat.min(axis=0), flat.max(axis=0)]))


def test_a_swarms_distances_are_bands_over_the_vehicles(swarm, monkeypatch):
    """The least line is the closest pair's distance at every sample (brute force over every
    pair), the median and the band at the drawn samples (brute force too), the key names
    them, and no colour bar names 120 vehicles."""
    from vo3d_opt.figures import distances, drawn_samples

    monkeypatch.setattr(distances, "BAND_SAMPLES", 4)
    fig = distances.figure_vehicle_distance(swarm)
    ax = fig.axes[0]
    idx = drawn_samples(swarm.positions.shape[0], 4)
    assert len(idx) == 4 < swarm.positions.shape[0]
    p = swarm.positions
    gaps = np.linalg.norm(p[:, :, None] - p[:, None, :], axis=-1)
    gaps[:, np.arange(swarm.n_agents), np.arange(swarm.n_agents)] = np.inf
    nearest = gaps.min(axis=2)  # (T+1, N)
    least = next(line for line in ax.get_lines() if line.get_color() == "k")
    np.testing.assert_allclose(least.get_xdata(), swarm.times)
    np.testing.assert_allclose(least.get_ydata(), nearest.min(axis=1), rtol=1e-12)
    median = next(line for line in ax.get_lines() if line.get_color() == distances.BAND_COLOR)
    np.testing.assert_allclose(median.get_xdata(), swarm.times[idx])
    np.testing.assert_allclose(median.get_ydata(), np.median(nearest[idx], axis=1), rtol=1e-12)
    texts = _legend_texts(fig)
    assert {"least over the vehicles", "5-95 % of the vehicles", "median"} <= set(texts)
    assert not any(a.get_ylabel().startswith("agent") for a in fig.axes)
