"""The per-hand metadata file (`hand.json`): every hand-specific fact code needs.

Code never branches on a hand's name; it reads these fields. A user's hand is a URDF plus
this file; a missing, unknown or mistyped field is reported by name with what it must be.
"""

from __future__ import annotations

import difflib
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
    # Other squeeze depths validated in turn when a grasp slips at `squeeze_depth` (empty:
    # none). A deeper squeeze holds parts far from the centre of mass (pump heads, mug handles)
    # that turn in the fingers at the first squeeze; a shallower one holds thin handles that the
    # squeeze itself turns. Either for every grasp loses others; as retries they lose no pair
    # (docs/planner_log.md, "Squeeze retry", "A shallower squeeze retried").
    retry_squeeze_depths: tuple[float, ...]
    # Where the grasp program starts the fingers of a learned sample: the open pose closed this
    # fraction of each joint's range along its closing direction (HandModel.closed_pose; the
    # model-based proposals start at 0.35). From the open pose at a power grasp's wrist the hand
    # starts inside the part and the program pushes the wrist away (13-17 cm on Shadow's hammer
    # handles); LEAP's fingers, closed, start across each other. Measured per hand with the
    # dataset's wrist and anchors on the validation split (docs/learned_log.md, "Where the
    # solve starts"); default 0, the open pose.
    learned_start_closure: float
    source: str  # where the kinematics come from (for provenance and vendor checks)
    # Joints driven together by one actuator (empty: one position actuator per joint).
    couplings: tuple[Coupling, ...] = ()

    def fingertip(self, name: str) -> Fingertip:
        for tip in self.fingertips:
            if tip.name == name:
                return tip
        raise HandError(
            f"hand {self.name} has no fingertip {name!r}; its fingertips are "
            f"{[t.name for t in self.fingertips]}"
        )


# Optional fields and their defaults; anything else in hand.json is refused by name, so a typo
# ("pinch_proposal") is an error instead of a silently ignored setting.
OPTIONAL_FIELDS = (
    "pinch_proposals",
    "pregrasp_clearance",
    "squeeze_depth",
    "retry_squeeze_depths",
    "learned_start_closure",
    "couplings",
    "joint_dynamics",
    "program_hull_links",
    "palm_on_thin_parts",
    "source",
)
FINGERTIP_FIELDS = ("name", "link", "point", "radius")
ACTUATOR_FIELDS = ("kp", "kv", "force_range")
DYNAMICS_FIELDS = ("damping", "armature", "frictionloss")
# finger_axis lies in the palm plane: |cos| of its angle to the palm normal at most this
PALM_AXES_COS = 0.1


def _show(value) -> str:
    """A value as it appears in an error message: its repr on one line, cut short."""
    text = " ".join(repr(value).split())
    return text if len(text) <= 80 else text[:77] + "..."


def _kind(value) -> str:
    """The JSON name of a value's type, for messages."""
    for kinds, name in (
        (bool, "a boolean"),
        ((int, float), "a number"),
        (str, "a string"),
        (list, "a list"),
        (dict, "an object"),
    ):
        if isinstance(value, kinds):
            return name
    return "null" if value is None else type(value).__name__


