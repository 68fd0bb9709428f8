"""`plan_grasp`, the Python entry point, with every argument checked before the work.

`from planner import plan_grasp` gives this function: it refuses bad settings, hands, texts and
objects with a `DrograspError` (a zero approach step once divided by zero, a tiny one asked for
terabytes, `schedule.solve_batch=0` never ended), plans with `planner.functional`, and writes
the object reference into every returned grasp's metrics (`metrics["object"]`), so a grasp
planned from the API can be saved and viewed again (`drograsp view g.json`) like one from
`drograsp plan`.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

from models.errors import DrograspError, HandError, InstructionError

__all__ = ["check_settings", "plan_grasp"]


class SettingsError(DrograspError, ValueError):
    """A planner setting of the wrong kind or out of range."""


# (low, high) bounds of numeric settings per group of PlannerSettings; None: unbounded on that
# side. Integers must be int.
_RANGES: dict[str, dict[str, tuple[float | None, float | None]]] = {
    "schedule": {
        "max_candidates": (1, None),
        "solve_batch": (1, None),
        "gate_solves": (0, None),
        "sweep_after": (0, None),
        "contact_distance": (1e-6, None),
    },
    "proposals": {
        "max_proposals": (1, None),
        "approach_step_deg": (1.0, 360.0),  # below 1 degree: 720+ proposals per part, for nothing
        "approach_clearance": (0.0, None),
        "palm_margin": (0.0, None),
        "border_margin": (0.0, None),
        "span_factor": (1e-6, None),
        "pinch_proposals": (0, None),
    },
    "intent": {},
    "learned": {
        "samples": (1, None),
        "guidance": (0.0, None),
        "sample_steps": (1, None),
        "seed": (0, None),
    },
    "program": {
        "major_iterations": (1, None),
        "wrist_position_scale": (1e-6, None),
        "wrist_quaternion_scale": (1e-6, None),
        "anchor_tolerance": (0.0, None),
        "influence_distance": (0.0, None),
        "squeeze_depth": (0.0, None),
        "pregrasp_clearance": (0.0, None),
    },
}


def _check_fields(
    obj: Any, where: str, ranges: dict[str, tuple[float | None, float | None]]
) -> None:
    """Each field of a settings dataclass against its default's kind and its range."""
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        default = f.default
        if (
            default is dataclasses.MISSING
            or dataclasses.is_dataclass(value)
            or f.name == "protocol"
        ):
            continue
        name = f"{where}.{f.name}"
        if value is None:
            if default is None:
                continue
            raise SettingsError(f"{name} must be set, like its default {default!r}")
        flag = default is None and "bool" in str(f.type)
        if isinstance(default, bool) or flag or (default is None and isinstance(value, bool)):
            if not isinstance(value, bool):
                raise SettingsError(f"{name} must be True or False, got {value!r}")
            continue
        numeric = isinstance(default, int | float) or (default is None and f.name in ranges)
        if not numeric:
            if default is not None and not isinstance(value, type(default)):
                raise SettingsError(
                    f"{name} must be a {type(default).__name__} like {default!r}, got {value!r}"
                )
            continue
        integer = isinstance(default, int) or (
            default is None and "int" in str(f.type) and "float" not in str(f.type)
        )
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise SettingsError(f"{name} must be a number, got {value!r}")
        if integer and not isinstance(value, int):
            raise SettingsError(f"{name} must be a whole number, got {value!r}")
        if not math.isfinite(value):
            raise SettingsError(f"{name} must be finite, got {value!r}")
        low, high = ranges.get(f.name, (None, None))
        if (low is not None and value < low) or (high is not None and value > high):
            span = (
                f"between {low:g} and {high:g}"
                if low is not None and high is not None
                else f"at least {low:g}"
                if low is not None
                else f"at most {high:g}"
            )
            raise SettingsError(f"{name} must be {span}, got {value!r}")


def check_settings(settings: Any = None) -> Any:
    """`settings` (a `PlannerSettings`, or None for the defaults) checked: every field of the
    right kind, finite and in range, the validation protocol known. Returns the settings."""
    from planner.settings import GROUPS, PlannerSettings
    from planner.validation.protocol import Protocol, get_protocol

    if settings is None:
        return PlannerSettings()
    if not isinstance(settings, PlannerSettings):
        raise SettingsError(
            f"settings must be a planner.functional.PlannerSettings, got "
            f"{type(settings).__name__}; e.g. "
            "PlannerSettings(schedule=ScheduleSettings(max_candidates=4))"
        )
    _check_fields(settings, "settings", {"cloud_checks": (0, None)})
    if not isinstance(settings.protocol, str | Protocol):
        raise SettingsError(
            f"settings.protocol must be a preset name or a Protocol, got {settings.protocol!r}"
        )
    get_protocol(settings.protocol)
    for name, group in GROUPS.items():
        value = getattr(settings, name)
        if not isinstance(value, group):
            raise SettingsError(f"settings.{name} must be a {group.__name__}, got {value!r}")
        _check_fields(value, f"settings.{name}", _RANGES[name])
    return settings


def _hand(hand: Any) -> Any:
    from models.hands import HandModel, load_hand

    if isinstance(hand, HandModel):
        return hand
    if not isinstance(hand, str) or not hand.strip():
        raise HandError(
            f"hand must be a built-in hand name (allegro, leap, shadow), a hand folder or a "
            f"HandModel, got {hand!r}"
        )
    return load_hand(hand)


def plan_grasp(obj: Any, text: Any, hand: Any, settings: Any = None) -> Any:
    """Plan a functional grasp: `from planner import plan_grasp`.

    obj: an ObjectModel (e.g. models.objects.make_object("mug", 3)), a mesh/cloud file or an
    (N, 3) array in metres, part labels optional; text: any sentence ("grab the mug by its
    handle") or "[Intent] a [Object] by [Part]"; hand: name, hand folder or HandModel;
    settings: a PlannerSettings (`proposer`: "auto", "model" or "learned"). Returns a
    PlanResult whose grasps carry their object reference (`grasp.metrics["object"]`)."""
    from models.objects import ObjectModel, load_object
    from planner.functional import FunctionalPlanner
    from planner.objectref import object_ref

    settings = check_settings(settings)
    if not isinstance(text, str) or not text.strip():
        raise InstructionError('the instruction is empty; write e.g. "Use a mug by handle"')
    if not isinstance(obj, ObjectModel):
        obj = load_object(obj)
    # FunctionalPlanner.plan parses the text, or reads it with the learned stages, and
    # refuses an unlabelled object for the model-based proposer
    result = FunctionalPlanner(_hand(hand), settings).plan(obj, text)
    ref = object_ref(obj)
    for cand in result.candidates:
        if cand.grasp is not None:
            cand.grasp.metrics.setdefault("object", ref)
    if result.grasp is not None:
        result.grasp.metrics.setdefault("object", ref)
    return result
