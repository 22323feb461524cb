"""Encounters the sweeps found failing, each a scenario file in tests/data/sweep-failures/
flown again: those whose cause was fixed fly clean; those not fixed yet fail as recorded."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from encounters import PAPER_GRID
from vo3d_opt.sim.metrics import summarize
from vo3d_opt.sim.scenario import load_scenario, scenario_variant
from vo3d_opt.sim.simulator import run_scenario

FAILURES = Path(__file__).parent / "data" / "sweep-failures"


def flown(name: str, options: dict | None = None) -> dict:
    """The summary of the scenario flown with ``options`` over its selector options."""
    sc = load_scenario(FAILURES / f"{name}.yaml")
    if options:
        sc = scenario_variant(sc, selector_options={**sc.selector_options, **options})
    return summarize(run_scenario(sc, progress=False))


def assert_safe(s: dict) -> None:
    """No collision, no intrusion into a vehicle's or an obstacle's zone, no limit broken."""
    assert s["collisions"] == 0 and s["pz_intrusions"] == 0
    assert s["obstacle_pz_intrusions"] == 0
    assert s["altitude_violations"] == 0 and s["speed_violations"] == 0


def flies_clean(name: str, options: dict | None = None) -> None:
    """Safe (``assert_safe``) and everyone home; ``options`` over the scenario's own."""
    s = flown(name, options)
    assert_safe(s)
    assert s["all_reached"]


# --- encounters a sweep found failing, flown again: the cause was fixed in the simulator ------


