"""How a selector is configured: named presets and one typed, frozen configuration.

``VelocitySelector(preset="safe", **overrides)`` resolves here: the preset's values over the
fields' own defaults (which are the paper's selection), then each keyword over one field.
:data:`PRESET_VALUES` is the one table of presets; :class:`SelectorConfig` groups the fields by
concern (the velocity obstacles, the safety rules, the planes, the sampled grid, the outside
backends). Every field has a documented range; a value outside it, an unknown field or an
unknown preset is one ``ValueError`` naming it and the choices.

Two fields are stated in what they mean and resolved per decision from its limits
(:meth:`SelectorConfig.resolve`): the buffer, ``buffer_steps`` steps of flight at the top
speed (``buffer_steps · v_max · dt`` metres unless ``pz_buffer`` gives metres), and the horizon
``"sensing"``, the time two vehicles closing head-on at the top speed take to cross the sensing
range (``sensing_range / (2 v_max)``, RVO2-3D's time horizon), or none under an acceleration
limit that keeps the vehicle from taking any velocity within a step (:func:`turns_at_once`).
"""

from __future__ import annotations

import difflib
import math
import numbers
from collections.abc import Mapping
from functools import cached_property
from typing import Annotated, Any, Final, Literal

import numpy as np
from pydantic import BeforeValidator, Field, PlainValidator, StrictBool, ValidationError

from .types import InputError, Model, check_number, one_line, short_repr

#: Every correction of the paper's section 3.1 (the names ``corrections`` takes).
CORRECTIONS: Final = (
    "tg_range",
    "symmetry_abs",
    "triangle",
    "base_chord",
    "vo_lines",
    "virtual_sphere",
)
#: ``horizon: "sensing"``: the sensing range over twice the top speed (none for a vehicle that
#: cannot take any velocity within a step: :func:`turns_at_once`).
SENSING = "sensing"


def _number(lo: float, hi: float, *, strict_lo: bool = False) -> Any:
    """A number in [lo, hi] (``strict_lo``: (lo, hi]); booleans and strings refused."""
    field = (
        Field(gt=lo, le=hi, allow_inf_nan=False)
        if strict_lo
        else Field(ge=lo, le=hi, allow_inf_nan=False)
    )
    return Annotated[float, BeforeValidator(check_number), field]


def _horizon(value: Any) -> float | str | None:
    """A horizon: None, "sensing", or a number of seconds in (0, 1e6]."""
    if value is None or value == SENSING:
        return None if value is None else SENSING
    what = f"must be a number of seconds in (0, 1e6], null or {SENSING!r}, got"
    if isinstance(value, (bool, np.bool_, str, bytes)) or not isinstance(value, numbers.Real):
        raise ValueError(f"{what} {short_repr(value)}")
    seconds = float(value)
    if not (math.isfinite(seconds) and 0.0 < seconds <= 1e6):
        raise ValueError(f"{what} {short_repr(value)}")
    return seconds


def _count(lo: int, hi: int) -> Any:
    return Annotated[int, Field(ge=lo, le=hi, strict=True)]


class VOConfig(Model):
    """The velocity obstacles: who takes which share of an avoidance, how far ahead and how
    large the zones are planned."""

    #: RVO: the cone's apex at (V_A + V_B)/2 for a cooperative neighbour, each of two vehicles
    #: running the same selector taking half of their avoidance.
    reciprocal: StrictBool = False
    #: s, (0, 1e6]: meetings further ahead are ignored; None: the paper's unbounded VO;
    #: "sensing": ``sensing_range / (2 v_max)``, or none under an acceleration limit that
    #: keeps the vehicle from taking any velocity within a step (``turns_at_once``).
    horizon: Annotated[float | str | None, PlainValidator(_horizon)] = None
    #: s, (0, 1e6]: how far ahead an obstacle's VO pyramid reaches (RVO2-3D's
    #: ``timeHorizonObst``); None: without a horizon, whatever ``horizon`` is. A neighbour
    #: that meets the vehicle late can still turn when it does; a prism does not, and a turn
    #: left late under actuator lag sinks into it.
    obstacle_horizon: _number(0.0, 1e6, strict_lo=True) | None = None  # type: ignore[valid-type]
    #: m, (0, 1e7]: what ``horizon: "sensing"`` is computed from (``select_many`` knows its own).
    sensing_range: _number(0.0, 1e7, strict_lo=True) | None = None  # type: ignore[valid-type]
    #: [0, 100]: every neighbour's sphere planned this many steps of flight at the top speed
    #: larger (``buffer_steps · v_max · dt``): both vehicles move before the next decision.
    buffer_steps: _number(0.0, 100.0) = 0.0  # type: ignore[valid-type]
    #: m, [0, 1e4]: the buffer in metres, in place of ``buffer_steps``; None: from the steps.
    pz_buffer: _number(0.0, 1e4) | None = None  # type: ignore[valid-type]
    #: m/s, (0, 1]: linearised VO half-spaces are pushed out by this much, so that an answer on
    #: a boundary (within a solver's tolerance) is still strictly outside the VO.
    margin: _number(0.0, 1.0, strict_lo=True) = 1e-3  # type: ignore[valid-type]
    #: The corrections of section 3.1 that apply (None: all six of :data:`CORRECTIONS`).
    corrections: frozenset[Literal[CORRECTIONS]] | None = None  # type: ignore[valid-type]


