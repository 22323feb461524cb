"""The Python side of ``VelocitySelector.select_many``: the arrays checked, who
senses whom (k-d trees, never an N×N matrix), and the answer, ``SwarmDecision``.

Sensing, for deciding vehicle i (the same rules as a loop of ``select`` calls would apply):

* vehicles: every other vehicle j whose centre distance ``‖P[i] − P[j]‖`` is at most
  ``sensing_range`` (or, with ``max_neighbors = k``, the k nearest of them), in index order, each
  seen with ``r_pz = max(R[i], R[j])``, its current velocity, and as cooperative when it decides
  too. scipy's ``cKDTree`` proposes the candidates within a hair more than the range (with
  ``max_neighbors``, each vehicle's few nearest: a crowd does not cost the square of its size);
  the range and the ranking are then numpy's distance, so the neighbour sets are exactly those
  of a brute-force ``np.linalg.norm`` test;
* obstacles: all of them, in the order given (the same for every vehicle); with
  the ``obstacle_range`` extension only those whose surface is within that distance
  (``Cylinder.surface_distance`` / ``Box.surface_distance``), found through a 2D k-d tree over
  the vehicles so that many obstacles stay cheap;
* static spheres (the ``spheres`` extension, (S, 5): x, y, z, radius, r_pz): zero-velocity,
  non-cooperative neighbours with their own r_pz after the vehicles, filtered like the obstacles
  (surface distance ``max(‖p − c‖ − radius, 0)``).

Modules: ``checks`` (the arguments), ``sensing`` (who senses whom), ``inputs`` (the call as
arrays, and its answer), ``threads``, ``many`` (the call itself: compiled, or a loop of
``select``).
"""

from __future__ import annotations

from .inputs import SwarmDecision, SwarmInputs
from .sensing import obstacle_links, sphere_links, vehicle_links
from .threads import cores, thread_count

__all__ = [
    "SwarmDecision",
    "SwarmInputs",
    "cores",
    "obstacle_links",
    "sphere_links",
    "thread_count",
    "vehicle_links",
]
