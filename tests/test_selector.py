"""VelocitySelector: its documented promises, properties over random
encounters checked against the exact 3D membership, and the hard cases."""
from __future__ import annotations

import numpy as np
import pytest
from encounters import encounters
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vo3d_opt import (
    AgentState,
    Box,
    Cylinder,
    Limits,
    Neighbor,
    VelocitySelector,
)
from vo3d_opt.formulations.common import Options, prepare
from vo3d_opt.geometry import build_cones
from vo3d_opt.geometry.membership import in_vo_cones
from vo3d_opt.solvers import (
    Backend,
    Result,
    available_qp_solvers,
    register_backend,
    unregister_backend,
)

QP_SOLVERS = available_qp_solvers()
SETTINGS = dict(deadline=None, suppress_health_check=[HealthCheck.too_slow], derandomize=True)

CONTRACT = dict(
    own=AgentState(position=(0.0, 0.0, 20.0), velocity=(4.0, 0.0, 0.0)),
    preferred_velocity=(4.0, 0.0, 0.0),
    neighbors=[Neighbor(position=(30.0, 0.0, 20.0), velocity=(-4.0, 0.0, 0.0), r_pz=10.0)],
    obstacles=[Cylinder(center=(15.0, 8.0), radius=3.0, height=30.0),
               Box(center=(40.0, -5.0), size=(6.0, 4.0), height=25.0, yaw=0.3)],
    limits=Limits(speed=(0.0, 4.0), altitude=(0.0, 40.0)),
    dt=0.2,
)


def exact(kw, sel=None):
    """The encounter as the exact checker sees it with the options ``sel`` plans with (None:
    the paper's): the VOs its answers must keep out of."""
    options = Options() if sel is None else sel.options_for(kw["limits"].v_max, kw["dt"])
    return prepare(kw["own"], np.asarray(kw["preferred_velocity"], float), kw["neighbors"],
                   kw["obstacles"], kw["limits"], kw["dt"], options)


def assert_within_limits(kw, v):
    lim = kw["limits"]
    assert v.shape == (3,) and np.all(np.isfinite(v))
    assert np.linalg.norm(v) <= lim.v_max + 1e-6
    z = kw["own"].position[2] + v[2] * kw["dt"]
    assert lim.z_min - 1e-6 <= z <= lim.z_max + 1e-6


def safe(kw, v, sel=None) -> bool:
    return not exact(kw, sel).unsafe(v)[0]


@pytest.mark.parametrize("formulation,solver", [("sampled", None), ("nlp", "casadi")]
                         + [("plane_qp", s) for s in QP_SOLVERS]
                         + [("cone_qp", s) for s in QP_SOLVERS if s != "exact2d"])
def test_contract_example(formulation, solver):
    sel = VelocitySelector(formulation=formulation, solver=solver)
    d = sel.select(**CONTRACT)
    assert isinstance(d.velocity, np.ndarray) and d.velocity.shape == (3,)
    assert isinstance(d.status, str) and isinstance(d.solve_time, float) and d.solve_time > 0
    assert d.status == "optimal"
    assert safe(CONTRACT, d.velocity, sel)
    assert_within_limits(CONTRACT, d.velocity)


@settings(max_examples=60, **SETTINGS)
@given(encounters())
def test_plane_qp_safe_whenever_sampled_is_and_no_worse(kw):
    """On the same planes, with its fallbacks on the sampled grid (the safe preset's own
    fallbacks' grid is coarser)."""
    sel = VelocitySelector("sampled")
    ref = sel.select(**kw)
    got = VelocitySelector("plane_qp", fallback_heading_step_deg=None,
                           fallback_speed_levels=None).select(**kw)
    for d in (ref, got):
        assert_within_limits(kw, d.velocity)
    if ref.status == "optimal":
        assert safe(kw, ref.velocity, sel)
        assert got.status == "optimal" and safe(kw, got.velocity, sel)
        o = Options()
        v_max = kw["limits"].v_max
        resolution = v_max / (o.speed_levels - 1) + v_max * np.deg2rad(o.heading_step_deg)
        dev = exact(kw).deviation
        assert dev(got.velocity)[0] <= dev(ref.velocity)[0] + resolution


