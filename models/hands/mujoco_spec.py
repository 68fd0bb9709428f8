"""Build a MuJoCo model of a hand from the same URDF: MjSpec reads it (capsules included),
then the wrist weld, position actuators and contact exclusions are added here, so there
is no second model file to keep in sync."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np

WRIST_MOCAP = "wrist_mocap"
WRIST_JOINT = "wrist_free"
WRIST_WELD = "wrist_weld"


def actuator_name(joint: str) -> str:
    return f"{joint}_act"


def hand_spec(hand) -> mujoco.MjSpec:
    """A fresh spec: mocap body `wrist_mocap`, root body with free joint `wrist_free` welded
    to it (`wrist_weld`), one position actuator `<joint>_act` per joint, or per coupling
    `<coupling>_act` on its fixed tendon (kp from hand.json, ctrlrange from the joint limits), joint damping/armature/friction loss from hand.json, and the
    hand.json contact exclusions."""
    spec = mujoco.MjSpec.from_file(str(hand.urdf_path))
    spec.compiler.fusestatic = False
    for (
        mesh
    ) in spec.meshes:  # collision meshes: absolute, so a scene that attaches the hand finds them
        if mesh.file and not Path(mesh.file).is_absolute():
            mesh.file = str((hand.urdf_path.parent / mesh.file).resolve())
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
    lower = dict(zip(hand.joint_names, hand.lower, strict=True))
    upper = dict(zip(hand.joint_names, hand.upper, strict=True))
    for actuated in hand.actuators():
        joints, coefs = actuated["joints"], np.asarray(actuated["tendon"])
        if len(joints) == 1:
            act = spec.add_actuator(
                name=actuator_name(joints[0]), target=joints[0], trntype=mujoco.mjtTrn.mjTRN_JOINT
            )
        else:  # a coupling: one position actuator on the fixed tendon sum(coef x q)
            tendon = spec.add_tendon(name=actuated["name"])
            for joint, coef in zip(joints, coefs, strict=True):
                tendon.wrap_joint(joint, float(coef))
            act = spec.add_actuator(
                name=actuator_name(actuated["name"]),
                target=actuated["name"],
                trntype=mujoco.mjtTrn.mjTRN_TENDON,
            )
        ends = np.array([[lower[j] * c, upper[j] * c] for j, c in zip(joints, coefs, strict=True)])
        act.set_to_position(kp=meta.kp, kv=meta.kv)
        act.ctrlrange = [float(ends.min(axis=1).sum()), float(ends.max(axis=1).sum())]
        act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        if meta.force_range > 0:
            act.forcerange = [-meta.force_range, meta.force_range]
            act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
    for a, b in meta.ignore_collision_pairs:
        spec.add_exclude(bodyname1=a, bodyname2=b)
    return spec


def mujoco_link_poses(hand, configs: np.ndarray) -> np.ndarray:
    """(C, L, 4, 4) poses of `hand.link_names` in MuJoCo's model of the hand (compiled from
    `hand_spec`), wrist at the identity, at joint configurations `configs` (C, dof). Raises
    what MuJoCo raises; HandModel.check turns that into a HandError naming the file."""
    model = hand_spec(hand).compile()
    data = mujoco.MjData(model)
    wrist = int(model.joint(WRIST_JOINT).qposadr[0])
    qadr = [int(model.joint(name).qposadr[0]) for name in hand.joint_names]
    bodies = [model.body(name).id for name in hand.link_names]
    out = np.zeros((len(configs), len(bodies), 4, 4))
    for k, q in enumerate(configs):
        data.qpos[:] = model.qpos0
        data.qpos[wrist : wrist + 7] = [0, 0, 0, 1, 0, 0, 0]
        data.qpos[qadr] = q
        mujoco.mj_forward(model, data)
        if not (np.all(np.isfinite(data.qacc)) and np.all(np.isfinite(data.xpos))):
            raise ValueError("the hand's dynamics are not finite (check masses and inertias)")
        out[k, :, :3, :3] = data.xmat[bodies].reshape(-1, 3, 3)
        out[k, :, :3, 3] = data.xpos[bodies]
        out[k, :, 3, 3] = 1.0
    return out
