"""``vo3d link``: one vehicle of a scenario flown through its autopilot over MAVLink.

Every ``1 / rate`` s (:meth:`Link.run`), between which it reads the connection:

1. **connect**: wait for the autopilot's heartbeat (system ``target_system``), sending the
   link's own heartbeat every second;
2. **engage**: stream zero-velocity set-points for ``prestream`` s (PX4 enters offboard only
   after a second of them), arm if asked, then ask for offboard (PX4) / guided (ArduPilot)
   with ``MAV_CMD_DO_SET_MODE`` every second until the heartbeat shows it;
3. **fly**: decide with the scenario's selector (:mod:`vo3d_opt.link.planning`) from the own
   state and the neighbours (:mod:`vo3d_opt.link.neighbors`), and send the velocity as a
   ``SET_POSITION_TARGET_LOCAL_NED`` set-point. Own state older than ``state_timeout`` or no
   autopilot heartbeat for ``link_timeout``: a zero set-point instead (brake to a hover),
   said on stderr and counted as a status;
4. **stop** on arrival (within the goal tolerance), ``max_time``, SIGINT or SIGTERM: brake,
   ask the autopilot to hold (PX4 hold / ArduCopter loiter), print the summary (a second
   signal meanwhile only cuts short the wait for the hold). If the autopilot leaves
   offboard / guided by itself (a pilot took over, a failsafe), the link stops commanding at
   once and ends; so it does when the other end closes a TCP connection.

Times are the link's clock: wall time since ``epoch`` times ``time_scale`` (1 on a real
vehicle; ``vo3d sitl`` runs faster than real time with a shared epoch).
"""

from __future__ import annotations

import logging
import signal
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from vo3d_opt.link.frames import GeodeticFrame
from vo3d_opt.link.messages import (
    AUTOPILOT_COMPONENT,
    ONBOARD_COMPONENT,
    Rejected,
    external_mode,
    flavour,
    hold_mode,
    mavlink,
    read_state,
    setpoint,
    under_external_control,
)
from vo3d_opt.link.neighbors import Track, Tracks
from vo3d_opt.link.planning import Plan, link_selector
from vo3d_opt.link.report import LinkLog, link_summary
from vo3d_opt.link.transport import MavlinkPort
from vo3d_opt.sim.scenario import Scenario
from vo3d_opt.types import AgentState

log = logging.getLogger("vo3d_opt.link")

#: Statuses of the ticks on which the link did not call the selector.
STALE, LOST = "hover: own state stale", "hover: link lost"
#: Seconds between the link's heartbeats, and between two tries of a command.
HEARTBEAT_PERIOD, RETRY_PERIOD = 1.0, 1.0


@dataclass
class LinkOptions:
    """Everything ``vo3d link`` takes (``vo3d_opt.link.command`` documents each)."""

    connect: str
    scenario: Scenario
    agent: str
    system_ids: dict[str, int]
    rate: float = 10.0
    signing_key: bytes | None = None
    origin: tuple[float, float, float] | None = None
    local_origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    autopilot: str = "auto"
    target_component: int = AUTOPILOT_COMPONENT
    source_system: int | None = None
    source_component: int = ONBOARD_COMPONENT
    extra_systems: tuple[int, ...] = ()
    arm: bool = False
    prestream: float = 1.0
    state_timeout: float = 0.5
    link_timeout: float = 3.0
    neighbor_timeout: float = 1.5
    connect_timeout: float = 30.0
    mode_timeout: float = 15.0
    max_time: float | None = None
    traffic_r_pz: float | None = None
    traffic_speed: float | None = None
    time_scale: float = 1.0
    epoch: float | None = None
    baud: int = 57600
    log_file: Path | None = None

    @property
    def target_system(self) -> int:
        return self.system_ids[self.agent]

    @property
    def state_message(self) -> str:
        return "GLOBAL_POSITION_INT" if self.origin is not None else "LOCAL_POSITION_NED"


@dataclass
class _Autopilot:
    """What the link knows of its own autopilot."""

    flavour: str | None = None
    heartbeat_t: float = -np.inf
    external: bool = False
    acks: Counter[str] = field(default_factory=Counter)


