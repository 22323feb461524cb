"""Recorded decisions that a refactoring must not change.

``python tests/golden_cases.py`` draws seeded encounters (random ones, crowds closing in with
no safe velocity, vehicles inside zones, near the altitude limits, among obstacles, with an
acceleration bound, with non-cooperative traffic) and swarms, decides each with every named
configuration of the selector and writes inputs and answers to ``tests/data/golden.npz``;
``tests/test_golden.py`` decides the same inputs again and asserts the same answers, bit for
bit on the compiled path.

A configuration is a name and the keyword options it stood for when the file was recorded
(``OPTION_SETS``): the test maps each to today's way of asking for it (a preset and
overrides), so the file holds the meaning, not the spelling. Options that depend on the
decision's limits (the safe buffer: two steps at the top speed; the swarm horizon: the sensing
range over twice the top speed, none under an acceleration limit below 2 v_max / dt) are
recorded as the numbers they resolved to.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

GOLDEN = Path(__file__).parent / "data" / "golden.npz"
GOLDEN_RUNS = Path(__file__).parent / "data" / "golden_runs.json"
#: Summary keys that measure the machine, not the run.
TIMING_KEYS = (
    "decision_time_median_us",
    "decision_time_p99_us",
    "decision_time_max_us",
    "wall_time",
)
#: (scenario, extra ``vo3d run`` flags): every bundled scenario with its defaults, and a few
#: with the swarm flags.
RUN_FLAGS = (
    ("sphere-swap-16", "--swarm"),
    ("paper-case1-ten-uav-crossing", "--fast"),
    ("paper-case4-five-uav-six-square-obstacles", "--swarm"),
)
#: The sensing range the swarm configuration's horizon was derived from (m).
SWARM_RANGE = 55.0
FAST = {"plane_step_deg": 45.0, "qp_samples": 12, "heading_step_deg": 45.0, "speed_levels": 3,
        "fine_planes": False}
SAFE_GRID = {"plane_step_deg": 30.0, "qp_samples": 24, "fallback_heading_step_deg": 45.0,
             "fallback_speed_levels": 3}
KINDS = ("random", "crowd", "inside", "ceiling", "obstacles", "noncoop", "accel", "coplanar")


def _norm(x: np.ndarray) -> float:
    """|x|, its squares summed in index order: ``np.linalg.norm`` of a vector goes through
    BLAS's dot, whose kernels differ between CPUs in the last bit (fused multiply-adds), and
    the recorded inputs must be the same on every machine."""
    return math.sqrt(sum(float(t) * float(t) for t in np.ravel(x)))


def option_set(
    name: str, v_max: float, dt: float, acceleration: float | None = None
) -> dict[str, Any]:
    """The keyword options configuration ``name`` stood for at recording time, over the
    ``paper`` preset's values (the defaults then), for a decision with top speed ``v_max``,
    period ``dt`` and acceleration limit ``acceleration``: the recorder asks for them so."""
    shared = {"reciprocal": True, "closing_guard": True, "pz_buffer": 2.0 * v_max * dt}
    safe = {**shared, **SAFE_GRID}
    # the swarm horizon: RVO2-3D's, unless the acceleration limit keeps the vehicle from
    # taking any velocity within a step
    lagging = acceleration is not None and acceleration * dt < 2.0 * v_max
    swarm_horizon = None if lagging else float(SWARM_RANGE) / (2.0 * float(v_max))
    return {
        "paper": {},
        "safe": safe,
        "fast": {**shared, **FAST},
        "swarm": {**shared, **FAST, "horizon": swarm_horizon},
        "safe_no_escape": {**safe, "least_bad_escape": False},
        "fast_coarse": {**shared, **FAST, "fine_fallback": False},
        "paper_planes20": {"plane_step_deg": 20.0, "qp_samples": 24, "margin": 1e-2},
        "paper_corr": {"corrections": frozenset({"tg_range", "triangle", "base_chord"})},
        "safe_horizon": {**safe, "horizon": 4.0},
    }[name]


def recorded_selector(
    name: str,
    v_max: float,
    dt: float,
    formulation: str = "plane_qp",
    solver: str | None = None,
    acceleration: float | None = None,
) -> Any:
    """The selector the recorder decides configuration ``name`` with: ``option_set`` over the
    ``paper`` preset."""
    from vo3d_opt import VelocitySelector

    options = option_set(name, v_max, dt, acceleration)
    return VelocitySelector(formulation, solver, preset="paper", **options)


OPTION_SETS = (
    "paper",
    "safe",
    "fast",
    "swarm",
    "safe_no_escape",
    "fast_coarse",
    "paper_planes20",
    "paper_corr",
    "safe_horizon",
)
#: (formulation, solver, option sets, every k-th encounter) of the Python paths.
PY_PATHS = (
    ("sampled", None, ("paper", "fast"), 8),
    ("plane_qp", "daqp", ("paper", "safe"), 8),
    ("plane_qp", "osqp", ("safe",), 24),
    ("cone_qp", "daqp", ("paper", "safe"), 8),
    ("nlp", "casadi", ("safe",), 48),
)
N_ENCOUNTERS = 480
N_SWARMS = 10
# obstacle rows: kind (0 cylinder, 1 box), x, y, radius or lx, ly (box), height, yaw
OB_COLS = 7


def _unit(rng: np.random.Generator) -> np.ndarray:
    d = rng.normal(size=3)
    return d / _norm(d)


def _obstacle(rng: np.random.Generator, p: np.ndarray, near: float) -> np.ndarray:
    while True:
        c = p[:2] + rng.uniform(-near, near, 2)
        h = float(rng.uniform(5.0, 70.0))
        if rng.random() < 0.5:
            row = [0.0, c[0], c[1], rng.uniform(0.5, 5.0), 0.0, h, 0.0]
            half = row[3] + 1.5
        else:
            lx, ly = rng.uniform(1.0, 8.0, 2)
            row = [1.0, c[0], c[1], lx, ly, h, rng.uniform(-3.2, 3.2)]
            half = 0.75 * float(np.hypot(lx, ly)) + 1.5
        if _norm(c - p[:2]) > half + 0.5:  # own vehicle outside the prism
            return np.array(row)


def encounter(seed: int) -> dict[str, Any]:
    """Encounter ``seed`` as arrays: own (3+3), preferred (3), nbrs (n, 8), obstacles (m, 7),
    limits (v_min, v_max, z_min, z_max, acceleration or NaN), dt."""
    rng = np.random.default_rng(seed)
    kind = KINDS[seed % len(KINDS)]
    v_max = float(rng.uniform(1.0, 6.0))
    z_min, z_max = 0.0, float(rng.uniform(15.0, 60.0))
    dt = float(rng.uniform(0.05, 0.5))
    acc = float(rng.uniform(0.5, 10.0)) if kind == "accel" or rng.random() < 0.1 else np.nan
    z = rng.uniform(z_min + 0.5, z_max - 0.5)
    if kind == "ceiling":
        z = z_max - rng.uniform(0.01, 1.0) if rng.random() < 0.5 else z_min + rng.uniform(0.01, 1.0)
    p = np.array([0.0, 0.0, z])
    heading = rng.normal(size=3)
    heading[2] *= 1.0 if kind == "ceiling" else 0.3
    v_pref = heading / _norm(heading) * rng.uniform(0.3, 1.2) * v_max
    v_now = v_pref if rng.random() < 0.5 else _unit(rng) * rng.uniform(0.0, v_max)
    n = int(rng.integers(8, 31)) if kind == "crowd" else int(rng.integers(1, 13))
    nbrs = np.zeros((n, 8))
    for i in range(n):
        r_pz = float(rng.uniform(2.0, 10.0))
        d = _unit(rng)
        if kind == "coplanar":
            d[2] = 0.0
            d /= _norm(d)
        if kind == "crowd":
            dist, vb = rng.uniform(r_pz * 1.02, r_pz * 2.0), -d * rng.uniform(0.5, 4.0)
        else:
            dist = rng.uniform(r_pz * 1.05, 55.0)
            vb = _unit(rng) * rng.uniform(0.0, 4.0)
            if kind == "coplanar":
                vb[2] = 0.0
        if kind == "inside" and i == 0:
            dist = rng.uniform(0.2, 0.95) * r_pz
        coop = 0.0 if (kind == "noncoop" and rng.random() < 0.6) else 1.0
        nbrs[i] = [*(p + dist * d), *vb, r_pz, coop]
    m = int(rng.integers(2, 11)) if kind == "obstacles" else int(rng.integers(0, 4))
    obs = np.array([_obstacle(rng, p, 40.0 if kind != "obstacles" else 20.0) for _ in range(m)])
    return dict(
        own=np.concatenate([p, v_now]),
        pref=v_pref,
        nbrs=nbrs,
        obstacles=obs.reshape(-1, OB_COLS),
        limits=np.array([0.0, v_max, z_min, z_max, acc]),
        dt=dt,
    )


def swarm(seed: int) -> dict[str, Any]:
    """Swarm ``seed`` as ``select_many``'s arrays (obstacles as rows of ``OB_COLS``)."""
    rng = np.random.default_rng(10_000 + seed)
    n = int(rng.choice([12, 40, 120, 300]))
    half = float(rng.uniform(30.0, 120.0))
    P = np.column_stack([rng.uniform(-half, half, (n, 2)), rng.uniform(5.0, 35.0, n)])
    goal = -P + rng.normal(scale=5.0, size=P.shape)
    goal[:, 2] = np.clip(goal[:, 2], 5.0, 35.0)
    W = goal - P
    W *= 4.0 / np.maximum(np.linalg.norm(W, axis=1, keepdims=True), 1e-9)
    V = W + rng.normal(scale=0.5, size=W.shape)
    R = rng.uniform(3.0, 8.0, n) if seed % 2 else np.full(n, 5.0)
    obs = np.array(
        [_obstacle(rng, np.array([0.0, 0.0, 20.0]), half) for _ in range(seed % 4)]
    ).reshape(-1, OB_COLS)
    decide = rng.random(n) > (0.2 if seed % 3 == 0 else 0.0)
    return dict(
        P=P,
        V=V,
        W=W,
        R=R,
        obstacles=obs,
        decide=decide,
        max_neighbors=-1 if seed % 2 else 8,
        dt=0.2,
        sensing_range=55.0,
        obstacle_range=-1.0 if seed % 4 < 2 else 30.0,
        spheres=np.array([[10.0, -10.0, 20.0, 2.0, 6.0]]) if seed == 5 else np.zeros((0, 5)),
    )


