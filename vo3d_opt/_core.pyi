"""Type stub of the compiled core (vo3d_opt/algorithm/bindings.cpp). Arrays are numpy arrays
of the dtype and shape each entry's docstring in the Python modules gives; anything else raises
ValueError naming the argument. Shapes of the Python side (VOCones, VOPyramids,
AvoidancePlanes, VOs, Sections, Bounds) travel as tuples in their fields' order."""

from collections.abc import Sequence
from typing import Any

import numpy as np

OUT_SIZE: int
MANY_OUT_SIZE: int
AGENT_COLUMNS: int
FINE_SPEED_LEVELS: int
FINE_HEADING_STEP: float
LIMIT_TOL: float
NEVER: float

_Tuple = tuple[Any, ...]
_A = np.ndarray
# kind, curve, chord, chord_cs, apex, symmetry, halfplane (Sections' arrays)
_Sections = tuple[_A, _A, _A, _A, _A, _A, _A]

class Corrections:
    tg_range: bool
    symmetry_abs: bool
    triangle: bool
    base_chord: bool
    vo_lines: bool
    virtual_sphere: bool
    def __init__(self) -> None: ...

class Config:
    """Set field by field; the arrays are read back as lists."""

    reciprocal: bool
    horizon: float
    obstacle_horizon: float
    pz_buffer: float
    margin: float
    corrections: Corrections
    phi: Sequence[float]
    cos_phi: Sequence[float]
    sin_phi: Sequence[float]
    t: Sequence[float]
    cos_t: Sequence[float]
    sin_t: Sequence[float]
    speed_levels: int
    heading_step: float
    fallback_speed_levels: int
    fallback_heading_step: float
    fine: Config | None
    closing_guard: bool
    least_bad_escape: bool
    fine_fallback: bool
    def __init__(self) -> None: ...

class ObjectPath:
    def __init__(self, types: dict[str, Any]) -> None: ...
    def decide(
        self,
        own: Any,
        v_pref: Any,
        neighbors: Any,
        obstacles: Any,
        limits: Any,
        dt: Any,
        t0: float,
    ) -> Any: ...
    def decide_arrays(
        self,
        position: Any,
        velocity: Any,
        v_pref: Any,
        neighbors: Any,
        cooperative: Any,
        obstacles: Any,
        limits: Any,
        dt: Any,
        t0: float,
    ) -> Any: ...

class PlaneQPs:
    def __init__(
        self,
        vos: _Tuple,
        planes: _Tuple,
        G3: np.ndarray,
        h3: np.ndarray,
        initial: np.ndarray,
        cfg: Config,
        lazy: bool,
    ) -> None: ...
    @property
    def key(self) -> np.ndarray: ...
    @property
    def sol(self) -> np.ndarray: ...
    @property
    def included(self) -> np.ndarray: ...
    @property
    def w0(self) -> np.ndarray: ...
    @property
    def rows(self) -> np.ndarray: ...
    @property
    def rhs(self) -> np.ndarray: ...
    def add_rows(self, k: int, p: int) -> None: ...
    def gather(self, r: int, p: int) -> int: ...
    def solve(self, r: int, p: int, bounds: _Tuple) -> None: ...
    def solve_all(self, bounds: _Tuple) -> None: ...
    def search(self, bounds: _Tuple, tried: np.ndarray) -> tuple[int, int, int, int]: ...
    def lift(self, w: np.ndarray, p: int, out: np.ndarray) -> None: ...
    def entered(self, v: np.ndarray, out: np.ndarray) -> bool: ...
    def within(self, v: np.ndarray, bounds: _Tuple) -> bool: ...

