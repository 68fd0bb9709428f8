"""PointNet++ set-abstraction encoder, sized for a CPU, with its grouping computed outside the net.

Two set-abstraction levels turn a cloud into a few dozen local tokens (a centre and a feature
each) that a denoiser can attend to: part-level detail survives where a single global vector
would lose it. Grouping uses farthest-point sampling and k nearest neighbours, both functions of
distances only, so the grouping of a cloud is unchanged by rotation, translation and uniform
scale: training computes it once per cached cloud and reuses it under every augmentation, and
inference computes it once per call (a few ms) however many samples are drawn.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from scipy.spatial import cKDTree
from torch import nn


@dataclass(frozen=True)
class LevelConfig:
    """One set-abstraction level: centres kept, neighbours per centre, MLP widths."""

    centres: int
    neighbours: int
    widths: tuple[int, ...]


@dataclass(frozen=True)
class Grouping:
    """Index arrays of the two levels: level-1 centres into the cloud and their neighbours;
    level-2 centres into the level-1 centres and their neighbours (also level-1 indices)."""

    centres1: np.ndarray  # (S1,)
    nbrs1: np.ndarray  # (S1, k1) into the cloud
    centres2: np.ndarray  # (S2,) into centres1
    nbrs2: np.ndarray  # (S2, k2) into centres1

    def tensors(self) -> dict[str, torch.Tensor]:
        return {k: torch.from_numpy(np.ascontiguousarray(v)) for k, v in self.__dict__.items()}


def farthest_point_indices(points: np.ndarray, n: int) -> np.ndarray:
    """n farthest-point samples starting from the point farthest from the centroid: distances
    only, so the choice ignores the cloud's pose (squared distances, coordinates apart: fast)."""
    pts = np.asarray(points, dtype=np.float64)
    n = min(n, len(pts))
    x, y, z = (np.ascontiguousarray(pts[:, i]) for i in range(3))
    c = pts.mean(axis=0)
    first = int(np.argmax((x - c[0]) ** 2 + (y - c[1]) ** 2 + (z - c[2]) ** 2))
    idx = np.empty(n, dtype=np.int64)
    idx[0] = first
    dist = np.full(len(pts), np.inf)
    tmp = np.empty(len(pts))
    for i in range(n):
        if i:
            idx[i] = int(np.argmax(dist))
        j = idx[i]
        np.subtract(x, x[j], out=tmp)
        d = tmp * tmp
        np.subtract(y, y[j], out=tmp)
        d += tmp * tmp
        np.subtract(z, z[j], out=tmp)
        d += tmp * tmp
        np.minimum(dist, d, out=dist)
    return idx


def grouping(points: np.ndarray, levels: tuple[LevelConfig, LevelConfig]) -> Grouping:
    """FPS centres and kNN neighbourhoods of both levels for one (N, 3) cloud."""
    pts = np.asarray(points, dtype=np.float64)
    a, b = levels
    c1 = farthest_point_indices(pts, a.centres)
    k1 = min(a.neighbours, len(pts))
    nb1 = cKDTree(pts).query(pts[c1], k=k1)[1].reshape(len(c1), k1)
    p1 = pts[c1]
    c2 = farthest_point_indices(p1, b.centres)
    k2 = min(b.neighbours, len(p1))
    nb2 = cKDTree(p1).query(p1[c2], k=k2)[1].reshape(len(c2), k2)
    return Grouping(
        c1.astype(np.int64), nb1.astype(np.int64), c2.astype(np.int64), nb2.astype(np.int64)
    )


def _gather(x: torch.Tensor, idx: torch.Tensor) -> torch.Tensor:
    """x (B, N, C), idx (B, ...) -> (B, ..., C)."""
    b = x.shape[0]
    flat = idx.reshape(b, -1)
    out = torch.gather(x, 1, flat.unsqueeze(-1).expand(-1, -1, x.shape[-1]))
    return out.reshape(*idx.shape, x.shape[-1])


def _mlp(widths: list[int]) -> nn.Sequential:
    layers: list[nn.Module] = []
    for i in range(len(widths) - 1):
        layers += [nn.Linear(widths[i], widths[i + 1]), nn.GELU()]
    return nn.Sequential(*layers)


class SetAbstraction(nn.Module):
    """Shared MLP over each neighbourhood (offsets from the centre, scaled, plus features), then
    max-pooling: PointNet on local regions."""

    def __init__(self, in_features: int, widths: tuple[int, ...], offset_scale: float):
        super().__init__()
        self.offset_scale = offset_scale
        self.mlp = _mlp([in_features + 3, *widths])

    def forward(
        self,
        xyz: torch.Tensor,
        feats: torch.Tensor | None,
        centres: torch.Tensor,
        nbrs: torch.Tensor,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        centre_xyz = _gather(xyz, centres)  # (B, S, 3)
        local = (_gather(xyz, nbrs) - centre_xyz.unsqueeze(2)) / self.offset_scale
        if feats is not None:
            local = torch.cat([local, _gather(feats, nbrs)], dim=-1)
        return centre_xyz, self.mlp(local).max(dim=2).values


class PointNet2Encoder(nn.Module):
    """Cloud -> (S2 tokens of width `out`, their centres, a global vector). Coordinates are in
    the model's units (the canonical frame, scaled); each token also sees its centre's position."""

    def __init__(
        self, levels: tuple[LevelConfig, LevelConfig], out: int, offset_scales: tuple[float, float]
    ):
        super().__init__()
        a, b = levels
        self.sa1 = SetAbstraction(0, a.widths, offset_scales[0])
        self.sa2 = SetAbstraction(a.widths[-1], b.widths, offset_scales[1])
        self.pos = nn.Linear(3, b.widths[-1])
        self.proj = nn.Sequential(nn.GELU(), nn.Linear(b.widths[-1], out))
        self.glob = nn.Linear(b.widths[-1], out)

    def forward(
        self, xyz: torch.Tensor, groups: dict[str, torch.Tensor]
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        p1, f1 = self.sa1(xyz, None, groups["centres1"], groups["nbrs1"])
        p2, f2 = self.sa2(p1, f1, groups["centres2"], groups["nbrs2"])
        f2 = f2 + self.pos(p2)
        tokens = self.proj(f2)
        return tokens, p2, self.glob(f2.max(dim=1).values)
