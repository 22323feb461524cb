"""A simulated vehicle that speaks the MAVLink a link uses, the way PX4's offboard interface
(or ArduCopter's guided mode) does; one process per vehicle of ``vo3d sitl``. A test harness,
not an autopilot.

* it starts in the air at its scenario start, armed, hovering in hold (PX4: auto loiter;
  ArduCopter: loiter), and sends a heartbeat every second (autopilot PX4 or ArduPilotMega,
  its mode in ``custom_mode`` as the real one encodes it);
* ``COMMAND_LONG``: ``MAV_CMD_DO_SET_MODE`` to offboard / guided (PX4: only after set-points
  have streamed for ``OFFBOARD_PROOF`` s, else temporarily rejected) or to hold;
  ``MAV_CMD_COMPONENT_ARM_DISARM`` (disarming in the air is denied); each answered by a
  ``COMMAND_ACK``; other commands: unsupported;
* ``SET_POSITION_TARGET_LOCAL_NED`` addressed to it, velocity-only in ``MAV_FRAME_LOCAL_NED``:
  its velocity command while in offboard / guided; no set-point for ``setpoint_timeout`` s
  (PX4's ``COM_OF_LOSS_T``, ArduPilot's ``GUID_TIMEOUT``) and it falls back to hold, which
  commands zero velocity;
* every ``1 / telemetry_rate`` s its state: ``GLOBAL_POSITION_INT`` and
  ``LOCAL_POSITION_NED`` (its local origin the world's); a non-cooperative agent
  (``avoids: false``) instead flies straight to its goal and is heard only as
  ``ADSB_VEHICLE`` traffic;
* the scenario's dynamics (kinematic, first_order) fly the command, stepped every
  ``1 / physics_rate`` s of its clock; every step is logged for the run's record.

Run as ``python -m vo3d_opt.link.vehicle CONFIG_JSON`` (:class:`VehicleConfig`'s fields); it
prints one JSON line per event (``arrived``, ``mode``) on stdout and stops on SIGTERM. A
non-cooperative agent hovers at its start until SIGUSR1 (``vo3d sitl`` sends it when every
link has engaged: the mission's start); SIGUSR2 starts a telemetry cut of ``cut`` seconds.
"""

from __future__ import annotations

import json
import os
import signal
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from vo3d_opt.link.frames import GeodeticFrame
from vo3d_opt.link.messages import (
    AUTOPILOT_COMPONENT,
    adsb_vehicle,
    custom_mode_of,
    external_mode,
    global_position,
    hold_mode,
    load_signing_key,
    local_position,
    mavlink,
    setpoint_velocity,
)
from vo3d_opt.link.transport import MavlinkPort
from vo3d_opt.sim.dynamics import make_dynamics
from vo3d_opt.sim.scenario import load_scenario
from vo3d_opt.sim.traffic import goal_velocity

#: Seconds of set-points PX4 wants before it enters offboard (it says "more than a second";
#: the link streams ``--prestream`` s, default 1).
OFFBOARD_PROOF = 0.5
HEARTBEAT_PERIOD = 1.0


@dataclass
class VehicleConfig:
    """One simulated vehicle: agent ``agent`` of ``scenario`` (a path), system ``system_id``,
    talking to ``connect``; clock: wall time since ``epoch`` (time.monotonic) times
    ``time_scale``; ``cut``: seconds without sending anything from a SIGUSR2 on (a telemetry
    cut the run's orchestrator starts)."""

    scenario: str
    agent: str
    system_id: int
    connect: str
    origin: tuple[float, float, float]
    epoch: float
    log_file: str
    autopilot: str = "px4"
    time_scale: float = 1.0
    physics_rate: float = 50.0
    telemetry_rate: float = 25.0
    setpoint_timeout: float = 0.5
    signing_key: str | None = None
    icao: int = 0
    cut: float | None = None