# ------------------------------------------------------------------------------ to objects


def obstacles_of(rows: np.ndarray) -> list:
    from vo3d_opt import Box, Cylinder

    out = []
    for kind, x, y, a, b, h, yaw in rows:
        if kind == 0:
            out.append(Cylinder(center=(x, y), radius=a, height=h))
        else:
            out.append(Box(center=(x, y), size=(a, b), height=h, yaw=yaw))
    return out


def limits_of(row: np.ndarray):
    from vo3d_opt import Limits

    acc = None if np.isnan(row[4]) else float(row[4])
    return Limits(speed=(row[0], row[1]), altitude=(row[2], row[3]), acceleration=acc)


def select_kwargs(e: dict[str, Any]) -> dict[str, Any]:
    from vo3d_opt import AgentState, Neighbor

    return dict(
        own=AgentState(position=e["own"][:3], velocity=e["own"][3:]),
        preferred_velocity=e["pref"],
        neighbors=[
            Neighbor(position=r[:3], velocity=r[3:6], r_pz=r[6], cooperative=bool(r[7]))
            for r in e["nbrs"]
        ],
        obstacles=obstacles_of(e["obstacles"]),
        limits=limits_of(e["limits"]),
        dt=float(e["dt"]),
    )


def many_kwargs(s: dict[str, Any], limits) -> dict[str, Any]:
    return dict(
        positions=s["P"],
        velocities=s["V"],
        preferred_velocities=s["W"],
        r_pz=s["R"],
        obstacles=obstacles_of(s["obstacles"]),
        limits=limits,
        dt=s["dt"],
        sensing_range=s["sensing_range"],
        max_neighbors=None if s["max_neighbors"] < 0 else int(s["max_neighbors"]),
        decide=s["decide"],
        obstacle_range=None if s["obstacle_range"] < 0 else float(s["obstacle_range"]),
        spheres=s["spheres"],
    )


