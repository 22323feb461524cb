"""Validation of the public data types: malformed input raises
ValueError naming the field; well-formed input, including numpy input, is accepted; L_pz and
h_pz are derived from the obstacle's size plus the documented margin."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vo3d_opt.types import PZ_MARGIN, AgentState, Box, Cylinder, InputError, Limits, Neighbor

BAD_NUMBERS = [math.nan, math.inf, -math.inf]


def _raises(field, make):
    with pytest.raises(ValueError, match=field):
        make()


# ----------------------------------------------------------------------------- NaN / inf


@pytest.mark.parametrize("bad", BAD_NUMBERS)
@pytest.mark.parametrize("index", [0, 1, 2])
def test_non_finite_vectors_rejected(bad, index):
    vec3 = [1.0, 2.0, 3.0]
    vec3[index] = bad
    _raises("position", lambda: AgentState(position=vec3))
    _raises("velocity", lambda: AgentState(position=(0, 0, 0), velocity=vec3))
    _raises("position", lambda: Neighbor(position=vec3, r_pz=5.0))
    _raises("velocity", lambda: Neighbor(position=(0, 0, 0), velocity=vec3, r_pz=5.0))
    vec2 = [1.0, 2.0]
    vec2[index % 2] = bad
    _raises("center", lambda: Cylinder(center=vec2, radius=1.0, height=3.0))
    _raises("center", lambda: Box(center=vec2, size=(1, 1), height=3.0))
    _raises("size", lambda: Box(center=(0, 0), size=vec2, height=3.0))


@pytest.mark.parametrize("bad", BAD_NUMBERS)
def test_non_finite_scalars_rejected(bad):
    _raises("r_pz", lambda: Neighbor(position=(0, 0, 0), r_pz=bad))
    _raises("radius", lambda: Cylinder(center=(0, 0), radius=bad, height=3.0))
    _raises("height", lambda: Cylinder(center=(0, 0), radius=1.0, height=bad))
    _raises("height", lambda: Box(center=(0, 0), size=(1, 1), height=bad))
    _raises("yaw", lambda: Box(center=(0, 0), size=(1, 1), height=3.0, yaw=bad))
    _raises("L_pz", lambda: Cylinder(center=(0, 0), radius=1.0, height=3.0, L_pz=bad))
    _raises("h_pz", lambda: Box(center=(0, 0), size=(1, 1), height=3.0, h_pz=bad))
    _raises("margin", lambda: Cylinder(center=(0, 0), radius=1.0, height=3.0, margin=bad))
    _raises("speed", lambda: Limits(speed=(0.0, bad)))
    _raises("speed", lambda: Limits(speed=(bad, 4.0)))
    _raises("altitude", lambda: Limits(altitude=(bad, 40.0)))
    _raises("altitude", lambda: Limits(altitude=(0.0, bad)))
    _raises("acceleration", lambda: Limits(acceleration=bad))


# ----------------------------------------------------------------------------- shapes


@pytest.mark.parametrize(
    "bad", [(1.0, 2.0), (1.0, 2.0, 3.0, 4.0), [[1.0, 2.0, 3.0]], np.zeros((3, 1)), 5.0, "abc", None]
)
def test_wrong_vec3_shapes_rejected(bad):
    _raises("position", lambda: AgentState(position=bad))
    _raises("velocity", lambda: AgentState(position=(0, 0, 0), velocity=bad))
    _raises("position", lambda: Neighbor(position=bad, r_pz=1.0))
    _raises("velocity", lambda: Neighbor(position=(0, 0, 0), velocity=bad, r_pz=1.0))


@pytest.mark.parametrize("bad", [(1.0,), (1.0, 2.0, 3.0), [[1.0, 2.0]], np.zeros((2, 2)), 1.0, "xy"])
def test_wrong_vec2_shapes_rejected(bad):
    _raises("center", lambda: Cylinder(center=bad, radius=1.0, height=3.0))
    _raises("center", lambda: Box(center=bad, size=(1, 1), height=3.0))
    _raises("size", lambda: Box(center=(0, 0), size=bad, height=3.0))


def test_wrong_range_shapes_rejected():
    _raises("speed", lambda: Limits(speed=(1.0, 2.0, 3.0)))
    _raises("speed", lambda: Limits(speed=4.0))
    _raises("altitude", lambda: Limits(altitude=(1.0,)))


# ----------------------------------------------------------------------------- signs and ranges


@pytest.mark.parametrize("bad", [0.0, -1.0, -1e-9])
def test_non_positive_sizes_rejected(bad):
    _raises("r_pz", lambda: Neighbor(position=(0, 0, 0), r_pz=bad))
    _raises("radius", lambda: Cylinder(center=(0, 0), radius=bad, height=3.0))
    _raises("height", lambda: Cylinder(center=(0, 0), radius=1.0, height=bad))
    _raises("height", lambda: Box(center=(0, 0), size=(1, 1), height=bad))
    _raises("size", lambda: Box(center=(0, 0), size=(bad, 1.0), height=3.0))
    _raises("size", lambda: Box(center=(0, 0), size=(1.0, bad), height=3.0))
    _raises("L_pz", lambda: Cylinder(center=(0, 0), radius=1.0, height=3.0, L_pz=bad))
    _raises("h_pz", lambda: Cylinder(center=(0, 0), radius=1.0, height=3.0, h_pz=bad))
    _raises("L_pz", lambda: Box(center=(0, 0), size=(1, 1), height=3.0, L_pz=bad))
    _raises("h_pz", lambda: Box(center=(0, 0), size=(1, 1), height=3.0, h_pz=bad))
    _raises("speed", lambda: Limits(speed=(0.0, bad)))  # v_max must be positive
    _raises("acceleration", lambda: Limits(acceleration=bad))


def test_negative_margin_and_min_speed_rejected():
    _raises("margin", lambda: Box(center=(0, 0), size=(1, 1), height=3.0, margin=-0.5))
    _raises("speed", lambda: Limits(speed=(-1.0, 4.0)))


def test_empty_ranges_rejected():
    _raises("speed", lambda: Limits(speed=(3.0, 2.0)))
    _raises("altitude", lambda: Limits(altitude=(10.0, 10.0)))
    _raises("altitude", lambda: Limits(altitude=(40.0, 0.0)))
    # a single speed is a valid (degenerate) range
    assert Limits(speed=(2.0, 2.0)).v_min == 2.0


def test_protected_prism_must_cover_obstacle():
    # section 4: h_pz at least the obstacle height, L_pz at least its largest horizontal extent
    _raises("h_pz", lambda: Cylinder(center=(0, 0), radius=1.0, height=10.0, h_pz=9.9))
    _raises("h_pz", lambda: Box(center=(0, 0), size=(3, 4), height=10.0, h_pz=5.0))
    _raises("L_pz", lambda: Cylinder(center=(0, 0), radius=2.0, height=10.0, L_pz=3.9))
    _raises("L_pz", lambda: Box(center=(0, 0), size=(3, 4), height=10.0, L_pz=4.9))  # diagonal 5
    assert Cylinder(center=(0, 0), radius=2.0, height=10.0, L_pz=4.0, h_pz=10.0).side == 4.0
    assert Box(center=(0, 0), size=(3, 4), height=10.0, L_pz=5.0).side == 5.0


def test_unknown_field_rejected():
    _raises("foo", lambda: Neighbor(position=(0, 0, 0), r_pz=1.0, foo=1))
    _raises("r_pz", lambda: Neighbor(position=(0, 0, 0)))  # missing
    _raises("cooperative", lambda: Neighbor(position=(0, 0, 0), r_pz=1.0, cooperative="yes"))


# ----------------------------------------------------------------------------- well-formed input


def test_well_formed_accepted_and_frozen():
    a = AgentState(position=(0.0, 0.0, 20.0), velocity=(4.0, 0.0, 0.0))
    assert isinstance(a.position, np.ndarray) and a.position.shape == (3,)
    assert a.position.dtype == float and not a.position.flags.writeable
    assert np.array_equal(AgentState(position=(1, 2, 3)).velocity, np.zeros(3))
    n = Neighbor(position=[30, 0, 20], velocity=[-4, 0, 0], r_pz=10)
    assert n.r_pz == 10.0 and np.array_equal(n.velocity, [-4.0, 0.0, 0.0])
    c = Cylinder(center=(15.0, 8.0), radius=3.0, height=30.0)
    b = Box(center=(40.0, -5.0), size=(6.0, 4.0), height=25.0, yaw=0.3)
    assert b.yaw == 0.3 and np.array_equal(b.size, [6.0, 4.0])
    lim = Limits(speed=(0.0, 4.0), altitude=(0.0, 40.0))
    assert (lim.v_min, lim.v_max, lim.z_min, lim.z_max) == (0.0, 4.0, 0.0, 40.0)
    assert Limits().acceleration is None and Limits(acceleration=2.0).acceleration == 2.0
    with pytest.raises(Exception):
        a.position[0] = 1.0  # read-only array
    with pytest.raises(Exception):
        c.radius = 1.0  # frozen model


def test_numpy_inputs_accepted():
    a = AgentState(position=np.array([1, 2, 3]), velocity=np.array([0.5, 0.0, -0.5], dtype=np.float32))
    assert a.position.dtype == float and np.array_equal(a.position, [1.0, 2.0, 3.0])
    n = Neighbor(position=np.arange(3.0), velocity=np.zeros(3), r_pz=np.float64(2.5))
    assert n.r_pz == 2.5 and isinstance(n.r_pz, float)
    c = Cylinder(center=np.array([1.0, 2.0]), radius=np.float32(2.0), height=np.int64(30))
    assert c.height == 30.0 and c.radius == 2.0
    b = Box(center=np.array([0, 0]), size=np.array([2.0, 3.0]), height=np.float64(5), yaw=np.float64(0.1))
    assert b.side == pytest.approx(math.hypot(2, 3) + 2 * PZ_MARGIN)
    lim = Limits(speed=(np.float64(0.0), np.float64(3.0)), altitude=np.array([0.0, 50.0]))
    assert lim.v_max == 3.0 and lim.z_max == 50.0


# ----------------------------------------------------------------------------- derived L_pz / h_pz


def test_derived_protected_prism_cylinder():
    c = Cylinder(center=(0, 0), radius=3.0, height=30.0)
    assert PZ_MARGIN == 2.0
    assert c.side == pytest.approx(2 * 3.0 + 2 * PZ_MARGIN)  # 2 r + 2 margin
    assert c.prism_height == pytest.approx(30.0 + PZ_MARGIN)
    c2 = Cylinder(center=(0, 0), radius=3.0, height=30.0, margin=0.5)
    assert c2.side == pytest.approx(7.0) and c2.prism_height == pytest.approx(30.5)
    c3 = Cylinder(center=(0, 0), radius=3.0, height=30.0, L_pz=12.0, h_pz=33.0)
    assert c3.side == 12.0 and c3.prism_height == 33.0


def test_derived_protected_prism_box():
    b = Box(center=(0, 0), size=(6.0, 8.0), height=25.0, yaw=1.0)
    assert b.side == pytest.approx(10.0 + 2 * PZ_MARGIN)  # diagonal + 2 margin
    assert b.prism_height == pytest.approx(25.0 + PZ_MARGIN)
    b0 = Box(center=(0, 0), size=(6.0, 8.0), height=25.0, margin=0.0)
    assert b0.side == pytest.approx(10.0) and b0.prism_height == pytest.approx(25.0)


@settings(max_examples=60, deadline=None)
@given(
    size=st.tuples(st.floats(0.01, 100), st.floats(0.01, 100)),
    yaw=st.floats(-10, 10),
    margin=st.floats(0, 10),
)
def test_derived_square_covers_box_in_any_orientation(size, yaw, margin):
    """A square of side L_pz centred on the box and turned any way contains the box's footprint
    (section 4.3: L_pz above the largest diagonal)."""
    b = Box(center=(0, 0), size=size, height=1.0, yaw=yaw, margin=margin)
    half = np.array(size) / 2
    corners = np.array([[sx, sy] for sx in (-1, 1) for sy in (-1, 1)]) * half
    c, s = math.cos(yaw), math.sin(yaw)
    world = corners @ np.array([[c, s], [-s, c]])
    for turn in np.linspace(0, np.pi, 7):
        ct, st_ = math.cos(turn), math.sin(turn)
        local = world @ np.array([[ct, -st_], [st_, ct]])
        assert np.all(np.abs(local) <= b.side / 2 + 1e-9)


@settings(max_examples=100, deadline=None)
@given(
    st.lists(st.floats(allow_nan=False, allow_infinity=False, width=64, min_value=-1e6, max_value=1e6),
             min_size=3, max_size=3),
    st.floats(min_value=1e-3, max_value=1e3),
)
def test_any_finite_vectors_accepted(vec, r):
    n = Neighbor(position=vec, velocity=vec, r_pz=r)
    assert np.array_equal(n.position, np.array(vec, dtype=float))


@settings(max_examples=100, deadline=None)
@given(
    st.lists(st.floats(allow_nan=False, allow_infinity=False, min_value=-1e6, max_value=1e6),
             min_size=3, max_size=3),
    st.integers(0, 2),
    st.sampled_from(BAD_NUMBERS),
)
def test_any_non_finite_entry_rejected(vec, index, bad):
    vec = list(vec)
    vec[index] = bad
    _raises("position", lambda: AgentState(position=vec))


# ----------------------------------------------------------------------------- numbers are numbers

NOT_NUMBERS = [True, False, np.bool_(True), "3", "1e3", b"3"]


@pytest.mark.parametrize("bad", NOT_NUMBERS, ids=repr)
def test_booleans_and_strings_are_not_numbers(bad):
    """What the YAML loader refuses, the Python API refuses too (``r_pz=True`` is not
    1 m, ``radius="3"`` is not 3 m)."""
    _raises("r_pz", lambda: Neighbor(position=(0, 0, 0), r_pz=bad))
    _raises("radius", lambda: Cylinder(center=(0, 0), radius=bad, height=3.0))
    _raises("height", lambda: Box(center=(0, 0), size=(1, 1), height=bad))
    _raises("yaw", lambda: Box(center=(0, 0), size=(1, 1), height=3.0, yaw=bad))
    _raises("L_pz", lambda: Cylinder(center=(0, 0), radius=1.0, height=3.0, L_pz=bad))
    _raises("margin", lambda: Box(center=(0, 0), size=(1, 1), height=3.0, margin=bad))
    _raises("acceleration", lambda: Limits(acceleration=bad))
    _raises("speed", lambda: Limits(speed=(0.0, bad)))
    _raises("altitude", lambda: Limits(altitude=(bad, 40.0)))
    _raises("position", lambda: AgentState(position=(bad, 0.0, 0.0)))
    _raises("velocity", lambda: Neighbor(position=(0, 0, 0), velocity=[0.0, bad, 0.0], r_pz=1.0))
    _raises("center", lambda: Cylinder(center=(bad, 0.0), radius=1.0, height=3.0))
    _raises("size", lambda: Box(center=(0, 0), size=(1.0, bad), height=3.0))


@pytest.mark.parametrize("bad", [
    ("1", "2", "3"), (True, 0, 0), np.array([True, False, True]), np.array(["1", "2", "3"]),
    np.array([1, "a", 2], dtype=object), [1.0, [2.0], 3.0], "123", 1 + 0j,
], ids=repr)
def test_vectors_of_non_numbers_rejected(bad):
    _raises("position", lambda: AgentState(position=bad))
    _raises("position", lambda: Neighbor(position=bad, r_pz=1.0))


def test_issue_11_examples_rejected_naming_the_field():
    cases = [
        ("Neighbor", "r_pz", lambda: Neighbor(position=(0, 0, 0), r_pz=True)),
        ("AgentState", "position", lambda: AgentState(position=(True, 0, 0))),
        ("AgentState", "position", lambda: AgentState(position=("1", "2", "3"))),
        ("Cylinder", "radius", lambda: Cylinder(center=(0, 0), radius="3", height=3.0)),
        ("Limits", "speed", lambda: Limits(speed=("0", "4"))),
    ]
    for model, field, make in cases:
        with pytest.raises(ValueError) as info:
            make()
        assert str(info.value).startswith(f"{model}: {field}: "), info.value


def test_errors_are_one_line_naming_every_field():
    with pytest.raises(InputError) as info:
        Box(center=(0.0, math.nan), size=(-1.0, 2.0), height=True, colour="red")
    msg = str(info.value)
    assert isinstance(info.value, ValueError)
    assert "\n" not in msg and "http" not in msg and "pydantic" not in msg, msg
    assert msg.startswith("Box: center: must be finite"), msg
    assert sorted(path for path, _ in info.value.problems) == ["center", "colour", "height", "size"]
    assert "colour: unknown field" in msg and "height: must be a number, got True" in msg, msg
    with pytest.raises(InputError, match=r"^Neighbor: r_pz: missing required field$"):
        Neighbor(position=(0, 0, 0))


def test_cross_field_errors_name_their_field():
    with pytest.raises(InputError) as info:
        Box(center=(0, 0), size=(3, 4), height=10.0, L_pz=4.9, h_pz=5.0)
    assert [p for p, _ in info.value.problems] == ["h_pz", "L_pz"], info.value
    with pytest.raises(InputError, match=r"^Limits: speed: empty range .*; altitude: empty range"):
        Limits(speed=(3.0, 1.0), altitude=(5.0, 5.0))