class SafetyConfig(Model):
    """Rules beyond the paper for when vehicles decide at once or no velocity is safe."""

    #: The speed towards each cooperative neighbour near its zone at most half the gap per
    #: step, so that two vehicles deciding on the same snapshot cannot both close it.
    closing_guard: StrictBool = False
    #: When every velocity tried enters a zone at once (the vehicle inside planning spheres or
    #: prisms): the one closing slowest on the zones it is inside, not the one nearest the
    #: preference.
    least_bad_escape: StrictBool = True
    #: With an obstacle in reach or a neighbour that does not avoid, the fallbacks' grid takes
    #: at least the default grid's speeds and headings, however coarse it is otherwise.
    fine_fallback: StrictBool = True
    #: degrees, [1, 180]: headings of the fallbacks' grid (tried when no QP answer is safe);
    #: None: the sampled grid's, ``heading_step_deg``.
    fallback_heading_step_deg: _number(1.0, 180.0) | None = None  # type: ignore[valid-type]
    #: [2, 50]: speeds of the fallbacks' grid; None: the sampled grid's, ``speed_levels``.
    fallback_speed_levels: _count(2, 50) | None = None  # type: ignore[valid-type]
    #: With an obstacle in reach or a neighbour that does not avoid, the avoidance planes and
    #: tangent samples at least the default ones, however coarse they are otherwise.
    fine_planes: StrictBool = True


class PlaneConfig(Model):
    """The avoidance planes (every formulation) and plane_qp's linearisation."""

    #: degrees, [1, 180]: avoidance planes every this many degrees in [-90, 90].
    plane_step_deg: _number(1.0, 180.0) = 10.0  # type: ignore[valid-type]
    #: [8, 720]: generator samples of eq. (12) plane_qp linearises the sections at.
    qp_samples: _count(8, 720) = 36  # type: ignore[valid-type]


class SampledConfig(Model):
    """The paper's sampled selection: a polar grid on every plane (the fallbacks' grid too,
    unless ``fallback_heading_step_deg`` or ``fallback_speed_levels`` give it its own)."""

    #: degrees, [1, 180]: headings of the grid on each plane.
    heading_step_deg: _number(1.0, 180.0) = 10.0  # type: ignore[valid-type]
    #: [2, 50]: speeds of the grid, v_min to v_max.
    speed_levels: _count(2, 50) = 9  # type: ignore[valid-type]
    #: [8, 720]: generator samples of the conic curves of eq. (12).
    n_samples: _count(8, 720) = 72  # type: ignore[valid-type]


class BackendConfig(Model):
    """Outside QP backends."""

    #: [3, 256]: sides of the polygon inscribed in the speed disc, for backends without cones.
    polygon_sides: _count(3, 256) = 24  # type: ignore[valid-type]


#: The groups of :class:`SelectorConfig` and their types, in order.
GROUPS: Final[dict[str, type[Model]]] = {
    "vo": VOConfig,
    "safety": SafetyConfig,
    "planes": PlaneConfig,
    "sampled": SampledConfig,
    "backends": BackendConfig,
}
#: Each field's group: a keyword names a field, whatever group it is in.
FIELD_GROUP: Final[dict[str, str]] = {
    name: group for group, model in GROUPS.items() for name in model.model_fields
}