def _finite_number(value) -> bool:
    """A JSON number (not a boolean, which Python counts as an int) that is finite."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and np.isfinite(value)


def _retry_depths(value, squeeze_depth: float, path: Path) -> tuple[float, ...]:
    """retry_squeeze_depths: distinct positive numbers, none the squeeze depth itself (the same
    squeeze validated again gives the same verdict)."""
    ok = isinstance(value, list) and all(_finite_number(v) and v > 0 for v in value)
    if not ok or len(set(value)) < len(value) or squeeze_depth in value:
        raise HandError(
            f"{path}: retry_squeeze_depths must be a list of distinct positive numbers other "
            f"than squeeze_depth ({squeeze_depth:g}), like [0.5, 2.0] (or [] for no retry), "
            f"got {_show(value)}"
        )
    return tuple(float(v) for v in value)


def _vec(value, field: str, path: Path) -> np.ndarray:
    if not (isinstance(value, list) and len(value) == 3 and all(map(_finite_number, value))):
        raise HandError(
            f"{path}: {field} must be 3 finite numbers like [0, 0, 1], got {_show(value)}"
        )
    return np.asarray(value, dtype=float)


def _direction(value, field: str, path: Path) -> np.ndarray:
    """A non-zero 3-vector, made unit."""
    arr = _vec(value, field, path)
    norm = np.linalg.norm(arr)
    if not norm > 1e-9:
        raise HandError(f"{path}: {field} must be a non-zero direction, got {_show(value)}")
    return arr / norm


def _number(value, field: str, path: Path, *, positive: bool = False) -> float:
    """A finite number, > 0 where `positive`, else >= 0."""
    if not _finite_number(value) or (value <= 0 if positive else value < 0):
        need = "a positive number" if positive else "a number, 0 or more"
        raise HandError(f"{path}: {field} must be {need}, got {_show(value)}")
    return float(value)


def _string(value, field: str, path: Path) -> str:
    if not isinstance(value, str) or not value.strip():
        raise HandError(f"{path}: {field} must be a non-empty string, got {_show(value)}")
    return value


def _strings(value, field: str, path: Path, *, unique: bool = True) -> tuple[str, ...]:
    """A list of non-empty strings (no repeats where `unique`)."""
    if not isinstance(value, list) or not all(isinstance(v, str) and v.strip() for v in value):
        raise HandError(
            f'{path}: {field} must be a list of names like ["a", "b"], got {_show(value)}'
        )
    repeated = sorted({v for v in value if value.count(v) > 1})
    if unique and repeated:
        raise HandError(f"{path}: {field} names {repeated} more than once")
    return tuple(value)


def _object(value, field: str, path: Path, known: tuple[str, ...], example: str) -> dict:
    """A JSON object whose keys are all in `known`."""
    if not isinstance(value, dict):
        raise HandError(f"{path}: {field} must be an object like {example}, got {_show(value)}")
    _no_unknown(value, known, field, path)
    return value


def _no_unknown(raw: dict, known: tuple[str, ...], field: str, path: Path) -> None:
    """HandError naming the keys of `raw` not in `known` (at the top level of hand.json, keys
    starting with "_" are comments and allowed)."""
    unknown = [k for k in raw if k not in known and not (field == "" and k.startswith("_"))]
    if unknown:
        hints = []
        for key in unknown:
            close = difflib.get_close_matches(str(key), known, n=1)
            hints.append(f"{key!r}" + (f" (did you mean {close[0]!r}?)" if close else ""))
        where = "hand.json" if field == "" else field
        raise HandError(
            f"{path}: unknown field{'s' if len(unknown) > 1 else ''} in {where}: "
            f"{', '.join(hints)}; the fields are {', '.join(known)}"
            + (" (and comments: fields starting with _)" if field == "" else "")
        )


def _per_joint(value, field: str, joints: tuple[str, ...], path: Path, example: str) -> dict:
    """An object with a value for every joint of joint_order."""
    if not isinstance(value, dict):
        raise HandError(
            f"{path}: {field} must be an object with a value per joint of joint_order, like "
            f"{example}; got {_show(value)}"
        )
    absent = [j for j in joints if j not in value]
    if absent:
        raise HandError(f"{path}: {field} lacks joints {absent}")
    return value


def _read_json(path: Path):
    """hand.json's text parsed; HandError naming the file for every way that can fail."""
    try:
        data = path.read_bytes()
    except FileNotFoundError as err:
        raise HandError(
            f"hand metadata {path} not found: a hand folder needs hand.urdf and hand.json "
            f"with fields {', '.join(REQUIRED_FIELDS)}"
        ) from err
    except OSError as err:
        raise HandError(f"cannot read hand metadata {path}: {err.strerror or err}") from err
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        raise HandError(
            f"hand metadata {path} is not UTF-8 text (byte {err.start}): save it as UTF-8 JSON"
        ) from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as err:
        raise HandError(f"hand metadata {path} is not valid JSON: {err}") from None
    except RecursionError:
        raise HandError(f"hand metadata {path} nests too deeply to be a hand.json") from None


