"""The fixed transform between a project hand's root link and an MJCF hand file's root frame.

A hand file for MuJoCo (DexGraspBench's, Menagerie's, a user's) describes the same hand as a
project hand folder but not necessarily in the same root frame: DexGraspBench moves the file's
own world frame (the frame its root body is placed in) with a free joint, while the project's
wrist pose is the pose of the URDF's root link. The transform between the two is computed here
from the files alone: both hands are put at the same joint values (matched by name, or through a
joint map), the world poses of the bodies that carry the same names in both are compared, and
the rigid transform that maps one set onto the other is solved (Kabsch, on each body's origin
and on points `AXIS_LENGTH` along its three axes, so orientations count too). Two joint
configurations are used (zero, and the middle of the project's joint ranges), so joint axes that
disagree show as a residual as well.

    offset = mjcf_root_offset("shadow", "hand/shadow_right_hand.xml")
    offset.pose  # xyz + quaternion wxyz of the MJCF root frame in the project's root link frame
    offset.matrix  # the same as a 4x4

The result is cached per (hand folder, MJCF path and its modification time, joint map).
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from models.errors import HandError
from models.hands.model import HandModel, load_hand
from models.reproducible import rounded

POSITION_TOLERANCE = 1e-5  # m: largest residual of a matched body point after the fit
AXIS_LENGTH = 0.1  # m: body axes enter the fit as points this far from the body's origin
MIN_COMMON_BODIES = 3


@dataclass(frozen=True)
class RootOffset:
    """The MJCF file's root frame in the project hand's root link frame.

    `pose` is xyz + quaternion wxyz, rounded to `models.reproducible.DECIMALS` places (the fit's
    last bits depend on the machine's linear algebra kernels) with the quaternion's first
    nonzero value positive; `matrix` the same as a 4x4. `bodies` are the bodies matched by
    name; `residual` the largest distance (m) of a matched body point from its counterpart
    after the fit.
    """

    pose: np.ndarray
    bodies: tuple[str, ...]
    residual: float

    @property
    def matrix(self) -> np.ndarray:
        out = np.eye(4)
        out[:3, :3] = Rotation.from_quat(self.pose[3:], scalar_first=True).as_matrix()
        out[:3, 3] = self.pose[:3]
        return out


def _canonical_pose(matrix: np.ndarray) -> np.ndarray:
    quat = rounded(Rotation.from_matrix(matrix[:3, :3]).as_quat(scalar_first=True))
    quat = quat / np.linalg.norm(quat)
    if quat[np.flatnonzero(quat)[0]] < 0:
        quat = -quat
    return np.concatenate([rounded(matrix[:3, 3]), quat]) + 0.0  # + 0.0: no negative zeros


def mjcf_root_offset(
    hand: str | Path | HandModel,
    xml_path: str | Path,
    joint_map: Mapping[str, str] | None = None,
) -> RootOffset:
    """The pose of `xml_path`'s root frame in the root link frame of project hand `hand`.

    `hand` is a built-in hand name, a hand folder or a loaded HandModel; `joint_map` maps the
    project's joint names to the file's where they differ. Raises HandError when the files do
    not describe the same hand (fewer than MIN_COMMON_BODIES bodies share names, or a matched
    body is more than POSITION_TOLERANCE from where the fitted transform puts it).
    """
    model = hand if isinstance(hand, HandModel) else load_hand(hand)
    path = Path(xml_path).expanduser().resolve()
    if not path.is_file():
        raise HandError(f"{xml_path}: no such MJCF hand file")
    items = tuple(sorted((str(k), str(v)) for k, v in dict(joint_map or {}).items()))
    stat = path.stat()  # an edited file is solved again
    offset = _cached_offset(str(model.folder), str(path), stat.st_mtime_ns, stat.st_size, items)
    return RootOffset(offset.pose.copy(), offset.bodies, offset.residual)


@functools.lru_cache(maxsize=32)
def _cached_offset(
    folder: str, xml_path: str, mtime_ns: int, size: int, joint_map: tuple[tuple[str, str], ...]
) -> RootOffset:
    return _solve(load_hand(folder), Path(xml_path), dict(joint_map))


def _mjcf_model(path: Path):
    import mujoco

    try:
        return mujoco.MjModel.from_xml_path(str(path))
    except ValueError as err:
        raise HandError(f"{path}: cannot read MJCF hand: {err}") from None


def _qpos_index(hand: HandModel, model, path: Path, joint_map: Mapping[str, str]) -> list[int]:
    """For each project joint, the qpos address of its MJCF joint."""
    import mujoco

    unknown = sorted(set(joint_map) - set(hand.joint_names))
    if unknown:
        raise HandError(f"joint map names joints hand {hand.name!r} lacks: {unknown}")
    out = []
    for name in hand.joint_names:
        xml_name = joint_map.get(name, name)
        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, xml_name)
        if jid < 0 or int(model.jnt_type[jid]) not in (
            int(mujoco.mjtJoint.mjJNT_HINGE),
            int(mujoco.mjtJoint.mjJNT_SLIDE),
        ):
            raise HandError(
                f"joint {name!r} of hand {hand.name!r} (MJCF name {xml_name!r}) is not a hinge "
                f"or slide joint of {path.name}; pass a joint map from the hand's joint names "
                "to the file's"
            )
        out.append(int(model.jnt_qposadr[jid]))
    return out


def _body_points(rotations: np.ndarray, origins: np.ndarray) -> np.ndarray:
    """(N, 3, 3), (N, 3) -> (N, 4, 3): each origin and the points AXIS_LENGTH along its axes."""
    axes = origins[:, None, :] + AXIS_LENGTH * np.swapaxes(rotations, 1, 2)
    return np.concatenate([origins[:, None, :], axes], axis=1)


def _solve(hand: HandModel, path: Path, joint_map: Mapping[str, str]) -> RootOffset:
    import mujoco

    model = _mjcf_model(path)
    mj_bodies = {model.body(b).name: b for b in range(1, model.nbody)}
    common = [name for name in hand.link_names if name in mj_bodies]
    if len(common) < MIN_COMMON_BODIES:
        raise HandError(
            f"{path.name} and hand {hand.name!r} share {len(common)} body names "
            f"({', '.join(common) or 'none'}); at least {MIN_COMMON_BODIES} are needed to find "
            f"the transform between their root frames. The hand's links are "
            f"{hand.link_names}; the file's bodies {sorted(mj_bodies)}"
        )
    qpos_index = _qpos_index(hand, model, path, joint_map)
    link_index = [hand.link_index(name) for name in common]
    body_index = [mj_bodies[name] for name in common]
    data = mujoco.MjData(model)
    middle = np.nan_to_num(0.5 * (hand.lower + hand.upper), nan=0.0, posinf=0.0, neginf=0.0)
    configurations = (np.zeros(hand.dof), middle)
    project, mjcf = [], []
    wrist = torch.tensor([[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]], dtype=torch.float64)
    for q in configurations:
        poses = hand.link_poses(wrist, torch.as_tensor(q[None], dtype=torch.float64))[0].numpy()
        poses = poses[link_index]
        project.append(_body_points(poses[:, :3, :3], poses[:, :3, 3]))
        data.qpos[:] = model.qpos0
        data.qpos[qpos_index] = q
        mujoco.mj_kinematics(model, data)
        rot = data.xmat[body_index].reshape(-1, 3, 3)
        mjcf.append(_body_points(rot, data.xpos[body_index]))
    target = np.concatenate(project).reshape(-1, 3)  # in the project root link frame
    source = np.concatenate(mjcf).reshape(-1, 3)  # in the MJCF root frame
    offset = RootOffset(_canonical_pose(kabsch(source, target)), tuple(common), 0.0)
    matrix = offset.matrix
    fitted = source @ matrix[:3, :3].T + matrix[:3, 3]
    error = np.linalg.norm(fitted - target, axis=1)
    residual = float(error.max())
    if not residual <= POSITION_TOLERANCE:
        worst = common[(int(error.argmax()) // 4) % len(common)]
        raise HandError(
            f"{path.name} does not describe hand {hand.name!r} ({hand.folder}): after the best "
            f"rigid fit of their {len(common)} common bodies at the same joint values, body "
            f"{worst!r} is {residual * 1000:.3f} mm off (tolerance "
            f"{POSITION_TOLERANCE * 1000:.3f} mm). Check that the file is this hand and that "
            "the joint map pairs the right joints"
        )
    return RootOffset(offset.pose, offset.bodies, residual)


def kabsch(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The 4x4 rigid transform T (rotation, no reflection) minimising |T source - target|^2."""
    source = np.asarray(source, dtype=np.float64)
    target = np.asarray(target, dtype=np.float64)
    cs, ct = source.mean(axis=0), target.mean(axis=0)
    cov = (source - cs).T @ (target - ct)
    u, _, vt = np.linalg.svd(cov)
    d = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
    rot = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    out = np.eye(4)
    out[:3, :3] = rot
    out[:3, 3] = ct - rot @ cs
    return out