@settings(max_examples=60, **SETTINGS)
@given(encounters())
def test_fast_options_try_fewer_velocities_never_an_unchecked_one(kw):
    """The fast preset (fewer planes, tangent points and grid velocities): every answer within the
    limits, every optimal one outside every VO by the exact 3D check, as with the defaults; an
    answer on a plane is on one of its 5 planes (every 45 degrees), not the defaults' 19."""
    sel = VelocitySelector(preset="fast")
    assert len(sel.options_for(4.0, 0.2).config.phi) == 5
    d = sel.select(**kw)
    assert_within_limits(kw, d.velocity)
    assert d.status in ("optimal", "inside_protected_zone", "infeasible_min_violation")
    if d.status == "optimal":
        assert safe(kw, d.velocity, sel)
    if d.plane is not None:
        turns = np.degrees(d.plane) / 45.0
        assert abs(turns - round(turns)) < 1e-9


@settings(max_examples=25, **SETTINGS)
@given(encounters())
def test_cone_qp_and_nlp(kw):
    start = VelocitySelector("plane_qp").select(**kw)
    for form in ("cone_qp", "nlp"):
        sel = VelocitySelector(form)
        d = sel.select(**kw)
        assert_within_limits(kw, d.velocity)
        if d.status == "optimal":
            assert safe(kw, d.velocity, sel)
    d = VelocitySelector("nlp").select(**kw)
    if start.status == "optimal":  # the NLP starts from plane_qp's answer and never does worse
        dev = exact(kw).deviation
        assert d.status == "optimal"
        assert dev(d.velocity)[0] <= dev(start.velocity)[0] + 1e-9


@pytest.mark.parametrize("solver", QP_SOLVERS)
@settings(max_examples=8, **SETTINGS)
@given(kw=encounters(max_neighbors=6, max_obstacles=3))
def test_every_backend_keeps_limits_and_safety(solver, kw):
    sel = VelocitySelector("plane_qp", solver=solver)
    d = sel.select(**kw)
    assert_within_limits(kw, d.velocity)
    if d.status == "optimal":
        assert safe(kw, d.velocity, sel)


# --- hard cases never raise ------------------------------------------------------------------

def surrounded():
    p = np.array([0.0, 0.0, 20.0])
    dirs = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1],
                     [1, 1, 1], [1, 1, -1], [1, -1, 1], [1, -1, -1], [-1, 1, 1], [-1, 1, -1],
                     [-1, -1, 1], [-1, -1, -1]], float)
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    nbs = [Neighbor(position=p + 11.0 * d, velocity=-2.0 * d, r_pz=10.0) for d in dirs]
    return dict(own=AgentState(position=p, velocity=(1.0, 0, 0)), preferred_velocity=(3.0, 0, 0),
                neighbors=nbs, obstacles=[], limits=Limits(speed=(0, 4), altitude=(0, 40)), dt=0.2)


@pytest.mark.parametrize("formulation", ["sampled", "plane_qp", "cone_qp", "nlp"])
def test_surrounded_returns_least_bad(formulation):
    kw = surrounded()
    assert exact(kw).unsafe(np.zeros((1, 3)))[0]  # even hovering is unsafe: no safe velocity
    d = VelocitySelector(formulation).select(**kw)
    assert d.status == "infeasible_min_violation"
    assert_within_limits(kw, d.velocity)


