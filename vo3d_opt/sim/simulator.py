"""Decentralised multi-UAV simulation (paper section 5): one loop, sense → decide → integrate.

"Each UAV independently produces avoiding velocity control based on its own detection of
obstacles ... moves at a constant time step ... the avoiding velocity control is updated at each
time step." Here, every ``dt`` (:func:`fly`):

1. **sense**: the snapshot of the previous step (positions, velocities), the same for everyone,
   so the order of the decisions does not matter; each agent's preferred velocity comes from a
   function of the positions (default :class:`vo3d_opt.sim.traffic.GoalWithDetours`: towards
   the goal at ``min(v_max, distance / dt)``, turned right for a while after an agent has
   stalled for 4 s; 0 for arrived agents but those keeping watch, below);
2. **decide**: a pluggable :class:`DecisionStep` turns the snapshot into one command per agent
   that decides (not arrived, or keeping watch): our selector for the whole swarm in one
   ``select_many`` call (:class:`vo3d_opt.sim.deciders.SwarmSelect`, what ``run_scenario`` and
   ``vo3d run`` use), any ``SelectorLike`` called once per agent
   (:class:`~vo3d_opt.sim.deciders.PerAgentSelect`), or RVO2-3D
   (:class:`vo3d_opt.baselines.rvo2.RVO2Step`);
3. **integrate**: ``vo3d_opt.sim.dynamics``, the scenario's ``dynamics`` and ``wind``
   (``kinematic``: ``p += v_cmd dt``; ``first_order`` (or ``velocity_response_tau``):
   ``v += (v_cmd - v) min(1, dt / tau)``, ``p += v dt``; ``rotorpy``: RotorPy multirotors,
   whose sub-step samples are recorded in ``RunRecord.samples`` and judged by the metrics;
   their commands, whoever gave them, change at most ``safety.command_rate`` per period).

Agents with ``avoids: false`` never decide: they fly their preferred (straight-to-goal)
velocity and the others see them as non-cooperative, as hovering ones. With sensing noise or
latency each agent decides from its own view of the others (``deciders.decision_step``). The
selector plans with the margins ``vo3d_opt.sim.safety`` derives from the scenario (acceleration
bound, pz_buffer, altitude margin, obstacle prisms; ``formulations/real_world.md``).

What an agent senses (both selector steps apply the same rules; ``vo3d_opt.swarm`` documents
them): the other vehicles within ``sensing.vehicle_range`` (centre distance), as neighbours with
their current velocity and ``r_pz = max(own r_pz, their r_pz)`` (so each side keeps the larger
zone, which is what the metrics count); those that do not decide (arrived ones hovering, and
``avoids: false``) as non-cooperative (they do not avoid, so a ``reciprocal`` selector takes all
of the avoidance, not half); the obstacles
within ``sensing.obstacle_range`` of their nearest point (those with ``sensed: false`` are never
seen), and the scenario's static spheres within that range as zero-velocity, non-cooperative
neighbours; its limits: speed ``(limits.speed[0], min(limits.speed[1], max_speed))`` less the
speed margin (``vo3d_opt.sim.safety``: RotorPy in wind) and the altitude range.

An agent within ``goal_tolerance`` of its goal has arrived: it stops (velocity 0 from that
sample on, which is what the others sense next), hovers there, still seen by the others, and no
longer decides, but while an agent that does not avoid, or one on a detour from a stall, not
yet arrived, is within its ``sensing.vehicle_range``: then it decides again with its goal as
preferred velocity until no such agent is in range and it is back within ``goal_tolerance``
(``traffic.keep_watch``; nobody else would steer round it, and hovering vehicles may wall a
stalled one off from its goal). The run stops when all agents have arrived and none keeps watch, or
after ``max_time``. The loop never clips a decision: the metrics report any limit it breaks (a
non-finite command becomes 0 with the status ``invalid_velocity (...)``).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from vo3d_opt.config import DEFAULT_PRESET
from vo3d_opt.extras import needs
from vo3d_opt.sim.deciders import decision_step
from vo3d_opt.sim.dynamics import Dynamics, make_dynamics
from vo3d_opt.sim.record import (
    DecisionStep,
    RunBuffers,
    RunRecord,
    SelectorLike,
    Snapshot,
    StepDecision,
    check_allotment,
)
from vo3d_opt.sim.safety import derive_margins, planning_speeds, within_reach
from vo3d_opt.sim.scenario import Scenario, load_scenario
from vo3d_opt.sim.traffic import GoalWithDetours, keep_watch

with needs("sim", "the simulator"):
    from tqdm import tqdm

if TYPE_CHECKING:
    from vo3d_opt.sim.rotorpy_fleet import RotorPyFleet

#: Default formulation when neither the caller nor the scenario names one.
DEFAULT_FORMULATION = "plane_qp"
#: The status of a command that was not a finite 3-vector (replaced by 0).
INVALID = "invalid_velocity"


def scenario_dynamics(sc: Scenario, fleet: RotorPyFleet | None = None) -> Dynamics:
    """The scenario's dynamics and wind (``velocity_response_tau`` is
    ``first_order``); the Dryden gusts are seeded with ``sensing.seed``. ``fleet``: the
    ``RotorPyFleet`` a batched RotorPy model joins (``vo3d_opt.sim.rotorpy_fleet``)."""
    extra = {} if fleet is None else {"fleet": fleet}
    return make_dynamics(sc.vehicle_dynamics, sc.wind, seed=sc.sensing.seed, **extra)


def scenario_goal_velocity(sc: Scenario) -> Callable[[np.ndarray], np.ndarray]:
    """The scenario's preferred-velocity rule as a function of the positions (N, 3), one per
    run (it keeps state): :func:`~vo3d_opt.sim.traffic.goal_velocity` towards each agent's goal,
    with :class:`~vo3d_opt.sim.traffic.GoalWithDetours`' way out of deadlocks."""
    return GoalWithDetours(sc.goals, sc.cruise_speed, float(sc.dt), near=sc.r_pz)


