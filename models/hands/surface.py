"""Fixed surface points on a hand's links (the D(R,O) hand cloud).

Point i is the same physical point in every configuration: points are sampled once in each
link's frame (dense, area-weighted) and thinned by farthest-point sampling at the open pose,
so the 512 points spread evenly over the whole hand rather than per link.
"""

from __future__ import annotations

import numpy as np
import trimesh

from models.hands.primitives import primitive_mesh, signed_distance
from models.hands.urdf import Geom


def farthest_point_sample(points: np.ndarray, n: int, seed: int = 0) -> np.ndarray:
    """Indices of n farthest-point samples, starting from a seeded random point."""
    rng = np.random.default_rng(seed)
    chosen = np.empty(n, dtype=np.int64)
    chosen[0] = rng.integers(len(points))
    dist = np.linalg.norm(points - points[chosen[0]], axis=1)
    for i in range(1, n):
        chosen[i] = int(np.argmax(dist))
        dist = np.minimum(dist, np.linalg.norm(points - points[chosen[i]], axis=1))
    return chosen


def surface_points(
    link_geoms: list[list[Geom]],
    link_poses_open: np.ndarray,
    n: int = 512,
    dense: int = 20000,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """(link index per point (n,), point in its link's frame (n, 3)).

    Only surface that is not buried inside another primitive of the same link is kept, so
    the points lie on the link's outer geometry."""
    meshes = [(li, g, primitive_mesh(g)) for li, geoms in enumerate(link_geoms) for g in geoms]
    areas = np.array([m.area for _, _, m in meshes])
    counts = np.maximum(1, np.round(dense * areas / areas.sum()).astype(int))
    rng = np.random.default_rng(seed)
    link_idx, local = [], []
    for (li, geom, mesh), count in zip(meshes, counts, strict=True):
        pts, _ = trimesh.sample.sample_surface(mesh, count, seed=int(rng.integers(2**31)))
        keep = np.ones(len(pts), dtype=bool)
        for lj, other, _ in meshes:
            if lj == li and other is not geom:
                keep &= signed_distance(other, pts) > 1e-4
        link_idx.append(np.full(keep.sum(), li))
        local.append(pts[keep])
    link_idx, local = np.concatenate(link_idx), np.concatenate(local)
    world = np.einsum("pij,pj->pi", link_poses_open[link_idx, :3, :3], local)
    world += link_poses_open[link_idx, :3, 3]
    chosen = farthest_point_sample(world, n, seed)
    return link_idx[chosen], local[chosen]