@pytest.mark.parametrize("formulation", ["sampled", "plane_qp", "cone_qp", "nlp"])
def test_inside_protected_zone_escapes(formulation):
    own = AgentState(position=(0.0, 0.0, 20.0), velocity=(2.0, 0.0, 0.0))
    nb = Neighbor(position=(5.0, 0.0, 20.0), velocity=(0.0, 0.0, 0.0), r_pz=10.0)
    kw = dict(own=own, preferred_velocity=(4.0, 0.0, 0.0), neighbors=[nb], obstacles=[],
              limits=Limits(speed=(0, 4), altitude=(0, 40)), dt=0.2)
    d = VelocitySelector(formulation).select(**kw)
    assert d.status == "inside_protected_zone"
    # not closing in (IPOPT's answer within its tolerance of hovering)
    assert d.velocity @ (nb.position - own.position) <= (1e-6 if formulation == "nlp" else 1e-9)
    assert_within_limits(kw, d.velocity)


class Exploding(Backend):
    name, has_cones, kind = "exploding", False, "qp"

    def solve(self, qp, warm_start=None):
        raise RuntimeError("boom")


class Garbage(Backend):
    name, has_cones, kind = "garbage", False, "qp"

    def solve(self, qp, warm_start=None):
        return Result(np.full(qp.n, 1e3), "optimal", self.name)  # violates the speed bound


@pytest.mark.parametrize("backend", [Exploding(), Garbage()])
def test_failing_backend_falls_back(backend):
    register_backend(backend.name, backend)
    try:
        sel = VelocitySelector("plane_qp", solver=backend.name)
        d = sel.select(**CONTRACT)
    finally:
        unregister_backend(backend.name)
    assert d.status == "solver_failed_fallback"
    assert safe(CONTRACT, d.velocity, sel)
    assert_within_limits(CONTRACT, d.velocity)


# --- options -----------------------------------------------------------------------------------

@settings(max_examples=15, **SETTINGS)
@given(encounters(max_neighbors=5, max_obstacles=2))
def test_acceleration_limit(kw):
    a_max = 2.0
    kw = dict(kw, limits=Limits(speed=kw["limits"].speed, altitude=kw["limits"].altitude, acceleration=a_max),
              own=AgentState(position=kw["own"].position, velocity=np.zeros(3)))
    d = VelocitySelector("plane_qp").select(**kw)
    assert np.all(np.abs(d.velocity) <= a_max * kw["dt"] + 1e-6)  # whatever the status


@pytest.mark.parametrize("a_max", [0.5, 2.0, 8.0])
def test_vz_range_leaves_room_to_brake_before_the_band_edges(a_max):
    """With an acceleration limit, the vertical speeds allowed towards an edge d away are those
    from which one step and then braking at a_max stop short of it (brute force over speeds),
    and no fewer; without one, one step's worth of the band."""
    from vo3d_opt.formulations.common import Bounds, vz_range

    dt, z_min, z_max = 0.2, 0.0, 12.0
    speeds = np.linspace(0.0, 4.0, 4001)
    for z in np.linspace(0.01, 11.99, 97):
        lo, hi = vz_range(z, Bounds(v_min=0.0, v_max=4.0, z_min=z_min, z_max=z_max,
                                    acceleration=a_max, dt=dt))
        for edge, s_allowed in ((z - z_min, -lo), (z_max - z, hi)):
            stops = speeds[speeds * dt + speeds**2 / (2 * a_max) <= edge]
            assert stops.max() - 2e-3 <= s_allowed <= stops.max() + 2e-3, (z, edge)  # grid step 1e-3
        free = vz_range(z, Bounds(v_min=0.0, v_max=4.0, z_min=z_min, z_max=z_max,
                                  acceleration=float("nan"), dt=dt))
        assert free == pytest.approx((max(-z / dt, -4.0), min((z_max - z) / dt, 4.0)))
    # out of a narrow band: back towards it no faster than the far edge allows, not at v_max
    narrow = Bounds(v_min=0.0, v_max=4.0, z_min=6.0, z_max=6.5, acceleration=a_max, dt=dt)
    for z, far in ((5.0, 1.5), (7.5, 1.5)):
        lo, hi = vz_range(z, narrow)
        assert lo == hi and abs(lo) == pytest.approx(min(_braking_speed(far, a_max, dt), 4.0))
        free = vz_range(z, narrow._replace(acceleration=float("nan")))
        assert free == (4.0, 4.0) if z < 6.0 else free == (-4.0, -4.0)  # as ever: the top speed