_SHARED: Final[dict[str, Any]] = {"reciprocal": True, "buffer_steps": 2.0, "closing_guard": True}
_SAFE: Final[dict[str, Any]] = {
    **_SHARED,
    "plane_step_deg": 30.0,
    "qp_samples": 24,
    "fallback_heading_step_deg": 45.0,
    "fallback_speed_levels": 3,
}
_COARSE: Final[dict[str, Any]] = {
    "plane_step_deg": 45.0,
    "qp_samples": 12,
    "heading_step_deg": 45.0,
    "speed_levels": 3,
    "fine_planes": False,
}
#: The presets, as the fields they set over the defaults (which are ``paper``'s):
#:
#: - ``safe`` (the default): what the simulator flies; every vehicle runs the same selector,
#:   so each takes half of a pairwise avoidance (reciprocal), plans every sphere two steps of
#:   flight larger (both move before the next decision), and caps its speed towards a close
#:   neighbour (closing guard); planes every 30 degrees with 24 tangent samples and a fallback
#:   grid of 8 headings by 3 speeds (the default grid near an obstacle or a vehicle that does
#:   not avoid: ``fine_fallback``; the default planes too: ``fine_planes``), so that a
#:   crowded decision costs few rows;
#: - ``paper``: the selection as published, the VO unbounded and unshared;
#: - ``fast``: the shared rules of ``safe`` with planes every 45 degrees, 12 tangent samples
#:   and a sampled grid (the fallbacks' too) of 8 headings by 3 speeds, the planes as coarse
#:   near obstacles (``fine_planes`` off): for swarms where time matters more than the
#:   shortest detour;
#: - ``swarm``: ``fast`` with RVO2-3D's time horizon, ``sensing_range / (2 v_max)``, for
#:   vehicles that change velocity within a step (without an acceleration limit, or one that
#:   spans the speed ball per step); with a tighter one, no horizon.
PRESET_VALUES: Final[dict[str, Mapping[str, Any]]] = {
    "safe": _SAFE,
    "paper": {},
    "fast": {**_SHARED, **_COARSE},
    "swarm": {**_SHARED, **_COARSE, "horizon": SENSING},
}
#: The preset names.
PRESETS: Final = tuple(PRESET_VALUES)
DEFAULT_PRESET: Final = "safe"


class SelectorConfig(Model):
    """A resolved configuration: the preset it started from and every field, by group."""

    preset: str = DEFAULT_PRESET
    vo: VOConfig = VOConfig()
    safety: SafetyConfig = SafetyConfig()
    planes: PlaneConfig = PlaneConfig()
    sampled: SampledConfig = SampledConfig()
    backends: BackendConfig = BackendConfig()

    @classmethod
    def of(cls, preset: str | None = None, **overrides: Any) -> SelectorConfig:
        """``preset``'s values (None: :data:`DEFAULT_PRESET`), each keyword over one field;
        ``ValueError`` naming an unknown preset or field and the choices, or a bad value."""
        preset = DEFAULT_PRESET if preset is None else preset
        if not isinstance(preset, str) or preset not in PRESET_VALUES:
            raise ValueError(
                f"preset: unknown {one_line(repr(preset))[:40]}; choices: {', '.join(PRESETS)}"
            )
        unknown = [k for k in overrides if k not in FIELD_GROUP]
        if unknown:
            raise ValueError(
                f"{unknown[0]}: unknown option; options: {', '.join(sorted(FIELD_GROUP))}"
            )
        values = {**PRESET_VALUES[preset], **overrides}
        groups: dict[str, dict[str, Any]] = {g: {} for g in GROUPS}
        for name, value in values.items():
            groups[FIELD_GROUP[name]][name] = value
        try:
            return cls.model_validate({"preset": preset, **groups})
        except ValidationError as exc:
            err = InputError.from_validation("options", exc)
            path, problem = err.problems[0]
            raise ValueError(f"{path.rpartition('.')[2]}: {problem}") from None

    def flat(self) -> dict[str, Any]:
        """Every field by its own name (what a keyword override names)."""
        return {name: getattr(getattr(self, FIELD_GROUP[name]), name) for name in FIELD_GROUP}

    def overrides(self) -> dict[str, Any]:
        """The fields that differ from the preset's values: what a keyword changed."""
        base = SelectorConfig.of(self.preset).flat()
        return {k: v for k, v in self.flat().items() if v != base[k]}

    @cached_property
    def per_decision(self) -> bool:
        """Whether :meth:`resolve` depends on the decision's limits: a buffer in steps, or the
        horizon from the sensing range."""
        vo = self.vo
        return (vo.pz_buffer is None and vo.buffer_steps > 0) or vo.horizon == SENSING

    def resolve(
        self,
        v_max: float,
        dt: float,
        sensing_range: float | None = None,
        acceleration: float | None = None,
    ) -> dict:
        """The numbers one decision plans with, keyed as the decision kernel's options: the
        buffer in metres and the horizon in seconds (None: none) for top speed ``v_max``,
        period ``dt`` and acceleration limit ``acceleration`` (m/s², None: none);
        ``sensing_range`` stands in for the configuration's when it holds none. ``ValueError``
        when the horizon needs a range that neither gives."""
        vo = self.vo
        pz_buffer = vo.buffer_steps * v_max * dt if vo.pz_buffer is None else vo.pz_buffer
        horizon = vo.horizon
        if horizon == SENSING:
            rng = vo.sensing_range if vo.sensing_range is not None else sensing_range
            if rng is None:
                raise ValueError(
                    f"sensing_range: preset {self.preset!r} derives its horizon from the "
                    "sensing range; give VelocitySelector(..., sensing_range=METRES) or "
                    "select(..., sensing_range=METRES)"
                )
            horizon = float(rng) / (2.0 * float(v_max)) if v_max > 0 else None
            if horizon is not None and not math.isfinite(horizon):
                horizon = None  # an unbounded range: no horizon
            if not turns_at_once(v_max, dt, acceleration):
                # A late reaction is safe only for a vehicle that can change its velocity
                # within a step: under bounded acceleration (a lagging vehicle) the conflicts
                # a horizon leaves for later pile up in a crowd until no velocity in reach
                # is safe.
                horizon = None
        flat = self.flat()
        for name in ("buffer_steps", "sensing_range"):
            del flat[name]
        return {**flat, "pz_buffer": float(pz_buffer), "horizon": horizon}


