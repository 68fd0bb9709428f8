"""Fixed surface points on a hand's links (the D(R,O) hand cloud).

Point i is the same physical point in every configuration: points are sampled once in each
link's frame (dense, area-weighted) and thinned by farthest-point sampling at the open pose,
so the 512 points spread evenly over the whole hand rather than per link.
"""

from __future__ import annotations

from dataclasses import replace

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


def _in_frame(geom: Geom, frame: np.ndarray, own: np.ndarray) -> Geom:
    """`geom` (given in the frame whose pose is `own`) expressed in the frame posed `frame`."""
    if own is frame or np.array_equal(own, frame):
        return geom
    return replace(geom, pose=np.linalg.inv(frame) @ own @ geom.pose)


def surface_points(
    link_geoms: list[list[Geom]],
    link_poses_open: np.ndarray,
    n: int = 512,
    dense: int = 20000,
    seed: int = 0,
    rigid_groups: list[int] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """(link index per point (n,), point in its link's frame (n, 3)).

    Only surface that is not buried inside another primitive of the same rigid body is kept,
    so the points lie on the body's outer geometry. `rigid_groups` gives each link's rigid body
    (links joined by fixed joints share one, e.g. a fingertip link and its distal link; default:
    every link its own), so a hand whose tip is a separate fixed link gets the same points as
    the same hand with the tip fused into its parent."""
    groups = list(range(len(link_geoms))) if rigid_groups is None else list(rigid_groups)
    meshes = [(li, g, primitive_mesh(g)) for li, geoms in enumerate(link_geoms) for g in geoms]
    areas = np.array([m.area for _, _, m in meshes])
    counts = np.maximum(1, np.round(dense * areas / areas.sum()).astype(int))
    rng = np.random.default_rng(seed)
    link_idx, local = [], []
    for (li, geom, mesh), count in zip(meshes, counts, strict=True):
        pts, _ = trimesh.sample.sample_surface(mesh, count, seed=int(rng.integers(2**31)))
        keep = np.ones(len(pts), dtype=bool)
        for lj, other, _ in meshes:
            if groups[lj] == groups[li] and other is not geom:
                # in the link frame of `li`: the links of one rigid body keep fixed poses
                other = _in_frame(other, link_poses_open[li], link_poses_open[lj])
                keep &= signed_distance(other, pts) > 1e-4
        link_idx.append(np.full(keep.sum(), li))
        local.append(pts[keep])
    link_idx, local = np.concatenate(link_idx), np.concatenate(local)
    world = np.einsum("pij,pj->pi", link_poses_open[link_idx, :3, :3], local)
    world += link_poses_open[link_idx, :3, 3]
    chosen = farthest_point_sample(world, n, seed)
    return link_idx[chosen], local[chosen]