def _braking_speed(d: float, a: float, dt: float) -> float:
    """The s with s dt + s^2 / (2 a) = d (0 for d <= 0)."""
    return a * (np.sqrt(dt * dt + 2.0 * d / a) - dt) if d > 0 else 0.0


@settings(max_examples=25, **SETTINGS)
@given(st.floats(0.2, 6.0), st.floats(0.5, 3.0), st.floats(0.0, 4.0))
def test_a_descent_under_an_acceleration_limit_stops_above_the_floor(z, a_max, sink):
    """Flown in closed loop (each answer the next velocity), a vehicle asked to dive through the
    floor never goes below it and never sinks faster than the braking room allows; while it is
    within that room every answer is optimal and within the acceleration box (the room is kept
    step after step); a vehicle that starts too fast for it is braked by the limits."""
    dt, limits = 0.2, Limits(speed=(0.0, 4.0), altitude=(0.0, 40.0), acceleration=a_max)
    sel, vz = VelocitySelector(), -sink
    for _ in range(60):
        room = _braking_speed(z, a_max, dt)
        own = AgentState(position=(0.0, 0.0, z), velocity=(0.0, 0.0, vz))
        d = sel.select(own=own, preferred_velocity=(0.0, 0.0, -4.0), limits=limits, dt=dt)
        assert d.velocity[2] >= -room - 1e-9
        if -vz <= room:
            assert d.status == "optimal"
            assert np.all(np.abs(d.velocity - (0.0, 0.0, vz)) <= a_max * dt + 1e-9)
        z, vz = z + d.velocity[2] * dt, d.velocity[2]
        assert z >= -1e-9


def test_reciprocal_takes_half_the_avoidance():
    own = AgentState(position=(0.0, 0.0, 20.0), velocity=(2.0, 0.0, 0.0))
    nb = Neighbor(position=(30.0, 1.0, 20.0), velocity=(-2.0, 0.0, 0.0), r_pz=10.0)
    kw = dict(own=own, preferred_velocity=(2.0, 0.0, 0.0), neighbors=[nb], obstacles=[],
              limits=Limits(speed=(0, 4), altitude=(0, 40)), dt=0.2)
    full = VelocitySelector("plane_qp", preset="paper").select(**kw)
    half = VelocitySelector("plane_qp", preset="paper", reciprocal=True).select(**kw)
    dev = exact(kw).deviation
    assert full.status == half.status == "optimal"
    assert dev(half.velocity)[0] < dev(full.velocity)[0]
    # A neighbour that does not avoid (hovering, static) gets no half share: the reciprocal
    # selector then keeps clear of its whole VO, like the non-reciprocal one.
    alone = dict(kw, neighbors=[nb.model_copy(update={"cooperative": False})])
    own_all = VelocitySelector("plane_qp", preset="paper", reciprocal=True).select(**alone)
    assert own_all.status == "optimal" and safe(kw, own_all.velocity)
    assert not safe(kw, half.velocity)  # the half share alone would not be safe
    assert dev(own_all.velocity)[0] == pytest.approx(dev(full.velocity)[0], abs=1e-3)