@pytest.mark.parametrize(
    ("name", "options"),
    [*((name, None) for name in (
        "lagged-s0-i413", "lagged-s0-i809", "lagged-s0-i647", "dense-s0-i576", "lagged-s0-i317",
        "lagged-s0-i1893", *(f"dense-s0-i{i}" for i in (1121, 3502, 6534, 7803, 9350)),
        "dense-s0-i5051", "group-s0-i38855", "group-s0-i68905", "intruder-s0-i63083",
        "intruder-s0-i72580", "intruder-s0-i29918", "lagged-s0-i76920", "noisy-s0-i66134",
        "lagged-s0-i16783", "lagged-s0-i92409", "dense-s0-i82705", "lagged-s0-i91377",
        "lagged-s0-i52246")),
     pytest.param("dense-s0-i82432", PAPER_GRID, id="dense-s0-i82432-paper-grid"),
     pytest.param("lagged-s0-i52246", {"fine_planes": False}, id="lagged-s0-i52246-7-planes")],
)
def test_sweep_failures_are_fixed(name, options):
    """`lagged` seed 0 before the margins derived from the scenario (sim/safety.py): encounter
    413 went 0.30 m below the floor and into an obstacle's prism, 809 to 0.77 m from an
    obstacle. With the margins: no intrusion, no altitude violation, everyone arrives. 647
    climbed over a box whose prism reached the ceiling and, squeezed, slid down its side to
    0.17 m from it; a prism reaching the ceiling is now gone round. In `dense` 576 one agent
    stopped for good 8 m from its goal, wedged among three that had arrived and hover; it now
    takes the simulator's detour after stalling (sim/traffic.GoalWithDetours) and arrives. In
    `lagged` 317 (found with the first detour rule) an agent stalled 1-3 m from its goal was
    sent off again and again; no detour within r_pz of the goal. In `dense` 1121, 3502, 6534,
    7803 and 9350 (the 10,000-encounter sweep) one agent crept to a stop 1-2 m short of a goal
    in a nook between hovering vehicles, where every ray of its VO runs on into their zones;
    the simulator now lands an agent waiting at its goal's door when the straight step is
    clear (sim/landing.py). In the 10,000-encounter `lagged` sweep 1893 crossed the edge of a
    box's prism top 5.2 mm deep: its command grazed the flat top and the lag kept it lower;
    every prism's top is now raised by the tracking error while planning (sim/safety.py,
    ``prism_rise``). In `dense` 5051, flown with the closing guard (now the simulator's
    default), one agent hovered 11.8 m from its goal among three hovering vehicles, the 90°
    detour's nearest safe velocity hovering again; detours in a row now turn further (90°,
    180°, 270°; with the buffer opening and the hovering vehicles making room it arrives
    without them too). In the 100,000-encounter
    `group` and `intruder` sweeps (38855, 68905; 63083, 72580) a vehicle low over the floor
    entered a box's prism: a velocity whose ray reached the box only below the ground counted
    as passing under it, and the vehicle, levelled off at the floor, flew in; C_pz now reaches
    below the ground (algorithm/vo.hpp, ``UNDERGROUND``). In `intruder` 29918 a vehicle that
    had arrived hovered at its goal without deciding and the intruder, which does not avoid,
    passed it 0.7 % inside the pair's zone; an arrived vehicle now decides again while a vehicle
    that does not avoid is within its sensing range (sim/traffic.keep_watch). In `lagged` 76920
    a vehicle under a lag climbed over a prism whose raised top lay 0.09 m under the planning
    ceiling, found no velocity outside every VO for several steps and entered the prism; a top
    that close to the ceiling now goes up to it, and the prism is gone round
    (sim/safety.planning_bodies). In `noisy` 66134 two vehicles flew side by side for seconds
    inside each other's buffer, holding the gap each sensed, and the noise in what each sensed
    ratcheted it down to 2.6 % inside the larger zone; inside a cooperative neighbour's buffer
    the answer deep in it now opens the gap (algorithm/vo.hpp, ``BUFFER_OPENING``). In
    `lagged` 16783, 92409 and `dense` 82432, 82705 one vehicle was short of its goal at the
    end; with that rule and the hovering vehicles making room for one on a detour
    (sim/traffic.keep_watch) all arrive (82432 on the planes it was found on, ``PAPER_GRID``;
    on the safe preset's own it is open). `lagged` 91377 (one vehicle short of its goal,
    beyond a box) arrives on the safe preset: another trajectory, not a rule aimed at it; on
    the planes it was found on it stays open (``test_open_sweep_failures``). `lagged` 52246,
    found on 7 planes everywhere (``fine_planes`` off), entered a prism's zone under the lag;
    near obstacles the safe preset plans on the default planes (``fine_planes``), and since a
    vehicle just under a prism's top no longer sinks it flies clean on 7 planes too."""
    flies_clean(name, options)


def test_dense_95048_arrives_when_the_hovering_vehicles_make_room(monkeypatch):
    """In `dense` 95048 one agent stalls about 20 m from its goal, walled off by vehicles
    hovering at theirs, and its detours find no way in; the hovering vehicles near an agent on
    a detour now decide again (``keep_watch`` with ``GoalWithDetours.stuck``) and make room.
    Without that, on the paper's planes and one grid, it is still short of its goal when the
    run ends (on the safe preset's own planes it then finds its way in)."""
    from vo3d_opt.sim import traffic

    flies_clean("dense-s0-i95048")
    sc = load_scenario(FAILURES / "dense-s0-i95048.yaml")
    sc = scenario_variant(sc, selector_options={**sc.selector_options, **PAPER_GRID})
    monkeypatch.setattr(traffic.GoalWithDetours, "stuck",
                        property(lambda self: np.zeros(len(self.goals), dtype=bool)))
    s = summarize(run_scenario(sc, progress=False))
    assert (s["reached"], s["agents"]) == (14, 15)