def turns_at_once(v_max: float, dt: float, acceleration: float | None) -> bool:
    """Whether a vehicle with top speed ``v_max`` and acceleration limit ``acceleration``
    (m/s², None: none) can take any velocity within one period ``dt``: the acceleration
    bound spans the speed ball, ``2 v_max``, per step."""
    return acceleration is None or acceleration * dt >= 2.0 * v_max


def describe() -> str:
    """The presets and their values, one line each (for ``--help`` texts and errors)."""
    return "; ".join(
        f"{name}: " + (", ".join(f"{k}={v}" for k, v in values.items()) or "the defaults")
        for name, values in PRESET_VALUES.items()
    )


#: How :func:`check_options` reports a key that is no option (a hint may follow).
UNKNOWN_OPTION: Final = "unknown key"
#: The keys a mapping of selector options takes (a scenario's ``selector_options``, the
#: command line's ``-o``): ``preset`` and every field.
OPTION_KEYS: Final = ("preset", *FIELD_GROUP)


def check_options(options: Mapping[str, Any]) -> dict[str, Any]:
    """A mapping of selector options (``preset`` and fields) checked: ``InputError`` whose
    ``problems`` name each bad key as ``(key, problem)``; else the options as a file holds them
    (JSON values: a set of corrections as a sorted list), in key order."""
    problems: list[tuple[str, str]] = []
    preset = options.get("preset")
    if preset is not None and (not isinstance(preset, str) or preset not in PRESET_VALUES):
        problems.append(("preset", f"unknown {short_repr(preset)}; choices: {', '.join(PRESETS)}"))
        preset = None
    fields = {k: v for k, v in options.items() if k != "preset"}
    for key in fields:
        if key not in FIELD_GROUP:
            near = difflib.get_close_matches(str(key), OPTION_KEYS, n=1)
            hint = f" (did you mean {near[0]!r}?)" if near else ""
            problems.append((str(key), UNKNOWN_OPTION + hint))
    groups: dict[str, dict[str, Any]] = {g: {} for g in GROUPS}
    for key, value in fields.items():
        if key in FIELD_GROUP:
            groups[FIELD_GROUP[key]][key] = value
    for group, values in groups.items():
        try:
            GROUPS[group].model_validate(values)
        except ValidationError as exc:
            problems += InputError.from_validation(group, exc).problems
    if problems:
        text = "; ".join(f"{k}: {m}" for k, m in problems)
        raise InputError(one_line(f"selector options: {text}"), problems)
    config = SelectorConfig.of(preset, **fields).flat()
    out: dict[str, Any] = {} if preset is None else {"preset": preset}
    for key in fields:
        value = config[key]
        out[key] = sorted(value) if isinstance(value, frozenset) else value
    return dict(sorted(out.items()))
