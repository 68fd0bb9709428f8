"""One adapter for every hand the validator drives: an MJCF file plus a joint map, or a
project hand (`models.hands`).

Either way the adapter yields a fresh `mujoco.MjSpec` of the hand alone with the project's
conventions: a mocap body "wrist_mocap", the hand root with a free joint "wrist_free", a weld
"wrist_weld" between them, and position actuators. The joints a grasp drives are named in grasp
order (`spec_joint_names`); actuator targets come from the actuator moment, so coupled joints
(ShadowHand's J1/J2 tendons) need nothing special.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import mujoco

from models.errors import HandError

MOCAP_BODY = "wrist_mocap"
FREE_JOINT = "wrist_free"
WELD = "wrist_weld"
MJCF_PREFIX = "hand/"
# MuJoCo's weld data as the XML parser leaves it: anchor 0, relpose from qpos0, torquescale 1.
WELD_DATA = [0.0] * 10 + [1.0, 0.0]


@dataclass(frozen=True)
class HandAdapter:
    """What the validator needs from a hand; picklable so process pools can rebuild it.

    `spec_factory()` returns a fresh MjSpec (see module docstring); `joint_names` is the grasp
    joint order and `spec_joint_names` the matching joint names inside the spec.
    """

    name: str
    joint_names: tuple[str, ...]
    spec_joint_names: tuple[str, ...]
    spec_factory: Callable[[], mujoco.MjSpec] = field(compare=False)
    key: tuple = ()

    @property
    def dof(self) -> int:
        return len(self.joint_names)


# ---------------------------------------------------------------------- MJCF hands
def _copy_options(src: mujoco.MjSpec, dst: mujoco.MjSpec) -> None:
    """Copy physics options so attaching does not warn about conflicts (overridden later)."""
    for attr in dir(src.option):
        if attr.startswith("_"):
            continue
        try:
            setattr(dst.option, attr, getattr(src.option, attr))
        except (AttributeError, TypeError):
            pass


def _absolute_asset_paths(child: mujoco.MjSpec, xml_path: Path) -> None:
    base = xml_path.parent
    meshdir = base / (child.meshdir or "")
    texdir = base / (child.texturedir or "")
    for mesh in child.meshes:
        if mesh.file and not os.path.isabs(mesh.file):
            mesh.file = str((meshdir / mesh.file).resolve())
    for tex in child.textures:
        if tex.file and not os.path.isabs(tex.file):
            tex.file = str((texdir / tex.file).resolve())
    child.meshdir = ""
    child.texturedir = ""


def _mjcf_spec(xml_path: str) -> mujoco.MjSpec:
    """The MJCF hand under a free-floating root welded to a mocap body (DexGraspBench's way)."""
    path = Path(xml_path)
    try:
        child = mujoco.MjSpec.from_file(str(path))
    except ValueError as err:
        raise HandError(f"{path}: cannot read MJCF hand: {err}") from None
    _absolute_asset_paths(child, path)
    spec = mujoco.MjSpec()
    _copy_options(child, spec)
    frame = spec.worldbody.add_frame()
    root = frame.attach_body(child.worldbody, MJCF_PREFIX, "")
    root.add_freejoint(name=FREE_JOINT)
    spec.worldbody.add_body(name=MOCAP_BODY, mocap=True)
    spec.add_equality(
        type=mujoco.mjtEq.mjEQ_WELD,
        name=WELD,
        name1=MOCAP_BODY,
        name2=root.name,
        objtype=mujoco.mjtObj.mjOBJ_BODY,
        data=WELD_DATA,
    )
    return spec


@functools.lru_cache(maxsize=16)
def mjcf_joint_names(xml_path: str) -> tuple[str, ...]:
    """The XML's hinge/slide joints in file order (DexGraspBench's qpos order)."""
    try:
        model = mujoco.MjModel.from_xml_path(str(xml_path))
    except ValueError as err:
        raise HandError(f"{xml_path}: cannot read MJCF hand: {err}") from None
    names = []
    for j in range(model.njnt):
        if int(model.jnt_type[j]) in (
            int(mujoco.mjtJoint.mjJNT_HINGE),
            int(mujoco.mjtJoint.mjJNT_SLIDE),
        ):
            names.append(model.joint(j).name)
    return tuple(names)


def mjcf_hand(
    xml_path: str | Path,
    joint_map: Mapping[str, str] | None = None,
    joint_names: Sequence[str] | None = None,
    name: str | None = None,
) -> HandAdapter:
    """An MJCF hand. `joint_names` is the grasp joint order (default: the XML's order);
    `joint_map` maps grasp joint names to XML joint names where they differ."""
    path = Path(xml_path).resolve()
    if not path.is_file():
        raise HandError(f"{xml_path}: no such MJCF file")
    xml_joints = mjcf_joint_names(str(path))
    joint_map = dict(joint_map or {})
    order = (
        tuple(joint_names)
        if joint_names is not None
        else tuple({v: k for k, v in joint_map.items()}.get(j, j) for j in xml_joints)
    )
    spec_names = []
    for joint in order:
        xml_joint = joint_map.get(joint, joint)
        if xml_joint not in xml_joints:
            raise HandError(
                f"joint {joint!r} (XML name {xml_joint!r}) is not a joint of {path.name}; "
                f"its joints are {list(xml_joints)}"
            )
        spec_names.append(MJCF_PREFIX + xml_joint)
    return HandAdapter(
        name=name or path.stem,
        joint_names=order,
        spec_joint_names=tuple(spec_names),
        spec_factory=functools.partial(_mjcf_spec, str(path)),
        key=("mjcf", str(path), tuple(sorted(joint_map.items())), order),
    )


# ---------------------------------------------------------------------- project hands
def _builtin_spec(name: str) -> mujoco.MjSpec:
    from models.hands import load_hand

    return load_hand(name).mujoco_spec()


def project_hand(hand: Any) -> HandAdapter:
    """A hand of `models.hands` (by name, or a loaded hand object)."""
    if isinstance(hand, str):
        try:
            from models.hands import load_hand
        except ImportError as err:
            raise HandError(f"project hands are unavailable ({err})") from None
        loaded = load_hand(hand)
        factory: Callable[[], mujoco.MjSpec] = functools.partial(_builtin_spec, hand)
        name = hand
    else:
        loaded = hand
        factory = hand.mujoco_spec
        name = str(getattr(hand, "name", type(hand).__name__))
    joints = tuple(loaded.joint_names)
    return HandAdapter(
        name=name,
        joint_names=joints,
        spec_joint_names=joints,
        spec_factory=factory,
        key=("builtin", name, joints),
    )


def as_hand(hand: Any) -> HandAdapter:
    """Resolve what users pass: an adapter, an .xml path, a built-in hand name or hand object."""
    if isinstance(hand, HandAdapter):
        return hand
    if isinstance(hand, Path) or (isinstance(hand, str) and hand.endswith(".xml")):
        return mjcf_hand(hand)
    if isinstance(hand, str) or hasattr(hand, "mujoco_spec"):
        return project_hand(hand)
    raise HandError(
        f"cannot use {hand!r} as a hand: give a built-in hand name, an MJCF path, "
        "a models.hands hand, or a HandAdapter"
    )
