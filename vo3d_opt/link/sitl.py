"""``vo3d sitl``: a whole scenario flown over real MAVLink by separate processes.

One router (:mod:`vo3d_opt.link.router`), one simulated vehicle per agent
(:mod:`vo3d_opt.link.vehicle`, system id k + 1 for the k-th agent) and one ``vo3d link`` per
agent that avoids, each a process of its own (:mod:`vo3d_opt.link.procs`: the vehicles and the
links forked once the package is imported), all on 127.0.0.1 and all on one clock: wall
time since a shared epoch (``time.monotonic`` is the same clock in every process) times
``time_scale``. The mission starts once every link has its vehicle in offboard / guided
(the straight flyers get SIGUSR1 then) and ends when every link has stopped and every
non-cooperative agent has arrived, or after the scenario's ``max_time``; every process is then
stopped (SIGTERM, SIGKILL for one that does not go), also on an error or Ctrl-C. The record
and the summary are built from the vehicles' logs (:mod:`vo3d_opt.link.sitl_record`).
"""

from __future__ import annotations

import json
import logging
import os
import select
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

from vo3d_opt.extras import needs
from vo3d_opt.link.faults import Fault, Injector
from vo3d_opt.link.frames import GeodeticFrame
from vo3d_opt.link.messages import load_signing_key
from vo3d_opt.link.procs import Forked, Proc
from vo3d_opt.link.vehicle import VehicleConfig, config_json, run_vehicle
from vo3d_opt.sim.scenario import Scenario

with needs("sim", "vo3d sitl"):
    import yaml

log = logging.getLogger("vo3d_opt.link.sitl")

#: Wall seconds given to the processes to start (import, bind) before the run's clock starts.
STARTUP = 0.5
#: Wall seconds the links get to engage (a first run may compile the selector's kernel).
ENGAGE_WALL = 180.0
#: Wall seconds a stopped process gets to write its log and summary before SIGKILL.
GRACE = 10.0
#: Models the simulated vehicles fly (RotorPy's multirotors need the simulator's sub-steps).
MODELS = ("kinematic", "first_order")


@dataclass
class SitlOptions:
    scenario: Scenario
    rate: float = 10.0
    time_scale: float = 1.0
    autopilot: str = "px4"
    signing_key: str | None = None
    origin: tuple[float, float, float] = (47.397742, 8.545594, 488.0)
    physics_rate: float = 50.0
    telemetry_rate: float = 25.0
    setpoint_timeout: float = 0.5
    faults: list[Fault] = field(default_factory=list)
    #: What a forked link runs: ``vo3d link ARGV``'s status (the command line's own entry,
    #: handed in so that this module needs no command line).
    link_main: Callable[[list[str]], int] | None = None


def _preload() -> None:
    """Import here, once, what every forked vehicle and link imports."""
    import vo3d_opt.link.loop  # noqa: F401
    from vo3d_opt.link.messages import mavlink

    mavlink()


def check_sitl_options(opts: SitlOptions) -> None:
    """``ValueError`` (naming the key) for what the harness cannot fly."""
    sc = opts.scenario
    if opts.link_main is None:
        raise ValueError("link_main: the command line's entry for the forked links is missing")
    model = sc.vehicle_dynamics.model
    if model not in MODELS:
        raise ValueError(f"{sc.source}: dynamics.model {model}: vo3d sitl flies {MODELS}")
    if sc.n_agents > 250:
        raise ValueError(f"{sc.source}: agents: vo3d sitl gives system ids 1-250 (one per agent)")
    cuts = [f.agent for f in opts.faults if f.kind == "cut"]
    if len(cuts) != len(set(cuts)):
        raise ValueError("--fault cut: one cut per agent")
    for f in opts.faults:
        if f.agent is not None and f.agent not in sc.ids:
            raise ValueError(f"--fault {f}: {f.agent} is not an agent of {sc.name}")
        if f.kind == "kill" and f.agent is not None and not sc.avoids[sc.ids.index(f.agent)]:
            raise ValueError(f"--fault {f}: {f.agent} has no link (avoids: false)")


