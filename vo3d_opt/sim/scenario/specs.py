"""The scenario file's groups of keys (``sensing``, ``safety``, ``defaults``, each agent, each
obstacle, each sphere): frozen pydantic models, unknown keys refused (the whole format and its
cross-checks: :mod:`vo3d_opt.sim.scenario.schema`)."""

from __future__ import annotations

from typing import Annotated, Any, ClassVar, Literal

from pydantic import (
    ConfigDict,
    Field,
    StrictBool,
)

from vo3d_opt.types import (
    PZ_MARGIN,
    Box,
    Cylinder,
    Model,
    NonNegative,
    Positive,
    Vec3,
)

Text = Annotated[str, Field(min_length=1)]


class Spec(Model):
    """Base of the scenario-only groups of keys (frozen, unknown keys refused)."""

    model_config = ConfigDict(frozen=True, extra="forbid", arbitrary_types_allowed=True)


class SensingSpec(Spec):
    """Sensing ranges of Table 1 (vehicles by centre distance, obstacles by nearest point) and
    what a vehicle senses of the others: Gaussian noise per axis (1-sigma, m and
    m/s), latency (s, a multiple of ``dt``: checked by the scenario) and the noise's seed."""

    vehicle_range: Positive = 55.0
    obstacle_range: Positive = 55.0
    position_noise: NonNegative = 0.0
    velocity_noise: NonNegative = 0.0
    latency: NonNegative = 0.0
    seed: Annotated[int, Field(ge=0, strict=True)] = 0

    @property
    def perfect(self) -> bool:
        """No noise and no latency: every vehicle senses the same true snapshot."""
        return self.position_noise == 0 and self.velocity_noise == 0 and self.latency == 0


class SafetySpec(Spec):
    """Overrides of what the simulator derives from the scenario to stay safe under its
    dynamics and sensing (``vo3d_opt.sim.safety``, ``formulations/real_world.md``); each None
    (the default) is derived, 0 switches that inflation off. ``acceleration``: m/s² per axis
    (the selector's ``Limits.acceleration``; None derived, 0 none); ``pz_buffer``: m (the
    selector's option); ``altitude_margin``: m kept from each altitude bound while planning;
    ``obstacle_margin``: m added to every obstacle's protected prism while planning (given,
    it alone sizes them: the prism tops are not raised by the tracking error either);
    ``speed_margin``: m/s planned below each vehicle's top speed (RotorPy in wind: derived)."""

    acceleration: NonNegative | None = None
    pz_buffer: NonNegative | None = None
    altitude_margin: NonNegative | None = None
    obstacle_margin: NonNegative | None = None
    speed_margin: NonNegative | None = None


class DefaultsSpec(Spec):
    """Per-agent parameters unless an agent overrides them (section 5: r_pz = 10 m)."""

    r_pz: Positive = 10.0
    radius: Positive = 0.5
    max_speed: Positive = 4.0
    #: m/s: the speed an agent prefers on its way (the preferred velocity's); None: max_speed
    cruise_speed: Positive | None = None


class AgentSpec(Spec):
    """One UAV: identifier, start and goal positions (m) and optional parameter overrides."""

    id: Text
    start: Vec3
    goal: Vec3
    r_pz: Positive | None = None
    radius: Positive | None = None
    max_speed: Positive | None = None
    cruise_speed: Positive | None = None
    avoids: StrictBool = True  # false: flies straight to its goal, never avoids


class _Placed:
    """What a scenario adds to a public obstacle type: its ``type`` tag and ``sensed``."""

    public: ClassVar[type[Cylinder] | type[Box]]

    def body(self) -> Cylinder | Box:
        """The obstacle as its public type (what the selector and the metrics take)."""
        cls = self.public
        return cls.model_construct(**{k: getattr(self, k) for k in cls.model_fields})


class CylinderSpec(_Placed, Cylinder):
    """A vertical cylinder standing on the ground (section 4.1): ``types.Cylinder``'s keys."""

    public: ClassVar[type[Cylinder]] = Cylinder
    type: Literal["cylinder"]
    sensed: StrictBool = True


class BoxSpec(_Placed, Box):
    """A (possibly yawed) box standing on the ground (section 4.3): ``types.Box``'s keys."""

    public: ClassVar[type[Box]] = Box
    type: Literal["box"]
    sensed: StrictBool = True


#: The ``type`` tags of the obstacle union (pydantic puts them in error locations).
OBSTACLE_TAGS = frozenset({"cylinder", "box"})
ObstacleSpec = Annotated[CylinderSpec | BoxSpec, Field(discriminator="type")]


class SphereSpec(Spec):
    """A static sphere, seen by the agents as a zero-velocity Neighbor (original 3D VO)."""

    center: Vec3
    radius: Positive
    margin: NonNegative = PZ_MARGIN
    physical: StrictBool = True

    @property
    def r_pz(self) -> float:
        return self.radius + self.margin


Problem = tuple[tuple[Any, ...], str, Any]