class Vehicle:
    def __init__(self, cfg: VehicleConfig) -> None:
        self.cfg = cfg
        sc = load_scenario(cfg.scenario)
        i = sc.ids.index(cfg.agent)
        self.sc, self.i = sc, i
        self.straight = not bool(sc.avoids[i])
        self.goal, self.v_max = sc.goals[i], float(sc.cruise_speed[i])
        self.dyn = make_dynamics(sc.vehicle_dynamics, sc.wind, seed=sc.sensing.seed)
        self.dyn.reset(sc.starts[i : i + 1])
        self.frame = GeodeticFrame(*cfg.origin)
        key = load_signing_key(cfg.signing_key) if cfg.signing_key else None
        self.port = MavlinkPort(
            cfg.connect,
            source_system=cfg.system_id,
            source_component=AUTOPILOT_COMPONENT,
            signing_key=key,
            link_id=1,
        )
        self.mav = self.port.mav
        self.external = False  # offboard / guided
        self.armed = True
        self.command = np.zeros(3)
        self.stream_since = -np.inf  # when the current set-point stream began
        self.last_setpoint = -np.inf
        self.arrived = False
        self.go = not self.straight  # a straight flyer waits for SIGUSR1 (the mission's start)
        self.cut_from = np.inf  # SIGUSR2: a telemetry cut starts
        self.stop = False
        self.rows: list[np.ndarray] = []

    def clock(self) -> float:
        return (time.monotonic() - self.cfg.epoch) * self.cfg.time_scale

    def event(self, **what: Any) -> None:
        print(json.dumps({"agent": self.cfg.agent, "t": round(self.clock(), 4), **what}))
        sys.stdout.flush()

    # --- incoming --------------------------------------------------------------------------

    def take(self, msg: Any, now: float) -> None:
        kind = msg.get_type()
        if getattr(msg, "target_system", None) != self.cfg.system_id:
            return
        if getattr(msg, "target_component", 0) not in (0, AUTOPILOT_COMPONENT):
            return
        if kind == "SET_POSITION_TARGET_LOCAL_NED":
            self.setpoint(msg, now)
        elif kind == "COMMAND_LONG":
            self.ack(msg, self.command_result(msg, now))

    def setpoint(self, msg: Any, now: float) -> None:
        v = setpoint_velocity(msg)
        if v is None:
            return
        if now - self.last_setpoint > self.cfg.setpoint_timeout:
            self.stream_since = now
        self.last_setpoint = now
        if self.external:
            self.command = v

    def command_result(self, msg: Any, now: float) -> int:
        m = mavlink()
        if msg.command == m.MAV_CMD_COMPONENT_ARM_DISARM:
            if msg.param1 == 0 and not self.straight:
                return int(m.MAV_RESULT_DENIED)  # in the air
            self.armed = msg.param1 != 0
            return int(m.MAV_RESULT_ACCEPTED)
        if msg.command != m.MAV_CMD_DO_SET_MODE:
            return int(m.MAV_RESULT_UNSUPPORTED)
        wanted = (int(msg.param2), int(msg.param3))
        if wanted == hold_mode(self.cfg.autopilot):
            self.enter(False, "commanded")
            return int(m.MAV_RESULT_ACCEPTED)
        if wanted != external_mode(self.cfg.autopilot) or self.straight:
            return int(m.MAV_RESULT_UNSUPPORTED)
        streaming = now - self.last_setpoint <= self.cfg.setpoint_timeout
        proof = self.cfg.autopilot != "px4" or now - self.stream_since >= OFFBOARD_PROOF
        if not (self.armed and streaming and proof):
            return int(m.MAV_RESULT_TEMPORARILY_REJECTED)
        self.enter(True, "commanded")
        return int(m.MAV_RESULT_ACCEPTED)

    def ack(self, msg: Any, result: int) -> None:
        self.port.send(
            self.mav.command_ack_encode(
                msg.command, result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent()
            )
        )

    def enter(self, external: bool, why: str) -> None:
        """Switch mode; a change is announced by a heartbeat at once (not at the next second:
        the peers learn sooner that this vehicle no longer avoids)."""
        changed = external != self.external
        self.external = external
        if not external:
            self.command = np.zeros(3)
        if changed:
            self.event(mode="offboard" if external else "hold", why=why)
            if not self.silent(self.clock()):
                self.heartbeat()

    # --- outgoing --------------------------------------------------------------------------

    def heartbeat(self) -> None:
        m = mavlink()
        mode = external_mode if self.external else hold_mode
        custom = custom_mode_of(self.cfg.autopilot, *mode(self.cfg.autopilot))
        base = m.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (
            m.MAV_MODE_FLAG_SAFETY_ARMED if self.armed else 0
        )
        pilot = (
            m.MAV_AUTOPILOT_PX4 if self.cfg.autopilot == "px4" else m.MAV_AUTOPILOT_ARDUPILOTMEGA
        )
        self.port.send(
            self.mav.heartbeat_encode(m.MAV_TYPE_QUADROTOR, pilot, base, custom, m.MAV_STATE_ACTIVE)
        )

    def telemetry(self, now: float) -> None:
        p, v = self.dyn.positions[0], self.dyn.velocities[0]
        if self.straight:
            self.port.send(adsb_vehicle(self.mav, self.frame, p, v, self.cfg.icao))
            return
        ms = int(now * 1000)
        self.port.send(global_position(self.mav, self.frame, p, v, ms))
        self.port.send(local_position(self.mav, p, v, ms))

    def silent(self, now: float) -> bool:
        cut = self.cfg.cut
        return cut is not None and self.cut_from <= now < self.cut_from + cut

    # --- the loop --------------------------------------------------------------------------

    def run(self) -> None:
        cfg = self.cfg
        signal.signal(signal.SIGTERM, self._on_signal)
        signal.signal(signal.SIGINT, self._on_signal)
        signal.signal(signal.SIGUSR1, self._on_go)
        signal.signal(signal.SIGUSR2, self._on_cut)
        wall_step = 1.0 / (cfg.physics_rate * cfg.time_scale)
        every = max(1, round(cfg.physics_rate / cfg.telemetry_rate))
        next_wall, ticks = time.monotonic(), 0
        last_t, last_beat = max(self.clock(), 0.0), -np.inf
        self.log(last_t, np.zeros(3))
        parent = os.getppid()
        while not self.stop:
            if os.getppid() != parent:  # vo3d sitl is gone (killed): do not outlive it
                break
            while not self.stop and (left := next_wall - time.monotonic()) > 0:
                self.port.wait(left)
                for msg in self.port.receive():
                    self.take(msg, self.clock())
            next_wall = max(next_wall + wall_step, time.monotonic())
            now = self.clock()
            if now < 0:  # before the epoch: everyone waits at the start
                continue
            self.fly(now, now - last_t)
            last_t = now
            ticks += 1
            if self.silent(now):
                continue
            if now - last_beat >= HEARTBEAT_PERIOD and not self.straight:
                self.heartbeat()
                last_beat = now
            if ticks % every == 0:
                self.telemetry(now)
        self.save()

    def _on_signal(self, signum: int, frame: Any) -> None:
        self.stop = True

    def _on_go(self, signum: int, frame: Any) -> None:
        self.go = True

    def _on_cut(self, signum: int, frame: Any) -> None:
        self.cut_from = self.clock()

    def fly(self, now: float, h: float) -> None:
        """Step the dynamics by ``h`` s with the command in force, after the failsafe."""
        if self.external and now - self.last_setpoint > self.cfg.setpoint_timeout:
            self.enter(False, "setpoint timeout")
        u = self.command
        if self.straight and self.go and not self.arrived:
            p = self.dyn.positions
            u = goal_velocity(p, self.goal[None], self.v_max, max(h, 1e-3))[0]
        if h > 0:
            self.dyn.step(u[None], h)
        if not self.arrived:
            gap = float(np.linalg.norm(self.dyn.positions[0] - self.goal))
            if gap <= self.sc.goal_tolerance:
                self.arrived = True
                if self.straight:
                    self.dyn.hold(np.ones(1, dtype=bool))
                self.event(arrived=True)
        self.log(now, u)

    def log(self, now: float, u: np.ndarray) -> None:
        row = np.concatenate(
            [[now], self.dyn.positions[0], self.dyn.velocities[0], u, [float(self.external)]]
        )
        self.rows.append(row)

    def save(self) -> None:
        """The log: an ``.npz`` with ``t`` (S,), ``p``, ``v``, ``u`` (S, 3), ``external`` (S,)."""
        a = np.asarray(self.rows, dtype=float).reshape(-1, 11)
        np.savez(
            Path(self.cfg.log_file),
            t=a[:, 0],
            p=a[:, 1:4],
            v=a[:, 4:7],
            u=a[:, 7:10],
            external=a[:, 10] > 0.5,
        )
        self.port.close()


def config_json(cfg: VehicleConfig) -> str:
    return json.dumps(asdict(cfg))


def run_vehicle(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    data = json.loads(args[0])
    data["origin"] = tuple(data["origin"])
    Vehicle(VehicleConfig(**data)).run()
    return 0


if __name__ == "__main__":
    sys.exit(run_vehicle())
