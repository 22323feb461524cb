"""What a link knows of the vehicles around it, and how old it is.

Every position report (own vehicle, cooperative peers by system id, ADS-B traffic by ICAO
address) lands in a :class:`Track`. The rules, and why:

* **implausible reports are refused** (:meth:`Tracks.update`): a speed above
  ``SPEED_FACTOR`` times the vehicle's top speed plus ``SPEED_SLACK``, or a jump from the last
  accepted position farther than that speed could fly since (plus ``JUMP_SLACK`` for
  quantisation and GPS noise). A forged packet that claims another system's id elsewhere is
  caught so; one placed where the real vehicle could be is not: that takes signing.
* **late data grows the zone**: a neighbour is planned with ``r_pz`` (the larger of the two
  vehicles', as in the simulator) plus its age times its top speed, which covers wherever it
  may have flown since it last reported; its age counts from the report's arrival here.
* **old data is dropped** after ``timeout`` s: a vehicle that stopped reporting may have landed
  or left, and a ghost whose zone keeps growing would block the others for good. A dropped
  track is taken afresh from its next report, without the jump check.
* a peer is **cooperative** only while its autopilot's heartbeat says it flies its companion's
  set-points (offboard / guided) and that heartbeat is recent: a peer whose link stopped holds
  position and no longer avoids, so the others take all of the avoidance (``reciprocal``
  selectors take half for cooperative neighbours only). ADS-B traffic is never cooperative.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from vo3d_opt.types import Neighbor

#: A report faster than SPEED_FACTOR x top speed + SPEED_SLACK (m/s) is impossible.
SPEED_FACTOR, SPEED_SLACK = 2.0, 2.0
#: Metres a position may jump beyond what that speed explains (quantisation, GPS noise).
JUMP_SLACK = 3.0
#: A heartbeat older than this (s) says nothing about a peer's mode any more.
HEARTBEAT_TIMEOUT = 3.0


@dataclass
class Track:
    """The last accepted report of one vehicle: world ``position``, ``velocity``, when it
    arrived (``t``, s), its ``r_pz`` and ``top_speed``."""

    name: str
    r_pz: float
    top_speed: float
    position: np.ndarray | None = None
    velocity: np.ndarray | None = None
    t: float = -np.inf
    cooperative: bool = False
    heartbeat_t: float = -np.inf
    dropped: bool = False
    peer: bool = True  # False: ADS-B traffic

    def age(self, now: float) -> float:
        return now - self.t

    def plausible(self, p: np.ndarray, v: np.ndarray, now: float, timeout: float) -> str | None:
        """None, or why the report (``p``, ``v`` at ``now``) is refused."""
        cap = SPEED_FACTOR * self.top_speed + SPEED_SLACK
        if float(np.linalg.norm(v)) > cap:
            return "impossible"
        fresh = self.position is None or self.dropped or self.age(now) > timeout
        if fresh:
            return None
        assert self.position is not None
        reach = cap * max(self.age(now), 0.0) + JUMP_SLACK
        return "implausible_jump" if float(np.linalg.norm(p - self.position)) > reach else None


@dataclass
class Tracks:
    """Own vehicle and neighbours: ``timeout`` (s) before a silent neighbour is dropped,
    ``late_after`` (s) from which its data counts as late (reported, not treated otherwise:
    the zone grows with any age), ``sensing_range`` (m, centre distance), ``own_r_pz``."""

    timeout: float
    late_after: float
    sensing_range: float
    own_r_pz: float
    peers: dict[int, Track] = field(default_factory=dict)
    traffic: dict[int, Track] = field(default_factory=dict)
    traffic_r_pz: float = 0.0
    traffic_speed: float = 0.0
    #: per neighbour name: ticks planned with late data, and drops
    late: Counter[str] = field(default_factory=Counter)
    drops: Counter[str] = field(default_factory=Counter)
    #: per peer: ticks it was planned as non-cooperative (its autopilot not under its link)
    passive: Counter[str] = field(default_factory=Counter)

    def add_peer(self, system_id: int, name: str, r_pz: float, top_speed: float) -> None:
        self.peers[system_id] = Track(name, r_pz, top_speed)

    def track_for(self, system_id: int, icao: int | None) -> Track:
        """The peer's track, or the ADS-B aircraft's (made on first sight)."""
        if icao is None:
            return self.peers[system_id]
        if icao not in self.traffic:
            self.traffic[icao] = Track(
                f"adsb:{icao:06X}", self.traffic_r_pz, self.traffic_speed, peer=False
            )
        return self.traffic[icao]

    def update(self, track: Track, p: np.ndarray, v: np.ndarray, now: float) -> str | None:
        """Take a report into ``track``; None, or why it was refused."""
        why = track.plausible(p, v, now, self.timeout)
        if why is None:
            track.position, track.velocity, track.t = p, v, now
            track.dropped = False
        return why

    def heartbeat(self, system_id: int, external: bool, now: float) -> None:
        track = self.peers.get(system_id)
        if track is not None:
            track.cooperative, track.heartbeat_t = external, now

    def neighbors(self, own: np.ndarray, now: float) -> list[Neighbor]:
        """The neighbours to plan with at ``now`` seen from ``own`` (world position): within
        the sensing range, not dropped, each zone grown by its age times its top speed."""
        out = []
        for track in [*self.peers.values(), *self.traffic.values()]:
            if track.position is None or track.dropped:
                continue
            assert track.velocity is not None
            age = max(track.age(now), 0.0)
            if age > self.timeout:
                track.dropped = True
                self.drops[track.name] += 1
                continue
            if float(np.linalg.norm(track.position - own)) > self.sensing_range:
                continue
            if age > self.late_after:
                self.late[track.name] += 1
            recent = now - track.heartbeat_t <= HEARTBEAT_TIMEOUT
            cooperative = bool(track.cooperative and recent)
            if not cooperative and track.peer:
                self.passive[track.name] += 1
            out.append(
                Neighbor(
                    position=track.position,
                    velocity=track.velocity,
                    r_pz=max(self.own_r_pz, track.r_pz) + age * track.top_speed,
                    cooperative=cooperative,
                )
            )
        return out
