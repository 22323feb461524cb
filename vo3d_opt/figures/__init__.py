"""Figures of a run, like the paper's Figs. 13-20: 3D trajectories, the top view with the named
obstacles, and the vehicle-vehicle and vehicle-obstacle distances over time.

Figures are drawn on ``matplotlib.figure.Figure`` with the Agg canvas, so importing this package
never changes the global matplotlib backend (notebooks keep theirs). ``figure_*`` build a
figure; ``plot_*`` write it to a file whose suffix (``.png``, ``.pdf`` or ``.svg``) sets the
format, cropped to what is drawn; :func:`write_plots` writes them all. PDF keeps its fonts as
TrueType and SVG its text as text, so both stay editable (journals reject Type 3 fonts).

Every figure explains what it draws in its key, labels are placed where they cross nothing
(:mod:`.labels`), sizes suit print and the colours stay apart under colour-vision deficiencies
(:mod:`.style`). Up to LEGEND_MAX_AGENTS vehicles each is drawn and named; a larger run is drawn
as a swarm (:mod:`.swarm`): occupancy, its closest pairs numbered, a named sample of paths, and
distance bands. Modules: ``style`` (print style, palette, writing files), ``scene`` (what is read
from the record), ``labels``, ``keys`` (legends), ``topview``, ``view3d``, ``distances``,
``swarm``, ``output`` (``plot_*``, ``write_plots``).
"""

from .distances import (
    BAND_SAMPLES,
    coinciding,
    distance_samples,
    figure_obstacle_distance,
    figure_vehicle_distance,
    obstacle_margins,
    swarm_bands,
)
from .keys import PRISM_LABEL, ZONE_DASHES, agent_key, key_handles, zone_dash
from .labels import crossings, place_label
from .output import (
    figure_top_view,
    plot_obstacle_distance,
    plot_top_view,
    plot_trajectories_3d,
    plot_vehicle_distance,
    skipped_plots,
    write_plots,
)
from .scene import (
    CLOSEST_PAIRS,
    DEFAULT_ZONES,
    PLOT_POINTS,
    SWARM_AGENTS,
    Zones,
    ZoneSnapshot,
    box_corners,
    chunk_samples,
    closest_pairs,
    drawn_positions,
    drawn_samples,
    nearest_passes,
    obstacle_names,
    parse_zones,
    position_bounds,
    positions_at,
    prism_margin,
    prism_square,
    scene_bounds,
    zone_snapshots,
)
from .style import (
    DEFAULT_DPI,
    FORMATS,
    LEGEND_MAX_AGENTS,
    OBSTACLE_GREY,
    PALETTE,
    PRISM_GREY,
    UNSENSED_GREY,
    agent_colors,
    agent_styles,
    check_dpi,
    content_bbox,
    figure_format,
    new_figure,
    save_figure,
)
from .swarm import figure_swarm_top_view, occupancy, sample_agents
from .topview import draw_obstacles_2d, figure_agents_top_view, label_obstacles
from .view3d import figure_trajectories_3d

__all__ = [
    "BAND_SAMPLES",
    "CLOSEST_PAIRS",
    "DEFAULT_DPI",
    "DEFAULT_ZONES",
    "FORMATS",
    "LEGEND_MAX_AGENTS",
    "OBSTACLE_GREY",
    "PALETTE",
    "PLOT_POINTS",
    "PRISM_GREY",
    "PRISM_LABEL",
    "SWARM_AGENTS",
    "UNSENSED_GREY",
    "ZONE_DASHES",
    "ZoneSnapshot",
    "Zones",
    "agent_colors",
    "agent_key",
    "agent_styles",
    "box_corners",
    "check_dpi",
    "chunk_samples",
    "closest_pairs",
    "coinciding",
    "content_bbox",
    "crossings",
    "distance_samples",
    "draw_obstacles_2d",
    "drawn_positions",
    "drawn_samples",
    "figure_format",
    "figure_obstacle_distance",
    "figure_swarm_top_view",
    "figure_agents_top_view",
    "figure_top_view",
    "figure_trajectories_3d",
    "figure_vehicle_distance",
    "key_handles",
    "label_obstacles",
    "nearest_passes",
    "new_figure",
    "obstacle_margins",
    "obstacle_names",
    "occupancy",
    "parse_zones",
    "place_label",
    "plot_obstacle_distance",
    "plot_top_view",
    "plot_trajectories_3d",
    "plot_vehicle_distance",
    "position_bounds",
    "positions_at",
    "prism_margin",
    "prism_square",
    "sample_agents",
    "save_figure",
    "scene_bounds",
    "skipped_plots",
    "swarm_bands",
    "write_plots",
    "zone_dash",
    "zone_snapshots",
]
