"""Batched forward kinematics in PyTorch (differentiable, any device and float dtype)."""

from __future__ import annotations

import numpy as np
import torch

from models.hands.urdf import KinematicTree


def quat_to_matrix(quat_wxyz: torch.Tensor) -> torch.Tensor:
    """(..., 4) unit quaternions (w, x, y, z) -> (..., 3, 3) rotation matrices."""
    q = quat_wxyz / quat_wxyz.norm(dim=-1, keepdim=True)
    w, x, y, z = q.unbind(-1)
    return torch.stack(
        [
            1 - 2 * (y * y + z * z),
            2 * (x * y - w * z),
            2 * (x * z + w * y),
            2 * (x * y + w * z),
            1 - 2 * (x * x + z * z),
            2 * (y * z - w * x),
            2 * (x * z - w * y),
            2 * (y * z + w * x),
            1 - 2 * (x * x + y * y),
        ],
        dim=-1,
    ).reshape(q.shape[:-1] + (3, 3))


def wrist_matrix(wrist: torch.Tensor) -> torch.Tensor:
    """Wrist pose as (B, 7) [xyz, quat wxyz] or (B, 4, 4) -> (B, 4, 4)."""
    if wrist.shape[-2:] == (4, 4):
        return wrist
    out = torch.zeros(wrist.shape[:-1] + (4, 4), dtype=wrist.dtype, device=wrist.device)
    out[..., :3, :3] = quat_to_matrix(wrist[..., 3:7])
    out[..., :3, 3] = wrist[..., :3]
    out[..., 3, 3] = 1
    return out


def _axis_angle(axis: torch.Tensor, angle: torch.Tensor) -> torch.Tensor:
    """Rodrigues: fixed unit axis (3,), angles (B,) -> (B, 4, 4) rotations about the axis."""
    k = torch.zeros(3, 3, dtype=angle.dtype, device=angle.device)
    k[0, 1], k[0, 2], k[1, 2] = -axis[2], axis[1], -axis[0]
    k = k - k.T
    s, c = torch.sin(angle)[:, None, None], torch.cos(angle)[:, None, None]
    eye = torch.eye(3, dtype=angle.dtype, device=angle.device)
    out = torch.zeros(angle.shape[0], 4, 4, dtype=angle.dtype, device=angle.device)
    out[:, :3, :3] = eye + s * k + (1 - c) * (k @ k)
    out[:, 3, 3] = 1
    return out


class Kinematics:
    """FK for one kinematic tree; joint values are taken in `joint_order` (the revolute joints;
    a fixed joint's child link rides on its parent at the joint's origin)."""

    def __init__(self, tree: KinematicTree, joint_order: list[str]):
        self.tree = tree
        self.links = list(tree.links)
        index = {name: i for i, name in enumerate(joint_order)}
        # (child link index, parent link index, origin, axis, q index; axis and q index None
        # for a fixed joint)
        self._steps = []
        for link in self.links[1:]:
            j = tree.joints[link]
            self._steps.append(
                (
                    self.links.index(link),
                    self.links.index(j.parent),
                    torch.as_tensor(j.origin, dtype=torch.float64),
                    torch.as_tensor(j.axis, dtype=torch.float64) if j.moves else None,
                    index[j.name] if j.moves else None,
                )
            )

    def link_poses(self, wrist: torch.Tensor, q: torch.Tensor) -> torch.Tensor:
        """World poses of every link, (B, L, 4, 4), links in `self.links` order."""
        base = wrist_matrix(wrist.to(dtype=q.dtype, device=q.device))
        poses: list[torch.Tensor | None] = [None] * len(self.links)
        poses[0] = base
        for child, parent, origin, axis, qi in self._steps:
            origin = origin.to(dtype=q.dtype, device=q.device)
            if axis is None:
                poses[child] = poses[parent] @ origin
                continue
            axis = axis.to(dtype=q.dtype, device=q.device)
            poses[child] = poses[parent] @ origin @ _axis_angle(axis, q[:, qi])
        return torch.stack(poses, dim=1)


def transform_points(poses: torch.Tensor, link_index: np.ndarray, local: torch.Tensor):
    """Apply per-point link poses: poses (B, L, 4, 4), local (P, 3) -> (B, P, 3)."""
    sel = poses[:, torch.as_tensor(link_index, dtype=torch.long)]  # (B, P, 4, 4)
    return (sel[..., :3, :3] @ local[None, :, :, None]).squeeze(-1) + sel[..., :3, 3]