SWARM_LIMITS = np.array([0.0, 4.0, 0.0, 40.0, np.nan])
SWARM_SETS = ("paper", "safe", "fast", "swarm")


# ------------------------------------------------------------------------------ recording


def _record() -> None:
    out: dict[str, np.ndarray] = {}
    rows = []
    for seed in range(N_ENCOUNTERS):
        e = encounter(seed)
        kw = select_kwargs(e)
        v_max, dt = float(e["limits"][1]), float(e["dt"])
        acc = kw["limits"].acceleration
        for name in OPTION_SETS:
            sel = recorded_selector(name, v_max, dt, acceleration=acc)
            d = sel.select(**kw)
            rows.append(("plane_qp", "exact2d", name, seed, d))
        for form, solver, names, every in PY_PATHS:
            if seed % every:
                continue
            for name in names:
                sel = recorded_selector(name, v_max, dt, form, solver, acc)
                rows.append((form, solver or "", name, seed, sel.select(**kw)))
    out["dec_path"] = np.array([f"{f}/{s}" for f, s, *_ in rows])
    out["dec_set"] = np.array([r[2] for r in rows])
    out["dec_seed"] = np.array([r[3] for r in rows])
    out["dec_velocity"] = np.array([r[4].velocity for r in rows])
    out["dec_status"] = np.array([str(r[4].status) for r in rows])
    out["dec_plane"] = np.array([np.nan if r[4].plane is None else r[4].plane for r in rows])
    out["dec_round"] = np.array([str(r[4].info.get("round", "")) for r in rows])
    for seed in range(N_SWARMS):
        s = swarm(seed)
        kw = many_kwargs(s, limits_of(SWARM_LIMITS))
        for name in SWARM_SETS:
            sel = recorded_selector(name, 4.0, 0.2)
            res = sel.select_many(**kw)
            out[f"swarm{seed}_{name}_velocities"] = res.velocities
            out[f"swarm{seed}_{name}_statuses"] = np.asarray(res.statuses, dtype=str)
    GOLDEN.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(GOLDEN, **out)
    statuses, counts = np.unique(out["dec_status"], return_counts=True)
    print(f"{len(rows)} decisions, {N_SWARMS} swarms x {len(SWARM_SETS)} -> {GOLDEN}")
    print(dict(zip(statuses.tolist(), counts.tolist(), strict=True)))
    rounds, counts = np.unique(out["dec_round"], return_counts=True)
    print(dict(zip(rounds.tolist(), counts.tolist(), strict=True)))


def run_summary(name: str, *flags: str) -> dict[str, Any]:
    """``vo3d run NAME FLAGS --json``'s summary without its timing keys."""
    import json
    import subprocess

    vo3d = Path(sys.executable).with_name("vo3d")
    out = subprocess.run(
        [str(vo3d), "run", name, *flags, "--json", "-q"], check=True, capture_output=True, text=True
    )
    summary = json.loads(out.stdout)
    return {k: v for k, v in summary.items() if k not in TIMING_KEYS}


def _record_runs() -> None:
    import json

    from vo3d_opt.sim.scenario.loader import bundled_dir

    names = sorted(p.stem for p in Path(bundled_dir()).glob("*.yaml"))
    runs = {name: run_summary(name) for name in names}
    for name, flag in RUN_FLAGS:
        runs[f"{name} {flag}"] = run_summary(name, flag)
    GOLDEN_RUNS.write_text(json.dumps(runs, indent=1, sort_keys=True) + "\n")
    print(f"{len(runs)} runs -> {GOLDEN_RUNS}")


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    _record()
    if "--runs" in sys.argv:
        _record_runs()