@pytest.mark.parametrize("depth_share", [0.6, 0.75, 0.9])
def test_deep_in_a_cooperative_buffer_the_answer_opens_the_gap(depth_share):
    """Two vehicles side by side, same velocity, the neighbour ``depth_share`` of the buffer
    inside it (the default preset: buffer 2 v_max dt = 1.6 m): past half the buffer the answer
    moves away from it, by more the deeper it is, and stays outside the VO. In the outer half,
    or beside a neighbour that does not avoid (it will not move aside), the preferred velocity
    (holding the gap) stands: two vehicles whose goals lie within each other's buffer, but
    outside its inner half, can both be home."""
    sel, dt, r_pz = VelocitySelector(), 0.2, 8.0
    limits = Limits(speed=(0, 4), altitude=(0, 40))
    buffer = sel.options_for(limits.v_max, dt).pz_buffer

    def answer(depth: float, cooperative: bool = True) -> np.ndarray:
        nb = Neighbor(position=(0.0, r_pz + (1.0 - depth) * buffer, 20.0),
                      velocity=(2.0, 0.0, 0.0), r_pz=r_pz, cooperative=cooperative)
        kw = dict(own=AgentState(position=(0.0, 0.0, 20.0), velocity=(2.0, 0.0, 0.0)),
                  preferred_velocity=(2.0, 0.0, 0.0), neighbors=[nb], obstacles=[],
                  limits=limits, dt=dt)
        d = sel.select(**kw)
        assert d.status == "optimal" and safe(kw, d.velocity, sel)
        assert_within_limits(kw, d.velocity)
        return d.velocity

    assert buffer == pytest.approx(2 * limits.v_max * dt)
    for holds in (-0.01, 0.25, 0.49):
        assert np.allclose(answer(holds), [2.0, 0.0, 0.0])
    assert np.allclose(answer(depth_share, cooperative=False), [2.0, 0.0, 0.0])
    opening = -answer(depth_share)[1]  # away from the neighbour: -y
    deeper = -answer(min(0.99, depth_share + 0.05))[1]
    assert 0.0 < opening < deeper


@settings(max_examples=200, **SETTINGS)
@given(
    gap=st.floats(0.0, 1.0),
    direction=st.tuples(*[st.floats(-1.0, 1.0)] * 3).filter(lambda u: np.linalg.norm(u) > 0.1),
    v_a=st.tuples(*[st.floats(-4.0, 4.0)] * 3),
    v_b=st.tuples(*[st.floats(-4.0, 4.0)] * 3),
    horizon=st.sampled_from([None, 0.5, 3.0]),
)
def test_the_opened_vo_holds_the_vo_of_the_real_apex(gap, direction, v_a, v_b, horizon):
    """Deep in a cooperative neighbour's buffer the cone's apex moves away from it; the moved
    cone must contain the cone at the reciprocal apex (V_A + V_B)/2 with the same planning
    sphere: no velocity within v_max outside the one is inside the other."""
    sel, dt, r_pz = VelocitySelector(horizon=horizon), 0.2, 6.0
    limits = Limits(speed=(0, 4), altitude=(0, 100))
    options = sel.options_for(limits.v_max, dt)
    buffer = options.pz_buffer
    u = np.asarray(direction) / np.linalg.norm(direction)
    p_a, d = np.array([0.0, 0.0, 50.0]), r_pz + gap * buffer
    nb = Neighbor(position=p_a + d * u, velocity=v_b, r_pz=r_pz)
    enc = prepare(AgentState(position=p_a, velocity=v_a), np.zeros(3), [nb], [], limits, dt,
                  options)
    planned = r_pz + min(buffer, 0.9 * (d - r_pz))
    apex = 0.5 * (np.asarray(v_a) + np.asarray(v_b))
    real = build_cones(p_a, (p_a + d * u)[None], apex[None], np.array([planned]), limits.v_max,
                       1.5)
    vs = np.random.default_rng(0).uniform(-4.0, 4.0, size=(400, 3))
    vs = vs[np.linalg.norm(vs, axis=1) <= limits.v_max]
    inside_real = in_vo_cones(real, vs, horizon=horizon)[0]
    inside_opened = (in_vo_cones(enc.cones, vs, horizon=horizon)[0] if len(enc.cones.apex)
                     else np.zeros(len(vs), dtype=bool))
    assert not (inside_real & ~inside_opened).any()