def test_rotorpy_998_flies_its_watcher_from_hover_without_an_upset():
    """In `rotorpy` 998 vehicle 1 arrives at 2.8 m/s (step 211), stops dead and hovers, and
    the next step keeps watch; its command-rate limit started from its last command, not from
    hover, so it was asked for 2.5 m/s at once and flipped (4.2 m/s over its top speed). Flown
    as then (planning at the top speed: no ``speed_margin``), its first 225 steps, which hold
    the release, now stay within every limit."""
    pytest.importorskip("torch")  # batched RotorPy vehicles
    pytest.importorskip("rotorpy")
    sc = load_scenario(FAILURES / "rotorpy-s0-i998.yaml")
    sc = scenario_variant(sc, safety={"speed_margin": 0.0})
    record = run_scenario(sc, progress=False, max_steps=225)
    assert (record.decided & record.arrived[:-1]).any()  # a vehicle home decided again
    assert_safe(summarize(record))


def test_rotorpy_960_brakes_under_a_prism_top_without_sinking():
    """In `rotorpy` 960 vehicle 3 crosses a cylinder at the top of its planning prism (raised by
    the tracking error) and ends 2 mm below it once RotorPy's velocity loop lags a climb. Inside
    a prism only going towards its centre closed in, and no velocity within one step's
    acceleration turned back, so the least-bad velocity braked and sank with the preferred
    descent into the zone (1.36 m from the surface, the zone 2 m). Just under a prism's top a
    descent now closes in too, and the least-bad velocity brakes without sinking: the first 100
    steps, which held the intrusion, fly clean (the whole encounter is in the rotorpy sweep's
    results page)."""
    pytest.importorskip("torch")  # batched RotorPy vehicles
    pytest.importorskip("rotorpy")
    record = run_scenario(load_scenario(FAILURES / "rotorpy-s0-i960.yaml"), progress=False,
                          max_steps=100)
    assert_safe(summarize(record))


# --- encounters a sweep found failing whose cause is not fixed yet: each flies as recorded ---


def _open(name: str, options: dict | None = None) -> object:
    return pytest.param(name, options, id=name + ("-paper-grid" if options else ""))


@pytest.mark.parametrize(
    ("name", "options"),
    [
        _open("lagged-s0-i14945"),
        _open("lagged-s0-i51181"),
        _open("lagged-s0-i14347"),
        _open("lagged-s0-i35316"),
        _open("lagged-s0-i91377", PAPER_GRID),
        _open("dense-s0-i82432"),
        _open("dense-s0-i36447"),
        _open("dense-s0-i60964"),
        _open("lagged-swarm-s0-i1077"),
    ],
)
def test_open_sweep_failures(name, options):
    """The sweeps' failures whose cause is not fixed yet (each family's results page lists those
    of its own preset; 91377 is open only on the planes and grid it was found on).
    `lagged` 14945, 51181, 14347 and 91377: one vehicle has not reached its goal when the
    run ends; no zone is entered. In 14945 it ends 18-25 m from its goal among six
    obstacles, a vehicle hovering at a goal 12.3 m from its own; in 51181 it waits about 11
    m from its goal, in 14347 4.8 m (within r_pz: waiting at its goal's door, never landed),
    each among vehicles hovering at goals 11-13 m from its own; in 35316 (since the altitude
    band keeps room to brake) it holds 28 m from its goal at 3.5 m, low over the floor, going
    back and forth on its detours; in 91377 about 30 m from it,
    beyond a box that reaches over the ceiling (on the planes and grid it was found on,
    ``PAPER_GRID``; the safe preset's own fly it clean). `dense` 82432, 36447 and 60964 on
    the safe preset (its 100,000-encounter sweep): one of 23-24 vehicles does not arrive
    (82432 on the planes it was found on arrives, ``test_sweep_failures_are_fixed``).
    `lagged` 1077 of the swarm preset's 10,000-encounter sweep: one of three vehicles is 2.2
    m from its goal (within r_pz, never landed) when the run ends. Each is still safe and
    still one vehicle short: once a change brings that vehicle home, this test fails and the
    encounter moves to ``test_sweep_failures_are_fixed``."""
    s = flown(name, options)
    assert_safe(s)
    assert s["reached"] == s["agents"] - 1, "arrives now: move it to the fixed ones"