class Sitl:
    """One run (:meth:`run`); ``self.procs`` are every process started, stopped in
    :meth:`stop_all` whatever happens."""

    def __init__(self, opts: SitlOptions, workdir: Path) -> None:
        check_sitl_options(opts)
        self.o, self.dir = opts, workdir
        sc = opts.scenario
        self.ids = {name: k + 1 for k, name in enumerate(sc.ids)}
        self.scenario_file = self._scenario_file()
        self.procs: list[Proc] = []
        self.links: dict[str, Proc] = {}
        self.vehicles: dict[str, Proc] = {}
        self.arrived: set[str] = set()
        self.events: list[dict[str, Any]] = []
        self.injected: dict[str, int] = {}
        self.read: dict[str, int] = {}  # event lines read, per vehicle
        self.engaged: set[str] = set()
        self.start: float | None = None  # the mission's start, once every link engaged
        self.epoch = 0.0

    def _scenario_file(self) -> str:
        sc = self.o.scenario
        if os.path.isfile(sc.source):
            return sc.source
        path = self.dir / "scenario.yaml"
        path.write_text(yaml.safe_dump(sc.model_dump(mode="json", exclude_none=True)))
        return str(path)

    def clock(self) -> float:
        return (time.monotonic() - self.epoch) * self.o.time_scale

    def _exec(self, name: str, argv: list[str]) -> Proc:
        popen = subprocess.Popen(
            [sys.executable, *argv],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=None,  # their warnings go where ours go
            text=True,
            start_new_session=True,  # Ctrl-C reaches us only: we stop them in order
        )
        return self._keep(Proc(name, popen))

    def _fork(self, name: str, target: Callable[[], int]) -> Proc:
        return self._keep(Proc(name, Forked(target)))

    def _keep(self, proc: Proc) -> Proc:
        self.procs.append(proc)
        return proc

    def _router(self) -> dict[str, int]:
        # run as a file: it needs only the standard library, not the package's imports
        proc = self._exec("router", [str(Path(__file__).with_name("router.py"))])
        ready, _, _ = select.select([proc.stdout], [], [], 30.0)
        line = proc.stdout.readline() if ready else ""
        if not line:
            raise RuntimeError("the router did not start")
        return dict(json.loads(line))

    def _vehicle(self, name: str, port: int) -> None:
        o = self.o
        cut = next((f for f in o.faults if f.kind == "cut" and f.agent == name), None)
        cfg = VehicleConfig(
            scenario=self.scenario_file,
            agent=name,
            system_id=self.ids[name],
            connect=f"udpout:127.0.0.1:{port}",
            origin=o.origin,
            epoch=self.epoch,
            log_file=str(self.dir / f"vehicle-{name}.npz"),
            autopilot=o.autopilot,
            time_scale=o.time_scale,
            physics_rate=o.physics_rate,
            telemetry_rate=o.telemetry_rate,
            setpoint_timeout=o.setpoint_timeout,
            signing_key=o.signing_key,
            icao=0xA00000 + self.ids[name],
            cut=None if cut is None else cut.amount,
        )
        self.vehicles[name] = self._fork(
            f"vehicle {name}", partial(run_vehicle, [config_json(cfg)])
        )

    def _link(self, name: str, port: int) -> None:
        o = self.o
        argv = [
            "link", "-q",
            "--connect", f"udpout:127.0.0.1:{port}",
            "--scenario", self.scenario_file,
            "--agent", name,
            "--rate", repr(o.rate),
            "--origin", ",".join(repr(x) for x in o.origin),
            "--system-ids", ",".join(f"{k}={v}" for k, v in self.ids.items()),
            "--autopilot", o.autopilot,
            "--arm",
            "--time-scale", repr(o.time_scale),
            "--epoch", repr(self.epoch),
            "--log", str(self.dir / f"link-{name}.npz"),
        ]  # fmt: skip
        if o.signing_key:
            argv += ["--signing-key", o.signing_key]
        assert self.o.link_main is not None  # check_sitl_options() refuses options without it
        self.links[name] = self._fork(f"link {name}", partial(self.o.link_main, argv))

    def run(self) -> float:
        """Start everything, fly until the end, stop everything; the run's end (s of the
        clock; the mission started at ``self.start``)."""
        sc, o = self.o.scenario, self.o
        try:
            _preload()
            ports = self._router()
            self.epoch = time.monotonic() + STARTUP
            for name in sc.ids:
                self._vehicle(name, ports["vehicles"])
            for k, name in enumerate(sc.ids):
                if sc.avoids[k]:
                    self._link(name, ports["links"])
            for proc in self.procs:  # threads only now: every fork is done
                proc.read_on()
            key = load_signing_key(o.signing_key) if o.signing_key else None
            injector = Injector(ports["vehicles"], self.ids, GeodeticFrame(*o.origin), key)
            return self._watch(injector)
        finally:
            self.stop_all()

    def _watch(self, injector: Injector) -> float:
        """Poll the processes, start the mission once every link engaged, fire the faults,
        until the end; the end's time."""
        sc = self.o.scenario
        pending = sorted(self.o.faults, key=lambda f: f.at)
        straight = {name for k, name in enumerate(sc.ids) if not sc.avoids[k]}
        wall_limit = time.monotonic() + ENGAGE_WALL
        while True:
            self._read_events()
            now = self.clock()
            for proc in self.vehicles.values():
                if not proc.alive():
                    raise RuntimeError(f"{proc.name} stopped unexpectedly")
            links_done = all(not p.alive() for p in self.links.values())
            if self.start is None:
                self._await_engagement(straight, wall_limit)
            else:
                while pending and self.start + pending[0].at <= now:
                    self._fire(pending.pop(0), injector)
                over = now >= self.start + float(sc.max_time)
                if (links_done and straight <= self.arrived) or over:
                    return now
            time.sleep(0.02)

    def _await_engagement(self, straight: set[str], wall_limit: float) -> None:
        """Start the mission (``self.start``; SIGUSR1 to the straight flyers) once every link
        has its vehicle in offboard / guided; refuse a link that stopped before."""
        gone = [name for name, p in self.links.items() if not p.alive()]
        if gone:
            raise RuntimeError(f"link {gone[0]} stopped before its vehicle engaged")
        if not set(self.links) <= self.engaged:
            if time.monotonic() > wall_limit:
                waiting = sorted(set(self.links) - self.engaged)
                raise RuntimeError(f"links {', '.join(waiting)} did not engage in {ENGAGE_WALL} s")
            return
        self.start = self.clock()
        log.info("t = %.2f s: every link engaged: the mission starts", self.start)
        for name in straight:
            self.vehicles[name].signal(signal.SIGUSR1)

    def _fire(self, fault: Fault, injector: Injector) -> None:
        log.info("t = %.2f s: fault %s", self.clock(), fault)
        if fault.kind in ("kill", "cut"):
            assert fault.agent is not None
            if fault.kind == "kill":
                self.links[fault.agent].signal(signal.SIGKILL)
            else:
                self.vehicles[fault.agent].signal(signal.SIGUSR2)
            self.injected[str(fault)] = 1
            return
        self.injected[str(fault)] = injector.send(fault)

    def _read_events(self) -> None:
        for name, proc in self.vehicles.items():
            seen = self.read.get(name, 0)
            for line in proc.lines[seen:]:
                event = json.loads(line)
                self.events.append(event)
                if event.get("arrived"):
                    self.arrived.add(name)
                if event.get("mode") == "offboard":
                    self.engaged.add(name)
            self.read[name] = seen + len(proc.lines[seen:])

    def stop_all(self) -> None:
        """SIGTERM the links, then the vehicles, then the router (each gets ``GRACE`` s to
        write what it must), SIGKILL any left; collect the links' summaries."""
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C waits
        try:
            self._stop_groups()
        finally:
            signal.signal(signal.SIGINT, previous)

    def _stop_groups(self) -> None:
        groups = [list(self.links.values()), list(self.vehicles.values())]
        groups.append([p for p in self.procs if p.name == "router"])
        for group in groups:
            for proc in group:
                proc.signal(signal.SIGTERM)
            deadline = time.monotonic() + GRACE
            for proc in group:
                proc.collect(deadline)

    def link_summaries(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for name, proc in self.links.items():
            text = "".join(proc.lines).strip().splitlines()
            out[name] = json.loads(text[-1]) if text else {"end": "killed", "agent": name}
        return out


def _interrupt(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt


def run_sitl(opts: SitlOptions) -> Any:
    """Fly ``opts`` and return its :class:`~vo3d_opt.link.sitl_record.SitlResult` (with
    ``interrupted`` set after Ctrl-C or SIGTERM: the summary of what flew until then).
    ``RuntimeError`` when a process failed before the mission started."""
    from vo3d_opt.link.sitl_record import build_result

    check_sitl_options(opts)
    previous = signal.signal(signal.SIGTERM, _interrupt)
    try:
        with tempfile.TemporaryDirectory(prefix="vo3d-sitl-") as tmp:
            sitl = Sitl(opts, Path(tmp))
            t0 = time.perf_counter()
            interrupted = False
            try:
                end = sitl.run()
            except KeyboardInterrupt:
                interrupted, end = True, sitl.clock()
            if sitl.start is None:
                raise KeyboardInterrupt
            result = build_result(sitl, (sitl.start, end), time.perf_counter() - t0)
            result.interrupted = interrupted
            return result
    finally:
        signal.signal(signal.SIGTERM, previous)


def print_sitl_summary(summary: dict[str, Any]) -> None:
    """The summary as ``vo3d run`` prints its table, plus the links' figures."""
    keys = [k for k in summary if k not in ("links", "faults")]
    width = max(len(k) for k in keys)
    for k in keys:
        value = summary[k]
        text = (
            ", ".join(f"{a}: {b}" for a, b in value.items()) if isinstance(value, dict) else value
        )
        print(f"{k:<{width}}  {text}")