def _checked_commands(out: StepDecision, deciding: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The commands (0 for agents that do not decide) and statuses, a non-finite command
    replaced by 0 with the status ``invalid_velocity (...)``."""
    u = np.asarray(out.commands, dtype=float).reshape(deciding.shape[0], 3).copy()
    statuses = np.asarray(out.statuses)
    bad = deciding & ~np.all(np.isfinite(u), axis=1)
    if bad.any():
        statuses = statuses.astype(object)
        for i in np.flatnonzero(bad):
            statuses[i] = f"{INVALID} ({statuses[i]})"
    u[bad | ~deciding] = 0.0
    return u, statuses


#: Seconds a run goes before its progress bar shows (shorter runs show none).
PROGRESS_DELAY = 1.0


def _progress_bar(sc: Scenario, total: int, progress: bool | None) -> tqdm:
    """Steps against the most the run may take, with the arrivals alongside (when everyone
    arrived early, ``fly`` sets the total to the steps flown, so the bar ends at 100 %)."""
    return tqdm(
        total=total,
        desc=sc.name,
        unit="step",
        file=sys.stderr,
        delay=PROGRESS_DELAY,
        leave=False,
        dynamic_ncols=True,
        disable=(None if progress is None else not progress),
    )


def fly(
    sc: Scenario,
    step: DecisionStep,
    *,
    preferred_velocity: Callable[[np.ndarray], np.ndarray] | None = None,
    dynamics: Dynamics | None = None,
    progress: bool | None = None,
    max_steps: int | None = None,
    spill: bool | None = None,
    spill_dir: str | Path | None = None,
) -> RunRecord:
    """The one simulation loop (the module docstring): sense → ``step.decide`` → integrate,
    until every agent arrived and none keeps watch, or ``max_time`` (or ``max_steps``); a
    watcher away from its goal is recorded as not arrived. ``preferred_velocity``:
    positions (N, 3) → preferred velocities (N, 3), default the scenario's goal rule;
    ``dynamics``: default :func:`scenario_dynamics`; ``progress`` None = a bar only on a TTY;
    ``spill``: keep the record in a temporary file in ``spill_dir`` (:class:`RunBuffers`; None:
    when its allotment exceeds ``vo3d_opt.sim.spill.SPILL_BYTES``; Linux only, never on a file
    system held in memory)."""
    n, dt, tol = sc.n_agents, float(sc.dt), sc.goal_tolerance
    straight = ~sc.avoids  # avoids: false: fly the preferred (goal) velocity, never decide
    total = sc.n_steps if max_steps is None else min(max_steps, sc.n_steps)
    prefer = preferred_velocity or scenario_goal_velocity(sc)
    dyn = dynamics or scenario_dynamics(sc)
    check_allotment(total, n, dyn.model == "kinematic", spill_dir)
    dyn.reset(sc.starts)
    buf = RunBuffers(
        total, n, same_commands=dyn.model == "kinematic", spill=spill, spill_dir=spill_dir
    )
    p, v = dyn.positions, dyn.velocities
    margins = derive_margins(sc)
    rate = margins.command_rate  # None: commands may change at once
    last = v  # the commands before: rate-limited models change them gradually from these
    # the rate limit's cap: the planning speeds (a turn moved into reach may be faster than
    # either command), the top speed for those that fly straight
    top = np.where(straight, sc.max_speed, planning_speeds(sc, margins))
    done = np.linalg.norm(p - sc.goals, axis=1) <= tol
    dyn.hold(done)
    watching = np.zeros(n, dtype=bool)
    buf.pos[0], buf.arrived[0] = p, done
    steps = 0
    t_start = time.perf_counter()
    bar = _progress_bar(sc, total, progress)
    try:
        for k in range(total):
            watching = _watch(sc, p, done, watching, getattr(prefer, "stuck", None))
            if done.all() and not watching.any():
                break
            steps = k + 1
            _hover_or_decide(dyn, done, watching)
            v = dyn.velocities
            w = np.asarray(prefer(p), dtype=float)
            w[done & ~watching] = 0.0
            deciding = (~done | watching) & ~straight
            waiting = getattr(prefer, "waiting", None)
            snap = Snapshot(
                k=k,
                t=k * dt,
                positions=p,
                velocities=v,
                preferred=w,
                deciding=deciding,
                waiting=None if waiting is None else waiting & deciding & ~done,
            )
            out = step.decide(snap)
            u, statuses = _checked_commands(out, deciding)
            u[straight] = w[straight]
            if rate is not None:  # the vehicle's command interface, whoever decided: RotorPy's
                u = within_reach(u, last, rate, dt, top)  # velocity loop (safety.py)
                u[done & ~watching] = 0.0  # held in hover
                last = u
            buf.pref[k], buf.cmd[k], buf.decided[k] = w, u, deciding
            buf.put_statuses(k, statuses, deciding)
            buf.put_times(k, out.decision_times, out.solve_times, deciding)
            flown = dyn.step(u, dt)
            p = flown.positions
            buf.vel[k] = flown.velocities
            buf.put_samples(k, flown.sample_positions, flown.sample_velocities)
            at_goal = np.linalg.norm(p - sc.goals, axis=1) <= tol
            arrived = ~done & at_goal
            done = done | arrived
            dyn.hold(arrived)  # an arrived agent hovers: the others see it still (v: next step)
            if rate is not None:  # stopped dead: a release ramps from 0
                last = np.where(arrived[:, None], 0.0, last)
            # a watcher away from its goal is not there: a run ending so has not all arrived
            buf.pos[k + 1], buf.arrived[k + 1] = p, done & (at_goal | ~watching)
            buf.release(k)
            bar.update(1)
            bar.set_postfix_str(f"arrived {int(done.sum())}/{n}", refresh=False)
        if done.all() and bar.total != steps:  # everyone arrived before max_time: complete
            bar.total = steps
            shown = not bar.disable and bar.last_print_t >= bar.start_t + bar.delay
            if shown:  # a bar never shown is not drawn now: close() would leave it on screen
                bar.refresh()
    finally:
        bar.close()
    wall = time.perf_counter() - t_start
    return buf.record(sc, step.formulation, step.solver, steps, wall, step.extra())


def _hover_or_decide(dyn: Dynamics, done: np.ndarray, watching: np.ndarray) -> None:
    """Watchers decide again, from hover; arrived agents home again with nothing in range
    stop and hover."""
    dyn.release(watching)
    dyn.hold(done & ~watching & ~dyn.held)


def _watch(
    sc: Scenario, p: np.ndarray, done: np.ndarray, watching: np.ndarray, stuck: np.ndarray | None
) -> np.ndarray:
    """The arrived agents that decide this step (``traffic.keep_watch``)."""
    n = sc.n_agents
    return keep_watch(
        p,
        sc.goals,
        done=done,
        straight=~sc.avoids,
        watching=watching,
        tolerance=np.full(n, sc.goal_tolerance),
        vehicle_range=np.full(n, sc.sensing.vehicle_range),
        stuck=stuck,
    )


def make_selector(
    formulation: str | None = None, solver: str | None = None, options: dict[str, Any] | None = None
) -> tuple[Any, str, str]:
    """Build ``vo3d_opt.selector.VelocitySelector``; returns (selector, formulation, solver).

    Unknown formulations or solvers raise ``ValueError`` (from the selector's constructor).
    """
    from vo3d_opt.selector import VelocitySelector  # late: the simulator works without it

    formulation = formulation or DEFAULT_FORMULATION
    kwargs: dict[str, Any] = dict(options or {})
    kwargs["formulation"] = formulation
    if solver is not None:
        kwargs["solver"] = solver
    sel = VelocitySelector(**kwargs)
    name = solver
    if name is None:  # the selector's choice; "none" when it uses no solver (sampled)
        value = getattr(sel, "solver", "default")
        name = value if isinstance(value, str) else "none"
    return sel, formulation, name


class Simulator:
    """Runs one scenario with one selector shared by every agent: a ``VelocitySelector`` (or
    anything with its ``select_many``) decides for the whole swarm in one call per step
    (:class:`~vo3d_opt.sim.deciders.SwarmSelect`); any other ``SelectorLike`` is called once per
    agent per step, in id order (:class:`~vo3d_opt.sim.deciders.PerAgentSelect`; it must be
    stateless between calls, or at least deterministic given the call order).
    ``max_neighbors`` (the k nearest vehicles in range) and ``threads`` go to ``select_many``.
    """

    def __init__(
        self,
        scenario: Scenario,
        selector: SelectorLike,
        *,
        formulation: str = "custom",
        solver: str = "custom",
        max_neighbors: int | None = None,
        threads: int | None = None,
    ) -> None:
        self.scenario = scenario
        self.selector = selector
        self.step = decision_step(
            scenario,
            selector,
            formulation=formulation,
            solver=solver,
            max_neighbors=max_neighbors,
            threads=threads,
        )

    def run(
        self,
        *,
        progress: bool | None = None,
        max_steps: int | None = None,
        spill: bool | None = None,
        spill_dir: str | Path | None = None,
    ) -> RunRecord:
        """Simulate until every agent is home or ``max_time`` (``fly``); ``progress`` None =
        only on a TTY; ``spill``, ``spill_dir``: where the record lives (:func:`fly`)."""
        return fly(
            self.scenario,
            self.step,
            progress=progress,
            max_steps=max_steps,
            spill=spill,
            spill_dir=spill_dir,
        )


def scenario_selector(
    sc: Scenario, formulation: str | None = None, solver: str | None = None
) -> tuple[Any, str, str]:
    """The selector a scenario runs with: the given or the scenario's formulation and solver,
    configured by its ``selector_options`` (a preset, ``safe`` unless it names another, and
    fields over it) with ``sensing_range`` its vehicle sensing range. The simulator adds one
    thing of its own, from the scenario's physics: where the buffer ``vo3d_opt.sim.safety``
    derives (dynamics, noise, latency, a ``safety.pz_buffer``, agents slower than the limits)
    is not what the preset's ``buffer_steps`` gives each agent, it is passed in metres
    (``scenario_buffer``)."""
    options = {"sensing_range": float(sc.sensing.vehicle_range), **sc.selector_options}
    buffer = scenario_buffer(sc, options)
    if buffer is not None:
        options["pz_buffer"] = buffer
    return make_selector(formulation or sc.formulation, solver or sc.solver, options)


def flown_options(sc: Scenario) -> dict[str, Any]:
    """The selector options a run of ``sc`` flies with, as its summary reports them: the
    preset (``safe`` unless the scenario names another) and the fields set over it."""
    return {"preset": DEFAULT_PRESET, **sc.selector_options}


def scenario_buffer(sc: Scenario, options: dict[str, Any]) -> float | None:
    """The buffer (m) the scenario needs when the selector's own, ``buffer_steps`` steps of
    flight at each agent's top speed, is not it; None when it is (or ``pz_buffer`` is given)."""
    from vo3d_opt.config import SelectorConfig

    config = SelectorConfig.of(**options)
    if config.vo.pz_buffer is not None:
        return None
    steps = config.vo.buffer_steps
    margins = derive_margins(sc, steps)
    derived = margins.pz_buffer
    dt, top = float(sc.dt), np.minimum(planning_speeds(sc, margins), sc.limits.v_max)
    own = {steps * float(v) * dt for v in top[sc.avoids]} or {derived}
    return None if own == {derived} else derived


def run_scenario(
    scenario: Scenario | str | Path,
    selector: SelectorLike | None = None,
    *,
    formulation: str | None = None,
    solver: str | None = None,
    progress: bool | None = None,
    max_steps: int | None = None,
    max_neighbors: int | None = None,
    threads: int | None = None,
    spill: bool | None = None,
    spill_dir: str | Path | None = None,
) -> RunRecord:
    """Load (if a path) and run a scenario. Without ``selector``, build a ``VelocitySelector``
    from ``formulation``/``solver`` (falling back to the scenario's, then to plane_qp and the
    selector's default solver); ``ValueError`` for unknown names. ``spill``, ``spill_dir``:
    where the record lives (:func:`fly`; None: in a temporary file when larger than
    ``SPILL_BYTES``)."""
    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    if selector is None:
        selector, formulation, solver = scenario_selector(sc, formulation, solver)
    sim = Simulator(
        sc,
        selector,
        formulation=formulation or "custom",
        solver=solver or "custom",
        max_neighbors=max_neighbors,
        threads=threads,
    )
    return sim.run(progress=progress, max_steps=max_steps, spill=spill, spill_dir=spill_dir)