def read_meta(path: Path) -> HandMeta:
    """Read and check `hand.json`: every field of the right kind, every missing or unknown
    field named; raises HandError naming the file, the field and what it must be."""
    raw = _read_json(path)
    if not isinstance(raw, dict):
        raise HandError(
            f"hand metadata {path} must be a JSON object {{...}} with fields "
            f"{', '.join(REQUIRED_FIELDS)}; it holds {_kind(raw)}"
        )
    missing = [f for f in REQUIRED_FIELDS if f not in raw]
    palm = raw.get("palm", {})
    if isinstance(palm, dict):
        missing += [f"palm.{f}" for f in PALM_FIELDS if f not in palm]
    act = raw.get("actuator", {})
    if "actuator" in raw and isinstance(act, dict) and "kp" not in act:
        missing.append("actuator.kp")
    if missing:
        raise HandError(f"hand metadata {path} is missing fields: {', '.join(missing)}")
    _no_unknown(raw, REQUIRED_FIELDS + OPTIONAL_FIELDS, "", path)
    name = _string(raw["name"], "name", path)
    urdf = _string(raw["urdf"], 'urdf (the URDF file\'s name, like "hand.urdf")', path)
    joints = _strings(raw["joint_order"], "joint_order", path)
    if not joints:
        raise HandError(f"{path}: joint_order must list the hand's revolute joints; it is empty")
    tips = _fingertips(raw["fingertips"], path)
    names = [t.name for t in tips]
    anchors = raw["anchor_fingers"]
    if (
        not isinstance(anchors, list)
        or len(anchors) != 4
        or not all(isinstance(a, str) and a in names for a in anchors)
        or len(set(anchors)) != 4
    ):
        raise HandError(
            f"{path}: anchor_fingers must name 4 different fingertips of {names}, thumb first; "
            f"got {_show(anchors)}"
        )
    pinches = raw.get("pinch_proposals", 0)
    if not isinstance(pinches, int) or isinstance(pinches, bool) or pinches < 0:
        raise HandError(
            f"{path}: pinch_proposals must be a whole number, 0 or more; got {pinches!r}"
        )
    open_pose = _per_joint(raw["open_pose"], "open_pose", joints, path, '{"j1": 0.0, ...}')
    bad = [j for j in joints if not _finite_number(open_pose[j])]
    if bad:
        raise HandError(
            f"{path}: open_pose must give every joint a finite angle (rad); not for {bad}: "
            f"{_show([open_pose[j] for j in bad])}"
        )
    closing = _per_joint(
        raw["closing_direction"], "closing_direction", joints, path, '{"j1": 1, "j2": 0, ...}'
    )
    bad = [j for j in joints if not _finite_number(closing[j]) or closing[j] not in (-1, 0, 1)]
    if bad:
        raise HandError(
            f"{path}: closing_direction must be 1 (increasing q closes), -1 (decreasing q "
            f"closes) or 0 (spreads) for every joint; not for {bad}: "
            f"{_show([closing[j] for j in bad])}"
        )
    palm = _object(raw["palm"], "palm", path, PALM_FIELDS, '{"center": [...], "normal": ...}')
    palm = Palm(
        _vec(palm["center"], "palm.center", path),
        _direction(palm["normal"], "palm.normal", path),
        _direction(palm["finger_axis"], "palm.finger_axis", path),
    )
    if abs(float(palm.normal @ palm.finger_axis)) > PALM_AXES_COS:
        raise HandError(
            f"{path}: palm.finger_axis must lie in the palm plane, perpendicular to "
            f"palm.normal; they are {np.degrees(np.arccos(palm.normal @ palm.finger_axis)):.0f} "
            "deg apart"
        )
    act = _object(raw["actuator"], "actuator", path, ACTUATOR_FIELDS, '{"kp": 5.0, "kv": 0.0}')
    dynamics = _object(
        raw.get("joint_dynamics", {}),
        "joint_dynamics",
        path,
        DYNAMICS_FIELDS,
        '{"damping": 0.1, "armature": 0.0, "frictionloss": 0.0}',
    )
    pairs = raw["ignore_collision_pairs"]
    if not isinstance(pairs, list) or not all(
        isinstance(p, list) and len(p) == 2 and all(isinstance(n, str) for n in p) for p in pairs
    ):
        raise HandError(
            f"{path}: ignore_collision_pairs must be a list of link name pairs like "
            f'[["palm", "th_base"]], got {_show(pairs)}'
        )
    hull_links = _strings(raw.get("program_hull_links", []), "program_hull_links", path)
    thin = raw.get("palm_on_thin_parts", True)
    if not isinstance(thin, bool):
        raise HandError(f"{path}: palm_on_thin_parts must be true or false, got {_show(thin)}")
    source = raw.get("source", "")
    if not isinstance(source, str):
        raise HandError(f"{path}: source must be a string, got {_show(source)}")
    closing_motion = {}
    for field, default in (("pregrasp_clearance", 0.01), ("squeeze_depth", 1.0)):
        value = raw.get(field, default)
        if not _finite_number(value) or value <= 0:
            raise HandError(f"{path}: {field} must be a positive number, got {value!r}")
        closing_motion[field] = float(value)
    retry = _retry_depths(
        raw.get("retry_squeeze_depths", []), closing_motion["squeeze_depth"], path
    )
    start = raw.get("learned_start_closure", 0.0)
    if not _finite_number(start) or not 0 <= start < 1:
        raise HandError(
            f"{path}: learned_start_closure must be a number from 0 (the open pose) up to, not "
            f"including, 1 (every joint at its closing limit), got {start!r}"
        )
    couplings = _couplings(raw.get("couplings", []), joints, open_pose, path)
    return HandMeta(
        name=name,
        urdf=urdf,
        joint_order=joints,
        fingertips=tips,
        anchor_fingers=tuple(anchors),
        open_pose={j: float(open_pose[j]) for j in joints},
        closing_direction={j: int(closing[j]) for j in joints},
        palm=palm,
        kp=_number(act["kp"], "actuator.kp", path, positive=True),
        kv=_number(act.get("kv", 0.0), "actuator.kv", path),
        force_range=_number(act.get("force_range", 0.0), "actuator.force_range", path),
        ignore_collision_pairs=tuple(tuple(p) for p in pairs),
        joint_damping=_number(dynamics.get("damping", 0.0), "joint_dynamics.damping", path),
        joint_armature=_number(dynamics.get("armature", 0.0), "joint_dynamics.armature", path),
        joint_frictionloss=_number(
            dynamics.get("frictionloss", 0.0), "joint_dynamics.frictionloss", path
        ),
        program_hull_links=hull_links,
        palm_on_thin_parts=thin,
        pinch_proposals=pinches,
        **closing_motion,
        retry_squeeze_depths=retry,
        learned_start_closure=float(start),
        source=source,
        couplings=couplings,
    )