@pytest.mark.parametrize("formulation", ["sampled", "plane_qp"])
def test_answer_keeps_the_margin_off_the_cone(formulation):
    """A neighbour at rest 20 m ahead on the line of flight (r_pz 10 m): the VO is the cone
    about +x of half-angle 30°, whose nearest point to the preferred velocity is (2.598, 0,
    1.5), exactly on the cone; every answer must be at least the margin (1e-3 m/s) outside
    it."""
    own = AgentState(position=(0.0, 0.0, 20.0), velocity=(4.0, 0.0, 0.0))
    kw = dict(own=own, preferred_velocity=(4.0, 0.0, 0.0), obstacles=[], limits=Limits(), dt=0.2,
              neighbors=[Neighbor(position=(20.0, 0.0, 20.0), velocity=(0.0, 0.0, 0.0), r_pz=10.0)])
    d = VelocitySelector(formulation, preset="paper").select(**kw)
    v = d.velocity
    off_axis = np.degrees(np.arctan2(np.hypot(v[1], v[2]), v[0]))
    distance = np.linalg.norm(v) * np.sin(np.radians(min(off_axis - 30.0, 90.0)))  # to the cone
    assert d.status == "optimal" and distance >= 1e-3 * (1 - 1e-6)


def test_horizon_ignores_far_threats():
    own = AgentState(position=(0.0, 0.0, 20.0), velocity=(2.0, 0.0, 0.0))
    nb = Neighbor(position=(50.0, 0.0, 20.0), velocity=(0.0, 0.0, 0.0), r_pz=5.0)
    kw = dict(own=own, preferred_velocity=(2.0, 0.0, 0.0), neighbors=[nb], obstacles=[],
              limits=Limits(speed=(0, 4), altitude=(0, 40)), dt=0.2)
    assert not np.allclose(VelocitySelector("plane_qp").select(**kw).velocity, [2, 0, 0])
    d = VelocitySelector("plane_qp", horizon=5.0).select(**kw)
    assert d.status == "optimal" and np.allclose(d.velocity, [2, 0, 0])


# --- bad input ---------------------------------------------------------------------------------

@pytest.mark.parametrize("change,field", [
    (dict(preferred_velocity=(1.0, np.nan, 0.0)), "preferred_velocity"),
    (dict(preferred_velocity=(1.0, 0.0)), "preferred_velocity"),
    (dict(dt=0.0), "dt"),
    (dict(dt=float("inf")), "dt"),
    (dict(own=(0, 0, 0)), "own"),
    (dict(neighbors=[(1, 2, 3)]), "neighbors[0]"),
    (dict(obstacles=["tree"]), "obstacles[0]"),
    (dict(limits=(0, 4)), "limits"),
])
def test_bad_input_names_the_field(change, field):
    with pytest.raises(ValueError, match=field.replace("[", r"\[").replace("]", r"\]")):
        VelocitySelector().select(**dict(CONTRACT, **change))


@pytest.mark.parametrize("options,name", [
    (dict(unknown_opt=1), "unknown_opt"),
    (dict(margin=-1), "margin"),
    (dict(margin=float("nan")), "margin"),
    (dict(n_samples="72"), "n_samples"),
    (dict(reciprocal=1), "reciprocal"),
    (dict(corrections={"tg_range", "typo"}), "corrections"),
])
def test_bad_option_is_one_line_naming_it(options, name):
    """A wrong or unknown option: a ValueError of one line that names it, without pydantic's
    multi-line report and its URLs."""
    with pytest.raises(ValueError, match=rf"^{name}\b") as err:
        VelocitySelector(formulation="plane_qp", **options)
    assert "\n" not in str(err.value) and "http" not in str(err.value)


def test_exact2d_only_for_plane_qp():
    """exact2d solves the per-plane problem only: asking it for cone_qp's 3D QPs is an error
    that names the backends that can."""
    with pytest.raises(ValueError, match="exact2d.*plane_qp.*available: .*clarabel"):
        VelocitySelector("cone_qp", solver="exact2d")
    with pytest.raises(ValueError, match="exact2d"):
        VelocitySelector("nlp", start_solver="osqp", solver="exact2d")