class Link:
    """One link session (:meth:`run` flies it and returns the summary)."""

    def __init__(self, opts: LinkOptions) -> None:
        self.o = opts
        sc = opts.scenario
        self.period = 1.0 / opts.rate
        self.epoch = time.monotonic() if opts.epoch is None else opts.epoch
        self.built = link_selector(sc, opts.agent)
        self.built.warm_up()
        self.plan = Plan(sc, opts.agent, self.period)
        self.frame = GeodeticFrame(*opts.origin) if opts.origin is not None else None
        self.local_origin = np.asarray(opts.local_origin, dtype=float)
        self.tracks = self._tracks()
        self.own = Track(opts.agent, self.plan.r_pz, self.plan.top_speed)
        self.own_wall = -np.inf  # wall time of the newest accepted own state
        self.allowed = set(opts.system_ids.values()) | set(opts.extra_systems)
        self.pilot = _Autopilot(flavour=None if opts.autopilot == "auto" else opts.autopilot)
        self.rejected: Counter[str] = Counter()
        self.record = LinkLog()
        self.stop_reason: str | None = None
        self.engaged_at: float | None = None
        self.said: str | None = None
        self.log_failed = False
        self.signals = 0  # SIGINT / SIGTERM received
        self.port = MavlinkPort(
            opts.connect,
            source_system=opts.source_system or opts.target_system,
            source_component=opts.source_component,
            signing_key=opts.signing_key,
            baud=opts.baud,
        )
        self.mav = self.port.mav

    def _tracks(self) -> Tracks:
        o, sc = self.o, self.o.scenario
        straight = [k for k in range(sc.n_agents) if not sc.avoids[k]]
        tracks = Tracks(
            timeout=o.neighbor_timeout,
            late_after=o.state_timeout,
            sensing_range=float(sc.sensing.vehicle_range),
            own_r_pz=self.plan.r_pz,
            traffic_r_pz=(
                o.traffic_r_pz
                if o.traffic_r_pz is not None
                else float(max((sc.r_pz[k] for k in straight), default=np.max(sc.r_pz)))
            ),
            traffic_speed=(
                o.traffic_speed
                if o.traffic_speed is not None
                else float(max((sc.max_speed[k] for k in straight), default=np.max(sc.max_speed)))
            ),
        )
        for k, name in enumerate(sc.ids):  # non-cooperative agents are heard as ADS-B traffic
            if name != o.agent and name in o.system_ids and sc.avoids[k]:
                tracks.add_peer(o.system_ids[name], name, float(sc.r_pz[k]), float(sc.max_speed[k]))
        return tracks

    def clock(self) -> float:
        """The link's time (s): wall time since the epoch, times ``time_scale``."""
        return (time.monotonic() - self.epoch) * self.o.time_scale

    # --- reading ------------------------------------------------------------------------------

    def _read_until(self, wall_deadline: float) -> None:
        while self.stop_reason is None:
            left = wall_deadline - time.monotonic()
            if left <= 0:
                return
            self.port.wait(left)
            for msg in self.port.receive():
                self._take(msg)
            if self.port.closed:
                self.stop_reason = "connection closed"

    def _take(self, msg: Any) -> None:
        src, kind = msg.get_srcSystem(), msg.get_type()
        if src not in self.allowed:
            self.rejected["foreign_system"] += 1
            return
        now = self.clock()
        if kind == "HEARTBEAT":
            self._heartbeat(msg, src, now)
        elif kind == "COMMAND_ACK" and src == self.o.target_system:
            self.pilot.acks[f"{msg.command}:{msg.result}"] += 1
        elif kind in (self.o.state_message, "ADSB_VEHICLE"):
            self._state(msg, src, now)

    def _heartbeat(self, msg: Any, src: int, now: float) -> None:
        kind = flavour(msg.autopilot)
        if kind is None:  # a ground station or a companion computer
            return
        if src == self.o.target_system:
            if self.pilot.flavour is None:
                self.pilot.flavour = kind
            self.pilot.heartbeat_t = now
            self.pilot.external = under_external_control(kind, msg.custom_mode)
        else:
            self.tracks.heartbeat(src, under_external_control(kind, msg.custom_mode), now)

    def _state(self, msg: Any, src: int, now: float) -> None:
        try:
            report = read_state(msg, self.frame, self.local_origin)
        except Rejected as exc:
            self.rejected[exc.reason] += 1
            return
        if report.icao is None and src == self.o.target_system:
            why = self.tracks.update(self.own, report.position, report.velocity, now)
            if why is None:
                self.own_wall = time.monotonic()
        elif report.icao is None and src not in self.tracks.peers:
            return  # a system allowed for its ADS-B reports only
        else:
            why = self.tracks.update(
                self.tracks.track_for(src, report.icao), report.position, report.velocity, now
            )
        if why is not None:
            self.rejected[why] += 1

    # --- sending ------------------------------------------------------------------------------

    def _send_setpoint(self, velocity: np.ndarray) -> None:
        self.port.send(
            setpoint(
                self.mav,
                velocity,
                time_boot_ms=int((time.monotonic() - self.epoch) * 1000),
                target_system=self.o.target_system,
                target_component=self.o.target_component,
            )
        )

    def _send_heartbeat(self) -> None:
        m = mavlink()
        self.port.send(
            self.mav.heartbeat_encode(
                m.MAV_TYPE_ONBOARD_CONTROLLER, m.MAV_AUTOPILOT_INVALID, 0, 0, m.MAV_STATE_ACTIVE
            )
        )

    def _command(self, command: int, *params: float) -> None:
        p = [*params, *([0.0] * (7 - len(params)))]
        self.port.send(
            self.mav.command_long_encode(
                self.o.target_system, self.o.target_component, command, 0, *p
            )
        )

    def _set_mode(self, main: int, sub: int) -> None:
        m = mavlink()
        self._command(m.MAV_CMD_DO_SET_MODE, m.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, main, sub)

    def _say(self, what: str) -> None:
        """Log a change of situation once (not every tick it lasts)."""
        if what != self.said:
            log.warning("vo3d link %s: %s", self.o.agent, what)
            self.said = what

    # --- the session --------------------------------------------------------------------------

    def run(self, report: Callable[[dict[str, Any]], None] | None = None) -> dict[str, Any]:
        """Fly until a stop; the summary (``vo3d_opt.link.report.link_summary``), handed to
        ``report`` (e.g. printed) before SIGINT / SIGTERM are the caller's again: a signal
        while stopping must not cut the hold, the log or the summary."""
        previous = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
        for s in previous:
            signal.signal(s, self._on_signal)
        try:
            try:
                self._session()
            finally:
                self._finish()
            summary = link_summary(self)
            if report is not None:
                report(summary)
        finally:
            for s, handler in previous.items():
                signal.signal(s, handler)
        return summary

    def _on_signal(self, signum: int, frame: Any) -> None:
        self.signals += 1
        self.stop_reason = self.stop_reason or "signal"

    def _session(self) -> None:
        wall_period = self.period / self.o.time_scale
        next_tick = time.monotonic()
        last_beat = -np.inf
        started = self.clock()
        engage_from: float | None = None
        last_try = -np.inf
        while self.stop_reason is None:
            self._read_until(next_tick)
            if self.stop_reason is not None:
                break
            next_tick = max(next_tick + wall_period, time.monotonic())
            now = self.clock()
            if now - last_beat >= HEARTBEAT_PERIOD:
                self._send_heartbeat()
                last_beat = now
            if self.pilot.heartbeat_t == -np.inf:  # 1. connect
                if now - started > self.o.connect_timeout:
                    self.stop_reason = "no autopilot heartbeat"
                continue
            if self.engaged_at is None:  # 2. engage
                engage_from = now if engage_from is None else engage_from
                self._send_setpoint(np.zeros(3))
                if self.pilot.external and now - engage_from >= self.o.prestream:
                    self.engaged_at = now
                    log.info("vo3d link %s: engaged at t = %.2f s", self.o.agent, now)
                elif now - engage_from >= self.o.prestream and now - last_try >= RETRY_PERIOD:
                    self._engage()
                    last_try = now
                if now - engage_from > self.o.mode_timeout:
                    self.stop_reason = "mode refused"
                continue
            self._fly(now)  # 3. fly

    def _engage(self) -> None:
        m = mavlink()
        if self.o.arm:
            self._command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
        self._set_mode(*external_mode(self.pilot.flavour or "px4"))

    def _fly(self, now: float) -> None:
        o = self.o
        assert self.engaged_at is not None
        if o.max_time is not None and now - self.engaged_at >= o.max_time:
            self.stop_reason = "max_time"
            return
        if not self.pilot.external:
            self.stop_reason = "autopilot left offboard/guided"
            return
        lost = now - self.pilot.heartbeat_t > o.link_timeout
        stale = self.own.position is None or self.own.age(now) > o.state_timeout
        if lost or stale:
            status = LOST if lost else STALE
            self._say(f"{status}: braking to a hover")
            self._send_setpoint(np.zeros(3))
            # no latency: this set-point does not come from a state
            self.record.tick(now, status, np.zeros(3), np.nan, np.nan)
            return
        assert self.own.position is not None and self.own.velocity is not None
        p = self.own.position
        if self.plan.arrived(p):
            self.stop_reason = "arrived"
            return
        self._decide(now, p, self.own.velocity)

    def _decide(self, now: float, p: np.ndarray, v: np.ndarray) -> None:
        plan = self.plan
        neighbors = self.tracks.neighbors(p, now) + plan.sphere_neighbors(p)
        own, preferred, obstacles = (
            AgentState(position=p, velocity=v),
            plan.preferred(p),
            plan.obstacles(p),
        )
        t0 = time.perf_counter()
        d = self.built.selector.select(
            own=own,
            preferred_velocity=preferred,
            neighbors=neighbors,
            obstacles=obstacles,
            limits=plan.limits,
            dt=self.period,
        )
        spent = time.perf_counter() - t0
        u = np.asarray(d.velocity, dtype=float).reshape(-1)
        status = str(d.status)
        if u.shape != (3,) or not np.all(np.isfinite(u)):
            u, status = np.zeros(3), f"invalid_velocity ({status})"
        self._send_setpoint(u)
        self.said = None
        self.record.tick(now, status, u, self._latency(), spent)

    def _latency(self) -> float:
        """Wall seconds from the newest own state's arrival to now (a set-point just sent)."""
        return time.monotonic() - self.own_wall

    def _finish(self) -> None:
        """Brake and ask for hold (unless the autopilot left offboard by itself or the
        connection is closed); write the log; close."""
        try:
            told = self.engaged_at is not None and not self.port.closed  # else no one listens
            if told and self.stop_reason != "autopilot left offboard/guided":
                for _ in range(3):
                    self._send_setpoint(np.zeros(3))
                self._set_mode(*hold_mode(self.pilot.flavour or "px4"))
                self._await_hold()
        except OSError as exc:  # the link is gone: nothing more to tell the autopilot
            log.warning("vo3d link %s: could not ask for hold: %s", self.o.agent, exc)
        finally:
            self.ended_at = self.clock()
            self._save_log()
            self.port.close()

    def _save_log(self) -> None:
        """Write ``--log``; a failure (a full disk) is said and kept in ``log_failed``: the
        flight is over, and its summary must still be printed."""
        if self.o.log_file is None:
            return
        try:
            self.record.save(self.o.log_file)
        except OSError as exc:
            log.error("vo3d link %s: --log %s: %s", self.o.agent, self.o.log_file, exc)
            self.log_failed = True

    def _await_hold(self) -> None:
        """Up to a second (link time), re-asking every 0.25 s, until the heartbeat shows the
        autopilot out of offboard / guided; a signal meanwhile (Ctrl-C again) ends the wait."""
        deadline = self.clock() + 1.0
        retry = self.clock() + 0.25
        self.stop_reason = self.stop_reason or "stopped"
        signals = self.signals
        while self.clock() < deadline and self.pilot.external and self.signals == signals:
            wall = time.monotonic() + 0.01 / self.o.time_scale
            self.port.wait(max(wall - time.monotonic(), 0.0))
            for msg in self.port.receive():
                self._take(msg)
            if self.clock() >= retry:
                self._set_mode(*hold_mode(self.pilot.flavour or "px4"))
                retry = self.clock() + 0.25
