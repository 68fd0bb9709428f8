"""Box, sphere, capsule and convex mesh: closed meshes and signed distances in the link frame."""

from __future__ import annotations

import numpy as np
import trimesh

from models.hands.urdf import Geom


def primitive_mesh(geom: Geom) -> trimesh.Trimesh:
    """The primitive as a closed mesh in its link's frame (for sampling and display)."""
    if geom.kind == "box":
        mesh = trimesh.creation.box(extents=2 * np.asarray(geom.size))
    elif geom.kind == "sphere":
        mesh = trimesh.creation.icosphere(subdivisions=3, radius=geom.size[0])
    elif geom.kind == "mesh":
        mesh = trimesh.convex.convex_hull(geom.vertices)
    else:
        mesh = trimesh.creation.capsule(
            height=2 * geom.size[1], radius=geom.size[0], count=[32, 32]
        )
    mesh.apply_transform(geom.pose)
    return mesh


def signed_distance(geom: Geom, points: np.ndarray) -> np.ndarray:
    """Signed distance (negative inside) from link-frame points (N, 3) to the primitive; for a
    convex mesh, the largest distance beyond its face planes (exact inside and on the surface,
    a lower bound outside: the sign is always right)."""
    local = (points - geom.pose[:3, 3]) @ geom.pose[:3, :3]
    if geom.kind == "mesh":
        hull = trimesh.convex.convex_hull(geom.vertices)
        offsets = np.einsum("fj,fj->f", hull.face_normals, hull.triangles[:, 0])
        return (local @ hull.face_normals.T - offsets).max(axis=1)
    if geom.kind == "sphere":
        return np.linalg.norm(local, axis=1) - geom.size[0]
    if geom.kind == "capsule":
        r, half = geom.size
        z = np.clip(local[:, 2], -half, half)
        return np.linalg.norm(local - np.stack([0 * z, 0 * z, z], axis=1), axis=1) - r
    q = np.abs(local) - np.asarray(geom.size)
    outside = np.linalg.norm(np.maximum(q, 0), axis=1)
    return outside + np.minimum(q.max(axis=1), 0)
