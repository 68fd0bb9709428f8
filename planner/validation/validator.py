"""Does a grasp hold? DexGraspBench's test in MuJoCo, with the closing simulated once.

The closing (pregrasp -> grasp -> squeeze) runs with no external force, so its end state is the
same for every force direction: it is simulated once and copied (mj_copyData) into each
direction's test, which then holds the force and checks the object's displacement. The verdict
equals DexGraspBench's, which re-simulates the closing per direction.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from typing import Any

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from models.grasp import Grasp
from planner.validation.hands import HandAdapter, as_hand
from planner.validation.objects import CollisionObject, as_collision_object
from planner.validation.protocol import Protocol, get_protocol
from planner.validation.scene import Scene, get_scene

IDENTITY_POSE = np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0])


@dataclass
class DirectionResult:
    """The object's displacement at the end of one direction's hold (or at its failure)."""

    direction: tuple[float, float, float]
    translation: float  # m
    rotation_deg: float
    held: bool
    hold_time: float  # s simulated under the force
    unstable: bool = False  # MuJoCo reset the simulation (or it went non-finite): not held


@dataclass
class ValidationResult:
    """Verdict and measurements of one grasp."""

    success: bool
    # "held", "pregrasp_penetration", "pregrasp_self_penetration", "slipped", or "unstable":
    # the simulation went non-finite or MuJoCo reset it (a wrist 1e300 m away, say), so where
    # the object ended says nothing about the grasp
    reason: str
    directions: list[DirectionResult] = field(default_factory=list)
    translation: float = 0.0  # m, worst over the directions tested
    rotation_deg: float = 0.0  # worst over the directions tested
    pregrasp_penetration: float = 0.0  # m, deepest hand-object penetration at the pregrasp
    pregrasp_self_penetration: float = 0.0  # m, deepest hand-hand penetration at the pregrasp
    grasp_penetration: float = 0.0  # m, same at the grasp configuration
    contact_count: int = 0  # hand bodies within the contact threshold at the grasp
    object_mass: float = 0.0  # kg, as compiled
    simulated_time: float = 0.0  # s of physics simulated for this grasp
    wall_time: float = 0.0  # s
    # MuJoCo's warnings during the test, e.g. "Nan, Inf or huge value in QACC ... unstable":
    # MuJoCo then resets the simulation state, and the grasp fails as "unstable" (after a reset
    # the object sits where it started, which would otherwise read as held); recorded here
    # instead of printed on stderr and appended to a MUJOCO_LOG.TXT in the working folder.
    warnings: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["directions"] = [asdict(r) | {"direction": list(r.direction)} for r in self.directions]
        return d


# ---------------------------------------------------------------------- geometry helpers
def _pose(value: Any) -> np.ndarray:
    from models.errors import ObjectError

    try:
        pose = np.asarray(IDENTITY_POSE if value is None else value)
        ok = pose.dtype.kind in "iuf"
    except (TypeError, ValueError):
        ok = False
    if not ok or pose.shape != (7,) or not np.all(np.isfinite(pose)):
        raise ObjectError(f"object pose must be 7 finite numbers (xyz + wxyz), got {value!r}")
    pose = pose.astype(np.float64)
    norm = np.linalg.norm(pose[3:])
    if norm < 1e-8:
        raise ObjectError(f"object pose: zero quaternion in {value!r} (expected w, x, y, z)")
    pose[3:] /= norm
    return pose


_RESET_WARNINGS = (
    mujoco.mjtWarning.mjWARN_BADQPOS,
    mujoco.mjtWarning.mjWARN_BADQVEL,
    mujoco.mjtWarning.mjWARN_BADQACC,
)


def _unstable(scene: Scene, data: mujoco.MjData) -> bool:
    """MuJoCo reset the state (its checks found NaN, inf or huge values), or the object's
    state is not finite: the simulation says nothing about the grasp."""
    if any(data.warning[int(w)].number > 0 for w in _RESET_WARNINGS):
        return True
    q = scene.object_qpos
    return not bool(np.isfinite(data.qpos[q : q + 7]).all())


def _displacement(initial: np.ndarray, current: np.ndarray) -> tuple[float, float]:
    """Translation (m) and rotation angle (deg) between two xyz+wxyz poses."""
    translation = float(np.linalg.norm(current[:3] - initial[:3]))
    q0 = initial[3:] / np.linalg.norm(initial[3:])
    q1 = current[3:] / np.linalg.norm(current[3:])
    w = min(1.0, abs(float(np.dot(q0, q1))))  # |w| of q1 * q0^-1
    return translation, float(np.degrees(2.0 * np.arccos(w)))


def _interpolate(pose_a: np.ndarray, pose_b: np.ndarray, n: int) -> np.ndarray:
    """n wrist waypoints after pose_a up to pose_b: linear position, slerp rotation."""
    rots = Rotation.from_quat(np.stack([pose_a[3:], pose_b[3:]]), scalar_first=True)
    s = np.linspace(0.0, 1.0, n + 1)[1:]
    pos = pose_a[:3] + s[:, None] * (pose_b[:3] - pose_a[:3])
    quat = Slerp([0.0, 1.0], rots)(s).as_quat(scalar_first=True)
    return np.concatenate([pos, quat], axis=1)


# ---------------------------------------------------------------------- simulation steps
def _set_configuration(
    scene: Scene, data: mujoco.MjData, wrist: np.ndarray, joints: np.ndarray, obj_pose: np.ndarray
) -> None:
    """Reset `data` to a static configuration with the mocap at the wrist."""
    mujoco.mj_resetData(scene.model, data)
    data.qpos[scene.wrist_qpos : scene.wrist_qpos + 7] = wrist
    data.qpos[scene.joint_qpos] = joints
    data.qpos[scene.object_qpos : scene.object_qpos + 7] = obj_pose
    data.mocap_pos[scene.mocap] = wrist[:3]
    data.mocap_quat[scene.mocap] = wrist[3:]


def _hand_object_contacts(scene: Scene, data: mujoco.MjData) -> tuple[list[float], list[int]]:
    """Distances of hand-object contacts and the hand body of each."""
    m = scene.model
    dists, bodies = [], []
    for i in range(data.ncon):
        c = data.contact[i]
        b1, b2 = int(m.geom_bodyid[c.geom1]), int(m.geom_bodyid[c.geom2])
        if b2 == scene.object_body and scene.hand_body[b1]:
            dists.append(float(c.dist))
            bodies.append(b1)
        elif b1 == scene.object_body and scene.hand_body[b2]:
            dists.append(float(c.dist))
            bodies.append(b2)
    return dists, bodies


def _self_penetration(scene: Scene, data: mujoco.MjData) -> float:
    """Deepest penetration (m, >= 0) of the contacts MuJoCo generated between two hand geoms.

    DexGraspBench's measure: data.contact after mj_forward, so the model's contype/conaffinity,
    <exclude> pairs and parent-child filter decide which pairs count.
    """
    m = scene.model
    deepest = 0.0
    for i in range(data.ncon):
        c = data.contact[i]
        if scene.hand_body[m.geom_bodyid[c.geom1]] and scene.hand_body[m.geom_bodyid[c.geom2]]:
            deepest = max(deepest, -float(c.dist))
    return deepest


def _grasp_contacts(
    scene: Scene, grasp: Grasp, obj_pose: np.ndarray, protocol: Protocol
) -> tuple[float, int]:
    """Penetration and contact count at the static grasp, with a wider object margin."""
    m, d = scene.model, scene.scratch
    saved_margin = m.geom_margin[scene.object_geoms].copy()
    saved_gap = m.geom_gap[scene.object_geoms].copy()
    try:
        m.geom_margin[scene.object_geoms] = protocol.contact_margin
        m.geom_gap[scene.object_geoms] = protocol.contact_margin
        _set_configuration(scene, d, grasp.wrist_pose("grasp"), grasp.grasp, obj_pose)
        mujoco.mj_forward(m, d)
        dists, bodies = _hand_object_contacts(scene, d)
    finally:
        m.geom_margin[scene.object_geoms] = saved_margin
        m.geom_gap[scene.object_geoms] = saved_gap
    touching = {
        b for dist, b in zip(dists, bodies, strict=True) if abs(dist) < protocol.contact_threshold
    }
    return max(0.0, -min(dists, default=0.0)), len(touching)


def _ctrl_map(scene: Scene, data: mujoco.MjData) -> np.ndarray:
    """ctrl = moment x joint targets: maps grasp joints to actuator targets (tendons included)."""
    m = scene.model
    moment = np.zeros((m.nu, m.nv))
    mujoco.mju_sparse2dense(
        moment, data.actuator_moment, data.moment_rownnz, data.moment_rowadr, data.moment_colind
    )
    return moment[:, scene.joint_dof]


def _move(
    scene: Scene,
    data: mujoco.MjData,
    wrists: tuple[np.ndarray, np.ndarray],
    ctrls: tuple[np.ndarray, np.ndarray],
    protocol: Protocol,
) -> None:
    """Drive mocap and actuator targets from one configuration to the next in waypoints.

    No mj_forward after setting the targets: mj_step runs it first (same result, bit for bit).
    """
    m, n = scene.model, protocol.waypoints
    poses = _interpolate(wrists[0], wrists[1], n)
    targets = np.linspace(ctrls[0], ctrls[1], n + 1)[1:]
    for k in range(n):
        data.mocap_pos[scene.mocap] = poses[k, :3]
        data.mocap_quat[scene.mocap] = poses[k, 3:]
        data.ctrl[:] = targets[k]
        mujoco.mj_step(m, data, nstep=protocol.substeps)


def _close(
    scene: Scene, data: mujoco.MjData, grasp: Grasp, obj_pose: np.ndarray, protocol: Protocol
) -> float:
    """Reset to the pregrasp and run pregrasp -> grasp -> squeeze; returns simulated seconds."""
    wrists = [grasp.wrist_pose(p) for p in ("pregrasp", "grasp", "squeeze")]
    _set_configuration(scene, data, wrists[0], grasp.pregrasp, obj_pose)
    mujoco.mj_forward(scene.model, data)
    cmap = _ctrl_map(scene, data)
    ctrls = [cmap @ grasp.pregrasp, cmap @ grasp.grasp, cmap @ grasp.squeeze]
    data.ctrl[:] = ctrls[0]
    _move(scene, data, (wrists[0], wrists[1]), (ctrls[0], ctrls[1]), protocol)
    _move(scene, data, (wrists[1], wrists[2]), (ctrls[1], ctrls[2]), protocol)
    return 2 * protocol.waypoints * protocol.substeps * protocol.timestep


def _hold(
    scene: Scene,
    data: mujoco.MjData,
    direction: np.ndarray,
    obj_pose: np.ndarray,
    protocol: Protocol,
) -> DirectionResult:
    """Apply the force along `direction`; check the displacement every `check_interval` (the
    protocol's verdict) and, in between, whether the object has come to rest (early exit)."""
    m = scene.model
    data.xfrc_applied[:] = 0.0
    data.xfrc_applied[scene.object_body, :3] = (
        protocol.force_scale * protocol.object_mass * direction
    )
    q = scene.object_qpos
    per_check, per_rest = protocol.steps_per_check, protocol.steps_per_rest_check
    chunk = math.gcd(per_check, per_rest)
    total = protocol.checks * per_check
    translation = rotation = 0.0
    held = True
    steps = at_rest = 0
    unstable = False
    while steps < total:
        mujoco.mj_step(m, data, nstep=chunk)
        steps += chunk
        if _unstable(scene, data):
            unstable, held = True, False
            break
        check = steps % per_check == 0
        rest_check = protocol.rest_speed > 0 and steps % per_rest == 0
        if not (check or rest_check):
            continue
        translation, rotation = _displacement(obj_pose, data.qpos[q : q + 7])
        if check and not (
            translation < protocol.max_translation and rotation < protocol.max_rotation_deg
        ):
            held = False
            break
        if rest_check:
            left = protocol.hold_time - steps * protocol.timestep
            at_rest = (
                at_rest + 1 if _resting(scene, data, translation, rotation, left, protocol) else 0
            )
            if at_rest >= protocol.rest_checks:
                break
    return DirectionResult(
        tuple(float(x) for x in direction),
        translation,
        rotation,
        held,
        steps * protocol.timestep,
        unstable,
    )


def _resting(
    scene: Scene,
    data: mujoco.MjData,
    translation: float,
    rotation: float,
    left: float,
    protocol: Protocol,
) -> bool:
    """Object slower than rest_speed, fingers no longer closing, and even at its current
    speed the object could not leave the thresholds in the `left` s of the hold."""
    dof = scene.object_dof
    speed = float(np.linalg.norm(data.qvel[dof : dof + 3]))
    spin = float(np.linalg.norm(data.qvel[dof + 3 : dof + 6]))
    fingers = float(np.abs(data.qvel[scene.joint_dof]).max(initial=0.0))
    if max(speed, spin * 0.1) >= protocol.rest_speed or fingers >= protocol.rest_finger_speed:
        return False
    return (
        translation + speed * left < 0.9 * protocol.max_translation
        and rotation + np.degrees(spin) * left < 0.9 * protocol.max_rotation_deg
    )


# ---------------------------------------------------------------------- public API
@contextmanager
def _mujoco_warnings(into: list[str]) -> Iterator[None]:
    """Collect MuJoCo's warnings into `into` (each message once), restoring the handler after."""
    previous = mujoco.get_mju_user_warning()

    def keep(message: str) -> None:
        text = message.split(" Time =")[0].strip()
        if text not in into:
            into.append(text)

    mujoco.set_mju_user_warning(keep)
    try:
        yield
    finally:
        mujoco.set_mju_user_warning(previous)


def validate(
    grasp: Grasp,
    obj: Any,
    hand: Any,
    protocol: str | Protocol = "dexgraspbench",
    *,
    object_pose: Any = None,
    all_directions: bool | None = None,
) -> ValidationResult:
    """Simulate `grasp` on `obj` (collision pieces, see objects.as_collision_object) with
    `hand` (name, MJCF path or HandAdapter) and return the verdict with its measurements.

    `object_pose` (xyz + wxyz, default identity) places the object; `all_directions` overrides
    the protocol's early stop at the first failing direction.
    """
    if not isinstance(grasp, Grasp):
        from models.errors import GraspError

        raise GraspError(
            f"validate needs a models.grasp.Grasp, got {type(grasp).__name__} (Grasp.from_dict "
            "or Grasp.load make one)"
        )
    if all_directions is not None and not isinstance(all_directions, bool):
        from planner.validation.protocol import ProtocolError

        raise ProtocolError(f"all_directions must be True, False or None, got {all_directions!r}")
    warnings: list[str] = []
    with _mujoco_warnings(warnings):
        result = _validate(grasp, obj, hand, protocol, object_pose, all_directions)
    result.warnings = warnings
    return result


def _validate(
    grasp: Grasp,
    obj: Any,
    hand: Any,
    protocol: str | Protocol,
    object_pose: Any,
    all_directions: bool | None,
) -> ValidationResult:
    start = time.perf_counter()
    proto = get_protocol(protocol)
    if all_directions is not None:
        proto = proto.replace(all_directions=all_directions)
    adapter: HandAdapter = as_hand(hand)
    grasp.check_hand(adapter.joint_names, adapter.name)
    body: CollisionObject = as_collision_object(obj)
    obj_pose = _pose(object_pose)
    scene = get_scene(adapter, body, proto)
    m, d = scene.model, scene.data

    grasp_pen, contact_count = _grasp_contacts(scene, grasp, obj_pose, proto)
    result = ValidationResult(
        success=False,
        reason="pregrasp_penetration",
        grasp_penetration=grasp_pen,
        contact_count=contact_count,
        object_mass=scene.object_mass,
    )
    _set_configuration(scene, d, grasp.wrist_pose("pregrasp"), grasp.pregrasp, obj_pose)
    mujoco.mj_forward(m, d)
    dists, _ = _hand_object_contacts(scene, d)
    result.pregrasp_penetration = max(0.0, -min(dists, default=0.0))
    # DexGraspBench fails a grasp over either limit; both are measured, and a grasp over both
    # is reported as pregrasp_penetration
    result.pregrasp_self_penetration = _self_penetration(scene, d)
    if result.pregrasp_penetration > proto.max_pregrasp_penetration:
        result.wall_time = time.perf_counter() - start
        return result
    if result.pregrasp_self_penetration > proto.max_pregrasp_self_penetration:
        result.reason = "pregrasp_self_penetration"
        result.wall_time = time.perf_counter() - start
        return result

    simulated = 0.0
    if proto.share_closing:
        simulated += _close(scene, d, grasp, obj_pose, proto)
        if _unstable(scene, d):
            return _failed_unstable(result, simulated, start)
    success = True
    for direction in np.asarray(proto.directions, dtype=np.float64):
        if proto.share_closing:
            mujoco.mj_copyData(scene.scratch, m, d)
            run = scene.scratch
        else:  # DexGraspBench's way: re-simulate the closing for every direction
            run = scene.scratch
            simulated += _close(scene, run, grasp, obj_pose, proto)
            if _unstable(scene, run):
                return _failed_unstable(result, simulated, start)
        outcome = _hold(scene, run, direction, obj_pose, proto)
        simulated += outcome.hold_time
        result.directions.append(outcome)
        success = success and outcome.held
        if not outcome.held and not proto.all_directions:
            break
    result.success = success
    unstable = any(r.unstable for r in result.directions)
    result.reason = "held" if success else ("unstable" if unstable else "slipped")
    result.translation = max(r.translation for r in result.directions)
    result.rotation_deg = max(r.rotation_deg for r in result.directions)
    result.simulated_time = simulated
    result.wall_time = time.perf_counter() - start
    return result


def _failed_unstable(result: ValidationResult, simulated: float, start: float) -> ValidationResult:
    """The closing went unstable: no direction is tested, the grasp fails."""
    result.success = False
    result.reason = "unstable"
    result.simulated_time = simulated
    result.wall_time = time.perf_counter() - start
    return result