def decide(
    p: np.ndarray,
    v_now: np.ndarray,
    v_pref: np.ndarray,
    nbrs: np.ndarray,
    prisms: np.ndarray,
    limits: np.ndarray,
    cfg: Config,
    out: np.ndarray,
) -> None: ...
def decide_rows(
    p: np.ndarray,
    v_now: np.ndarray,
    v_pref: Sequence[float] | np.ndarray,
    nbrs: Sequence[tuple[float, ...]] | np.ndarray,
    prisms: Sequence[tuple[float, ...]] | np.ndarray,
    limits: tuple[float, ...],
    cfg: Config,
    out: np.ndarray,
) -> None: ...
def decide_many(
    swarm: _Tuple, cfg: Config, threads: int, out: np.ndarray, lo: int = 0, hi: int = -1
) -> None: ...
def neighbor_lists(
    a: np.ndarray,
    b: np.ndarray,
    dist: np.ndarray,
    sensing_range: float,
    place: np.ndarray,
    k: int,
    span: np.ndarray,
) -> np.ndarray: ...
def nearest_lists(
    P: np.ndarray,
    who: np.ndarray,
    near: np.ndarray,
    far: np.ndarray,
    sensing_range: float,
    chosen: np.ndarray,
) -> np.ndarray: ...
def build_cones(
    p_A: np.ndarray,
    p_B: np.ndarray,
    apex: np.ndarray,
    r_pz: np.ndarray,
    reach: float,
    tau_min: float,
) -> _Tuple: ...
def min_speeds(cones: _Tuple) -> np.ndarray: ...
def outward_normals(R: np.ndarray, sin_alpha: np.ndarray, t: np.ndarray) -> np.ndarray: ...
def build_pyramids(p_A: np.ndarray, prisms: np.ndarray) -> _Tuple: ...
def prism_corners(frame: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray: ...
def avoidance_frame(direction: np.ndarray) -> np.ndarray: ...
def build_planes(direction: np.ndarray, phi: np.ndarray) -> _Tuple: ...
def in_vos(
    cones: _Tuple,
    pyramids: _Tuple,
    v: np.ndarray,
    horizon: float,
    tol: float,
    obstacle_horizon: float = ...,
) -> np.ndarray: ...
def cone_penetration(cones: _Tuple, v: np.ndarray) -> np.ndarray: ...
def entry_times(pyramids: _Tuple, v: np.ndarray) -> np.ndarray: ...
def clearances(
    cones: _Tuple, pyramids: _Tuple, v: np.ndarray, horizon: float, obstacle_horizon: float = ...
) -> np.ndarray: ...
def clearance_floors(cones: _Tuple, v: np.ndarray) -> np.ndarray: ...
def ball_in_cone(cones: _Tuple, k: int, c: np.ndarray, rho: float) -> bool: ...
def cone_sections(
    cones: _Tuple, planes: _Tuple, t: np.ndarray, corrections: Sequence[bool]
) -> _Sections: ...
def pyramid_sections(pyramids: _Tuple, planes: _Tuple) -> _Sections: ...
def pick(curve: np.ndarray, chord: np.ndarray, w0: np.ndarray) -> tuple[int, int, int]: ...
def build_vos(
    p: np.ndarray,
    v_now: np.ndarray,
    v_pref: np.ndarray,
    nbrs: np.ndarray,
    prisms: np.ndarray,
    bounds: _Tuple,
    cfg: Config,
) -> tuple[_Tuple, _Tuple, np.ndarray]: ...
def pref_clear(
    p: np.ndarray,
    v_now: np.ndarray,
    v_pref: np.ndarray,
    nbrs: np.ndarray,
    prisms: np.ndarray,
    bounds: _Tuple,
    cfg: Config,
) -> bool: ...
def decision_planes(vos: _Tuple, v_now: np.ndarray, cfg: Config) -> _Tuple: ...
def limit_rows(
    p: np.ndarray, v_now: np.ndarray, nbrs: np.ndarray, bounds: _Tuple, cfg: Config
) -> tuple[np.ndarray, np.ndarray]: ...
def escape_rows(vos: _Tuple, margin: float) -> tuple[np.ndarray, np.ndarray]: ...
def vz_range(z: float, bounds: _Tuple) -> tuple[float, float]: ...
def enforce_limits(v: np.ndarray, p: np.ndarray, bounds: _Tuple) -> np.ndarray: ...
def closing_rates(vos: _Tuple, v: np.ndarray) -> np.ndarray: ...
def times_to_intrusion(vos: _Tuple, v: np.ndarray) -> np.ndarray: ...
def zone_times(vos: _Tuple, k: int, v: np.ndarray) -> np.ndarray: ...
def zone_time_bound(vos: _Tuple, k: int, c: np.ndarray, rho: float) -> float: ...
def all_within(v: np.ndarray, G: np.ndarray, h: np.ndarray, bounds: _Tuple) -> np.ndarray: ...
def polar_grid(bounds: _Tuple, cfg: Config) -> np.ndarray: ...
def grid_of(
    bounds: _Tuple, cfg: Config, hazard: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...
def has_hazard(vos: _Tuple, nbrs: np.ndarray) -> bool: ...
def fallback(
    vos: _Tuple,
    planes: _Tuple,
    tried: np.ndarray,
    p: np.ndarray,
    v_now: np.ndarray,
    G3: np.ndarray,
    h3: np.ndarray,
    bounds: _Tuple,
    cfg: Config,
    hazard: bool,
) -> tuple[bool, np.ndarray, int]: ...
def least_bad(
    vos: _Tuple,
    planes: _Tuple,
    tried: np.ndarray,
    p: np.ndarray,
    v_now: np.ndarray,
    G3: np.ndarray,
    h3: np.ndarray,
    bounds: _Tuple,
    cfg: Config,
) -> np.ndarray: ...
def first_safe(
    vos: _Tuple, v: np.ndarray, G3: np.ndarray, h3: np.ndarray, bounds: _Tuple, cfg: Config
) -> int: ...
def nearest_in_disc(
    G: np.ndarray,
    h: np.ndarray,
    m: int,
    w0: np.ndarray,
    r_max: float,
    r_min: float,
    order: np.ndarray,
    out: np.ndarray,
) -> bool: ...
def lift(planes: _Tuple, w: np.ndarray, p: int, out: np.ndarray) -> None: ...
def qp_screen(
    P: np.ndarray,
    q: np.ndarray,
    C: np.ndarray,
    l: np.ndarray,
    u: np.ndarray,
    r: float,
    has_r: bool,
    m_ineq: int,
    m_eq: int,
) -> int: ...
def qp_violation(C: np.ndarray, l: np.ndarray, u: np.ndarray, x: np.ndarray, r: float) -> float: ...
def qp_rows_form(P: object, q: object, G: object, h: object) -> int: ...
def qp_rows_gap(G: np.ndarray, h: np.ndarray, x: object) -> float: ...
def first_bad(values: np.ndarray, max_magnitude: float, positive_from: int) -> int: ...
