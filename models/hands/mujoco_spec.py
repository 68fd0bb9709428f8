"""Build a MuJoCo model of a hand from the same URDF: MjSpec reads it (capsules included),
then the wrist weld, position actuators and contact exclusions are added here, so there
is no second model file to keep in sync."""

from __future__ import annotations

import mujoco

WRIST_MOCAP = "wrist_mocap"
WRIST_JOINT = "wrist_free"
WRIST_WELD = "wrist_weld"


def actuator_name(joint: str) -> str:
    return f"{joint}_act"


def hand_spec(hand) -> mujoco.MjSpec:
    """A fresh spec: mocap body `wrist_mocap`, root body with free joint `wrist_free` welded
    to it (`wrist_weld`), one position actuator `<joint>_act` per joint (kp from hand.json,
    ctrlrange = joint limits), joint damping/armature/friction loss from hand.json, and the
    hand.json contact exclusions."""
    spec = mujoco.MjSpec.from_file(str(hand.urdf_path))
    spec.compiler.fusestatic = False
    root = spec.body(hand.root_link)
    root.add_freejoint(name=WRIST_JOINT)
    spec.worldbody.add_body(name=WRIST_MOCAP, mocap=True)
    weld = spec.add_equality(
        name=WRIST_WELD,
        type=mujoco.mjtEq.mjEQ_WELD,
        objtype=mujoco.mjtObj.mjOBJ_BODY,
        name1=hand.root_link,
        name2=WRIST_MOCAP,
    )
    # MJCF's weld defaults (anchor 0, relative pose from qpos0, torque scale 1); the spec API
    # would otherwise put the anchor at (0, 1, 0)
    weld.data[:] = 0.0
    weld.data[10] = 1.0
    meta = hand.meta
    for joint in hand.joint_names:
        spec_joint = spec.joint(joint)
        spec_joint.damping[0] = meta.joint_damping  # MuJoCo 4: [linear, ...] coefficients
        spec_joint.armature = meta.joint_armature
        spec_joint.frictionloss = meta.joint_frictionloss
    for joint, lo, hi in zip(hand.joint_names, hand.lower, hand.upper, strict=True):
        act = spec.add_actuator(
            name=actuator_name(joint), target=joint, trntype=mujoco.mjtTrn.mjTRN_JOINT
        )
        act.set_to_position(kp=meta.kp, kv=meta.kv)
        act.ctrlrange = [lo, hi]
        act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        if meta.force_range > 0:
            act.forcerange = [-meta.force_range, meta.force_range]
            act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
    for a, b in meta.ignore_collision_pairs:
        spec.add_exclude(bodyname1=a, bodyname2=b)
    return spec
