"""The simulated grasp test, as settings: DexGraspBench's protocol and the paper's variant.

Every number here is a fact read from DexGraspBench's evaluator (see
../shared/reference/dexgraspbench/README.md); `get_protocol(name, **overrides)` changes any of
them, so experiments never need to edit code.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from models.errors import DrograspError

#: World directions of the external force, in DexGraspBench's order.
DIRECTIONS: tuple[tuple[float, float, float], ...] = (
    (-1.0, 0.0, 0.0),
    (1.0, 0.0, 0.0),
    (0.0, -1.0, 0.0),
    (0.0, 1.0, 0.0),
    (0.0, 0.0, -1.0),
    (0.0, 0.0, 1.0),
)


class ProtocolError(DrograspError, ValueError):
    """Unknown preset or an invalid protocol setting."""


# simulation steps of one phase (the closing, or one direction's hold): 500 for DexGraspBench's
# 2 s hold; the bound keeps a mistyped setting from running for hours
MAX_STEPS = 100_000


def _numbers(name: str, value: Any, size: int, low: float | None) -> tuple[float, ...]:
    """`value` as `size` finite numbers (each >= `low`), or a ProtocolError."""
    if not isinstance(value, tuple | list) or len(value) != size:
        raise ProtocolError(f"protocol {name} needs {size} numbers, got {value!r}")
    for x in value:
        if isinstance(x, bool) or not isinstance(x, int | float) or not math.isfinite(x):
            raise ProtocolError(f"protocol {name} needs {size} finite numbers, got {value!r}")
        if low is not None and x < low:
            raise ProtocolError(f"protocol {name} values must be {low} or more, got {value!r}")
    return tuple(float(x) for x in value)


@dataclass(frozen=True)
class Protocol:
    """Settings of the MuJoCo grasp test (defaults: DexGraspBench's evaluator)."""

    # Physics options.
    timestep: float = 0.004
    integrator: str = "implicitfast"
    solver: str = "newton"
    cone: str = "elliptic"
    impratio: float = 10.0
    noslip_iterations: int = 2
    gravity: bool = False
    # Contact parameters: every geom, and the hand's geoms (stiff contacts, little penetration).
    condim: int = 4
    friction: tuple[float, float] = (0.6, 0.02)
    hand_solimp: tuple[float, float, float] = (0.5, 0.99, 0.0001)
    hand_solref: tuple[float, float] = (0.005, 1.0)
    weld_solimp: tuple[float, float, float, float, float] = (0.9, 0.95, 0.001, 0.5, 2.0)
    # Object: mass set through density; its weight emulated by force_scale x mass along a direction.
    object_mass: float = 0.1
    force_scale: float = 10.0
    directions: tuple[tuple[float, float, float], ...] = DIRECTIONS
    # Motion: pregrasp -> grasp -> squeeze, each `waypoints` x `substeps` steps.
    waypoints: int = 10
    substeps: int = 10
    # Test: hold the force `hold_time` s, check every `check_interval` s.
    hold_time: float = 2.0
    check_interval: float = 0.2
    max_translation: float = 0.05  # m
    max_rotation_deg: float = 15.0
    max_pregrasp_penetration: float = 0.01  # m; deeper hand-object penetration fails at once
    # m; deeper hand-hand penetration at the pregrasp fails at once too: the deepest contact
    # MuJoCo generates between two hand geoms (its exclusions and parent-child filter apply)
    max_pregrasp_self_penetration: float = 0.01
    # Static metrics at the grasp (not part of the verdict).
    contact_margin: float = 0.01
    contact_threshold: float = 0.002
    # Speed, not physics: the constraint Jacobian's storage. MuJoCo's "auto" picks dense below 60
    # dofs; the same equations in sparse form skip the zeros of the hand's finger chains, which
    # makes the elliptic-cone Newton steps cheaper (verdicts unchanged on the reference grasps).
    jacobian: str = "sparse"
    # Speed: simulate the closing once and copy it per direction; stop at the first failure.
    share_closing: bool = True
    all_directions: bool = False
    # Speed: end a direction's hold early once the object has been at rest (speed below
    # rest_speed, spin below rest_speed / 0.1 m) and the fingers no longer closing, at every
    # rest check over `rest_window` s, and even moving at its current speed the object could not
    # leave the thresholds in the time left. Failure is still checked every `check_interval` as
    # the protocol says. Under kp 5 position control the fingers keep creeping into the object at
    # 0.05-0.2 rad/s long after it is held, so waiting for them to stop (0.02 rad/s) ran most
    # holds to the end. Agreement and speed of both rules: README, "Validation".
    # rest_speed 0 disables the early exit.
    rest_speed: float = 0.002  # m/s of the object
    rest_finger_speed: float = 0.2  # rad/s: fastest finger joint still counted as at rest
    rest_interval: float = 0.04  # s between rest checks
    rest_window: float = 0.24  # s the object must stay at rest

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):  # an override of the wrong kind fails here, loudly
            default, value = f.default, getattr(self, f.name)
            if isinstance(default, bool):
                ok = isinstance(value, bool)
            elif isinstance(default, int):
                ok = isinstance(value, int) and not isinstance(value, bool)
            elif isinstance(default, float):
                ok = isinstance(value, int | float) and not isinstance(value, bool)
                ok = ok and math.isfinite(value)
            elif isinstance(default, tuple):
                ok = isinstance(value, tuple)
            else:
                ok = isinstance(value, type(default))
            if not ok:
                finite = " (finite)" if isinstance(default, float) else ""
                raise ProtocolError(
                    f"protocol {f.name} must be a {type(default).__name__}{finite} like "
                    f"{default!r}, got {value!r}"
                )
        for name, size, low in (
            ("friction", 2, 0.0),
            ("hand_solimp", 3, None),
            ("hand_solref", 2, None),
            ("weld_solimp", 5, None),
        ):
            _numbers(name, getattr(self, name), size, low)
        if not self.directions:
            raise ProtocolError("protocol needs at least one force direction")
        for d in self.directions:
            vec = _numbers("directions", d, 3, None)
            if abs(math.hypot(*vec) - 1.0) > 1e-6:
                raise ProtocolError(
                    f"protocol force directions must be unit vectors such as (0, 0, -1), got {d}"
                )
        positive = (
            "timestep",
            "impratio",
            "object_mass",
            "hold_time",
            "check_interval",
            "rest_interval",
            "rest_window",
            "max_translation",
            "max_rotation_deg",
        )
        for name in positive:
            if not getattr(self, name) > 0:
                raise ProtocolError(f"protocol {name} must be positive, got {getattr(self, name)}")
        non_negative = (
            "force_scale",
            "contact_margin",
            "contact_threshold",
            "rest_speed",
            "rest_finger_speed",
            "noslip_iterations",
        )
        for name in non_negative:
            if getattr(self, name) < 0:
                raise ProtocolError(f"protocol {name} must be 0 or more, got {getattr(self, name)}")
        if self.waypoints < 1 or self.substeps < 1:
            raise ProtocolError("protocol waypoints and substeps must be at least 1")
        for name in ("check_interval", "rest_interval"):
            if getattr(self, name) < self.timestep:
                raise ProtocolError(
                    f"protocol {name} ({getattr(self, name)} s) must be at least one timestep "
                    f"({self.timestep} s)"
                )
        closing = 2 * self.waypoints * self.substeps
        holding = self.hold_time / self.timestep
        if closing > MAX_STEPS or holding > MAX_STEPS:
            raise ProtocolError(
                f"the protocol would simulate {max(closing, round(holding))} steps per phase "
                f"(closing: 2 x waypoints x substeps; hold: hold_time / timestep); at most "
                f"{MAX_STEPS} are allowed: lower waypoints, substeps or hold_time, or raise "
                "timestep"
            )
        if self.condim not in (1, 3, 4, 6):
            raise ProtocolError(f"protocol condim must be 1, 3, 4 or 6, got {self.condim}")
        if self.integrator not in ("euler", "implicit", "implicitfast", "rk4"):
            raise ProtocolError(f"unknown integrator {self.integrator!r}")
        if self.solver not in ("newton", "cg", "pgs"):
            raise ProtocolError(f"unknown solver {self.solver!r}")
        if self.cone not in ("elliptic", "pyramidal"):
            raise ProtocolError(f"unknown friction cone {self.cone!r}")
        if self.jacobian not in ("dense", "sparse", "auto"):
            raise ProtocolError(f"unknown jacobian {self.jacobian!r}")

    @property
    def steps_per_check(self) -> int:
        return max(1, round(self.check_interval / self.timestep))

    @property
    def steps_per_rest_check(self) -> int:
        return max(1, round(self.rest_interval / self.timestep))

    @property
    def rest_checks(self) -> int:
        """Consecutive rest checks that end a hold."""
        return max(1, round(self.rest_window / self.rest_interval))

    @property
    def checks(self) -> int:
        return max(1, round(self.hold_time / self.check_interval))

    def physics_key(self) -> tuple:
        """The settings baked into a compiled model (the cache key of a scene)."""
        return (
            self.timestep,
            self.integrator,
            self.solver,
            self.cone,
            self.jacobian,
            self.impratio,
            self.noslip_iterations,
            self.gravity,
            self.condim,
            self.friction,
            self.hand_solimp,
            self.hand_solref,
            self.weld_solimp,
            self.object_mass,
        )

    def replace(self, **overrides: Any) -> Protocol:
        unknown = set(overrides) - {f.name for f in dataclasses.fields(self)}
        if unknown:
            raise ProtocolError(
                f"unknown protocol settings {sorted(unknown)}; known: "
                f"{', '.join(f.name for f in dataclasses.fields(self))}"
            )
        return dataclasses.replace(self, **overrides)


PRESETS: dict[str, Protocol] = {
    "dexgraspbench": Protocol(),
    "paper": Protocol(hold_time=3.0),
}


def get_protocol(preset: str | Protocol = "dexgraspbench", **overrides: Any) -> Protocol:
    """A preset by name (or a Protocol), with any setting overridden."""
    if isinstance(preset, Protocol):
        base = preset
    else:
        if not isinstance(preset, str) or preset not in PRESETS:
            raise ProtocolError(f"unknown protocol preset {preset!r}; choose from {list(PRESETS)}")
        base = PRESETS[preset]
    return base.replace(**overrides) if overrides else base
