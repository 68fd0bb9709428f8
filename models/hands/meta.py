"""The per-hand metadata file (`hand.json`): every hand-specific fact code needs.

Code never branches on a hand's name; it reads these fields. A user's hand is a URDF plus
this file, and a missing field is reported by name.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from models.errors import HandError

REQUIRED_FIELDS = (
    "name",
    "urdf",
    "joint_order",
    "fingertips",
    "anchor_fingers",
    "open_pose",
    "closing_direction",
    "palm",
    "actuator",
    "ignore_collision_pairs",
)
PALM_FIELDS = ("center", "normal", "finger_axis")


@dataclass(frozen=True)
class Fingertip:
    """A fingertip: the sphere centre at the tip of `link` (link frame) and its radius."""

    name: str
    link: str
    point: np.ndarray
    radius: float


@dataclass(frozen=True)
class Palm:
    """Palm frame in the root link: centre on the palm surface, outward normal (the approach
    direction is -normal: the hand moves along its normal's opposite onto the object), and
    the direction the straight fingers point."""

    center: np.ndarray
    normal: np.ndarray
    finger_axis: np.ndarray


@dataclass(frozen=True)
class Coupling:
    """Joints the maker drives together, e.g. ShadowHand's J1 and J2 of a finger, pulled by one
    tendon. In simulation one position actuator drives the fixed tendon sum(tendon_i x q_i);
    the planner keeps the joints in the fixed ratio q_i / plan_ratio_i (BODex plans J1 = J2),
    so it never asks for a configuration the one actuator cannot hold."""

    name: str
    joints: tuple[str, ...]
    tendon: np.ndarray  # coefficient of each joint in the tendon length
    plan_ratio: np.ndarray  # the planner keeps q_i proportional to these


@dataclass(frozen=True)
class HandMeta:
    name: str
    urdf: str
    joint_order: tuple[str, ...]
    fingertips: tuple[Fingertip, ...]
    anchor_fingers: tuple[str, ...]  # K = 4 fingertip names, thumb first
    open_pose: dict[str, float]
    closing_direction: dict[str, int]  # +1 / -1: increasing q closes; 0: spreads (abduction)
    palm: Palm
    kp: float
    kv: float
    force_range: float
    ignore_collision_pairs: tuple[tuple[str, str], ...]
    joint_damping: float  # simulation joint dynamics (vendor values; URDF cannot hold armature)
    joint_armature: float
    joint_frictionloss: float
    # Links whose several boxes the grasp program merges into one convex hull (a bounding,
    # so still conservative, shape): fewer collision pairs, faster solves. MuJoCo keeps the boxes.
    program_hull_links: tuple[str, ...]
    # Whether the planner may pull the palm onto a part thinner than a fingertip (pens). Allegro's
    # long fingers cannot then keep the thumb opposite the fingers, and the pen rolls out.
    palm_on_thin_parts: bool
    # Pinch proposals (thumb and the next two anchor fingers on the part, the last one free)
    # solved after the regular ones. LEAP's wide fingertips cannot all fit on small parts (pump
    # heads, triggers, blades): 8 of them raise its grasps held on the part 94 -> 96% on train
    # and 95 -> 97% on val (docs/planner_log.md, "Pinch proposals").
    pinch_proposals: int
    # How the fingers close in validation: the anchor fingertips back off `pregrasp_clearance`
    # (m, mean) at the pregrasp, and squeeze = grasp + squeeze_depth x (grasp - pregrasp).
    # BODex's 1 cm and 1 by default; Allegro closes from 5 mm to twice that past the contact,
    # the same squeeze target with half the travel (docs/planner_log.md, "Allegro's shorter
    # closing").
    pregrasp_clearance: float
    squeeze_depth: float
    # A second, deeper squeeze validated when a grasp slips at `squeeze_depth` (None: none).
    # The built-in hands retry at twice their depth, a squeeze target 2 cm past the contact: on
    # all-validated records it held parts far from the centre of mass (pump heads, mug handles)
    # that turn in the fingers at the first squeeze, and lost no pair, where the deeper squeeze
    # for every grasp loses others (docs/planner_log.md, "Squeeze retry").
    retry_squeeze_depth: float | None
    source: str  # where the kinematics come from (for provenance and vendor checks)
    # Joints driven together by one actuator (empty: one position actuator per joint).
    couplings: tuple[Coupling, ...] = ()

    def fingertip(self, name: str) -> Fingertip:
        for tip in self.fingertips:
            if tip.name == name:
                return tip
        raise HandError(f"hand {self.name} has no fingertip {name!r}")


def _vec(value, field: str, path: Path) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise HandError(f"{path}: {field} must be 3 finite numbers, got {value!r}")
    return arr


def _finite_number(value) -> bool:
    """A JSON number (not a boolean, which Python counts as an int) that is finite."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and np.isfinite(value)


def read_meta(path: Path) -> HandMeta:
    """Read and check `hand.json`; raises HandError naming every missing field."""
    try:
        raw = json.loads(path.read_text())
    except FileNotFoundError as err:
        raise HandError(
            f"hand metadata {path} not found: a hand folder needs hand.urdf and hand.json "
            f"with fields {', '.join(REQUIRED_FIELDS)}"
        ) from err
    except json.JSONDecodeError as err:
        raise HandError(f"hand metadata {path} is not valid JSON: {err}") from err
    missing = [f for f in REQUIRED_FIELDS if f not in raw]
    missing += [f"palm.{f}" for f in PALM_FIELDS if f not in raw.get("palm", {})]
    if "actuator" in raw and "kp" not in raw["actuator"]:
        missing.append("actuator.kp")
    if missing:
        raise HandError(f"hand metadata {path} is missing fields: {', '.join(missing)}")
    tips = tuple(
        Fingertip(
            t["name"], t["link"], _vec(t["point"], f"fingertip {t['name']}", path), t["radius"]
        )
        for t in raw["fingertips"]
    )
    names = {t.name for t in tips}
    pinches = raw.get("pinch_proposals", 0)
    if not isinstance(pinches, int) or isinstance(pinches, bool) or pinches < 0:
        raise HandError(
            f"{path}: pinch_proposals must be a whole number, 0 or more; got {pinches!r}"
        )
    unknown = [f for f in raw["anchor_fingers"] if f not in names]
    if unknown or len(raw["anchor_fingers"]) != 4:
        raise HandError(
            f"{path}: anchor_fingers must name 4 of the fingertips {sorted(names)}; "
            f"got {raw['anchor_fingers']}"
        )
    joints = tuple(raw["joint_order"])
    for field in ("open_pose", "closing_direction"):
        absent = [j for j in joints if j not in raw[field]]
        if absent:
            raise HandError(f"{path}: {field} lacks joints {absent}")
    palm = raw["palm"]
    act = raw["actuator"]
    closing = {}
    for field, default in (("pregrasp_clearance", 0.01), ("squeeze_depth", 1.0)):
        value = raw.get(field, default)
        if not _finite_number(value) or value <= 0:
            raise HandError(f"{path}: {field} must be a positive number, got {value!r}")
        closing[field] = float(value)
    retry = raw.get("retry_squeeze_depth")
    if retry is not None:
        if not _finite_number(retry) or retry <= closing["squeeze_depth"]:
            raise HandError(
                f"{path}: retry_squeeze_depth must be null or a number above squeeze_depth "
                f"({closing['squeeze_depth']}), got {retry!r}"
            )
        retry = float(retry)
    couplings = _couplings(raw.get("couplings", []), joints, raw["open_pose"], path)
    return HandMeta(
        name=raw["name"],
        urdf=raw["urdf"],
        joint_order=joints,
        fingertips=tips,
        anchor_fingers=tuple(raw["anchor_fingers"]),
        open_pose={j: float(raw["open_pose"][j]) for j in joints},
        closing_direction={j: int(raw["closing_direction"][j]) for j in joints},
        palm=Palm(
            _vec(palm["center"], "palm.center", path),
            _vec(palm["normal"], "palm.normal", path) / np.linalg.norm(palm["normal"]),
            _vec(palm["finger_axis"], "palm.finger_axis", path)
            / np.linalg.norm(palm["finger_axis"]),
        ),
        kp=float(act["kp"]),
        kv=float(act.get("kv", 0.0)),
        force_range=float(act.get("force_range", 0.0)),
        ignore_collision_pairs=tuple(tuple(p) for p in raw["ignore_collision_pairs"]),
        joint_damping=float(raw.get("joint_dynamics", {}).get("damping", 0.0)),
        joint_armature=float(raw.get("joint_dynamics", {}).get("armature", 0.0)),
        joint_frictionloss=float(raw.get("joint_dynamics", {}).get("frictionloss", 0.0)),
        program_hull_links=tuple(raw.get("program_hull_links", ())),
        palm_on_thin_parts=bool(raw.get("palm_on_thin_parts", True)),
        pinch_proposals=pinches,
        **closing,
        retry_squeeze_depth=retry,
        source=raw.get("source", ""),
        couplings=couplings,
    )


def _couplings(raw, joints: tuple[str, ...], open_pose, path: Path) -> tuple[Coupling, ...]:
    """Check the `couplings` field: each names 2+ distinct joints of the hand (no joint in two
    couplings), with one finite tendon coefficient and one non-zero plan ratio per joint, and
    the open pose must keep the plan ratio (the planner starts from it)."""
    example = (
        '[{"name": "FFJ0", "joints": ["FFJ2", "FFJ1"], "tendon": [1, 1], "plan_ratio": [1, 1]}]'
    )
    if not isinstance(raw, list):
        raise HandError(f"{path}: couplings must be a list like {example}; got {raw!r}")
    out, seen = [], set()
    for i, entry in enumerate(raw):
        if not isinstance(entry, dict) or not {"name", "joints", "tendon"} <= set(entry):
            raise HandError(
                f"{path}: couplings[{i}] must be an object with name, joints, tendon "
                f"(and optional plan_ratio), like {example}; got {entry!r}"
            )
        names = entry["joints"]
        if (
            not isinstance(names, list)
            or len(names) < 2
            or not all(isinstance(n, str) for n in names)
        ):
            raise HandError(f"{path}: couplings[{i}].joints must list 2 or more joint names")
        unknown = [n for n in names if n not in joints]
        if unknown:
            raise HandError(f"{path}: couplings[{i}] names joints not in joint_order: {unknown}")
        repeated = [n for n in names if n in seen] + [n for n in set(names) if names.count(n) > 1]
        if repeated:
            raise HandError(f"{path}: joints {sorted(set(repeated))} are in two couplings")
        seen.update(names)
        ratio_raw = entry.get("plan_ratio", entry["tendon"])
        arrays = {}
        for field, value in (("tendon", entry["tendon"]), ("plan_ratio", ratio_raw)):
            if not isinstance(value, list) or not all(_finite_number(v) for v in value):
                raise HandError(f"{path}: couplings[{i}].{field} must be a list of numbers")
            if len(value) != len(names):
                raise HandError(
                    f"{path}: couplings[{i}].{field} has {len(value)} values for "
                    f"{len(names)} joints"
                )
            arrays[field] = np.asarray(value, dtype=float)
        if np.any(arrays["plan_ratio"] == 0) or not np.any(arrays["tendon"] != 0):
            raise HandError(
                f"{path}: couplings[{i}] needs non-zero plan_ratio values and a non-zero tendon"
            )
        opened = np.array([float(open_pose[n]) for n in names]) / arrays["plan_ratio"]
        if np.ptp(opened) > 1e-9:
            raise HandError(
                f"{path}: open_pose breaks couplings[{i}] ({entry['name']}): its joints "
                f"{names} must be in the ratio {ratio_raw}"
            )
        out.append(Coupling(str(entry["name"]), tuple(names), **arrays))
    return tuple(out)