def _fingertips(raw, path: Path) -> tuple[Fingertip, ...]:
    example = '[{"name": "th", "link": "th_tip", "point": [0, 0, 0.04], "radius": 0.012}, ...]'
    if not isinstance(raw, list) or not raw:
        raise HandError(f"{path}: fingertips must be a list like {example}, got {_show(raw)}")
    tips = []
    for i, entry in enumerate(raw):
        field = f"fingertips[{i}]"
        if not isinstance(entry, dict):
            raise HandError(
                f"{path}: {field} must be an object with {', '.join(FINGERTIP_FIELDS)}, like "
                f"{example}; got {_show(entry)}"
            )
        absent = [f for f in FINGERTIP_FIELDS if f not in entry]
        if absent:
            raise HandError(f"{path}: {field} lacks {', '.join(absent)}; e.g. {example}")
        _no_unknown(entry, FINGERTIP_FIELDS, field, path)
        tips.append(
            Fingertip(
                _string(entry["name"], f"{field}.name", path),
                _string(entry["link"], f"{field}.link", path),
                _vec(entry["point"], f"{field}.point (in the link frame, m)", path),
                _number(entry["radius"], f"{field}.radius (m)", path, positive=True),
            )
        )
    names = [t.name for t in tips]
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise HandError(f"{path}: fingertips name {repeated} more than once")
    return tuple(tips)


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
        _string(entry["name"], f"couplings[{i}].name", path)
        _no_unknown(entry, ("name", "joints", "tendon", "plan_ratio"), f"couplings[{i}]", path)
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