def test_unknown_names_list_what_is_available():
    with pytest.raises(ValueError, match="plane_qp"):
        VelocitySelector(formulation="magic")
    with pytest.raises(ValueError, match="osqp"):
        VelocitySelector(solver="no-such-solver")
    with pytest.raises(ValueError, match="casadi"):
        VelocitySelector("nlp", solver="osqp")
    with pytest.raises(ValueError, match="plane_step_deg"):
        VelocitySelector(plane_step_deg=0)
    with pytest.raises(ValueError, match="colour"):
        VelocitySelector(colour="red")


@pytest.mark.parametrize("formulation", ["plane_qp", "sampled"])
def test_a_prism_reaching_the_ceiling_is_not_flown_over(formulation):
    """A box whose protected prism (top 33 m) reaches the 32.5 m ceiling, straight ahead of a
    UAV at 30 m that would like to climb: going over it, one step at a time within the altitude
    limit, ends squeezed between ceiling and prism (sweep 'lagged' encounter 647). The answer
    must be safe against the same box standing 1 km tall, i.e. go round it."""
    box = dict(center=(25.0, 0.0), size=(6.0, 6.0), height=31.0)
    kw = dict(
        own=AgentState(position=(0.0, 0.0, 30.0), velocity=(4.0, 0.0, 0.5)),
        preferred_velocity=(3.8, 0.0, 0.8),
        neighbors=[],
        obstacles=[Box(**box)],
        limits=Limits(speed=(0.0, 4.0), altitude=(0.0, 32.5)),
        dt=0.2,
    )
    v = VelocitySelector(formulation).select(**kw).velocity
    assert_within_limits(kw, v)
    tall = {**kw, "obstacles": [Box(**{**box, "height": 1000.0})]}
    assert not exact(tall).unsafe(v)[0]
    # with room above the prism, flying over stays allowed: about the preferred velocity,
    # which the 1 km box would stop
    roomy = {**kw, "limits": Limits(speed=(0.0, 4.0), altitude=(0.0, 40.0))}
    v = VelocitySelector(formulation).select(**roomy).velocity
    assert np.linalg.norm(v - (3.8, 0.0, 0.8)) < 0.2
    assert exact({**roomy, "obstacles": tall["obstacles"]}).unsafe(v)[0]


def test_nothing_to_avoid_but_the_preferred_velocity_breaks_the_limits():
    """No neighbour, no obstacle, a UAV 0.1 m under the ceiling that would like to climb at
    4 m/s: no VO at all, yet the preferred velocity is not allowed, so the plane QPs run with
    no VO rows (the compiled kernel once wrote past its work list here: a crash in the lagged
    sweep). The answer keeps the ceiling, nearest the preferred velocity: level at full speed
    minus what the climb costs; select_many gives the same for a swarm of such UAVs."""
    kw = dict(
        own=AgentState(position=(0.0, 0.0, 39.9), velocity=(0.0, 0.0, 0.0)),
        preferred_velocity=(2.0, 0.0, 3.0),
        limits=Limits(speed=(0.0, 4.0), altitude=(0.0, 40.0)),
        dt=0.2,
    )
    sel = VelocitySelector()
    d = sel.select(**kw)
    assert d.status == "optimal"
    assert_within_limits({**kw, "neighbors": [], "obstacles": []}, d.velocity)
    assert d.velocity[2] == pytest.approx(0.5, abs=0.06)  # (40 - 39.9) / dt
    assert d.velocity[0] == pytest.approx(2.0, abs=0.06)
    many = sel.select_many(np.array([[0.0, 0.0, 39.9], [100.0, 0.0, 39.9]]), np.zeros((2, 3)),
                           np.array([[2.0, 0.0, 3.0], [2.0, 0.0, 3.0]]), 5.0,
                           limits=kw["limits"], dt=0.2)
    assert list(many.statuses) == ["optimal", "optimal"]
    for v in many.velocities:
        np.testing.assert_allclose(v, d.velocity, atol=1e-9)


