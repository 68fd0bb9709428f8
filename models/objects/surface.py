"""Surface samples with outward normals, normal estimation for bare clouds, farthest-point sampling."""

from __future__ import annotations

import numpy as np
import trimesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import breadth_first_order, connected_components, minimum_spanning_tree
from scipy.spatial import cKDTree


def sample_mesh(
    mesh: trimesh.Trimesh, n: int, seed: int, face_labels: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Area-weighted random surface points, their face normals, and their faces' part labels."""
    rng = np.random.default_rng(seed)
    area = mesh.area_faces
    cdf = np.cumsum(area)
    faces = np.searchsorted(cdf, rng.random(n) * cdf[-1], side="right")
    faces = np.minimum(faces, len(area) - 1)
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    tri = mesh.triangles[faces]
    pts = tri[:, 0] + u[:, None] * (tri[:, 1] - tri[:, 0]) + v[:, None] * (tri[:, 2] - tri[:, 0])
    normals = mesh.face_normals[faces]
    labels = None if face_labels is None else np.asarray(face_labels)[faces]
    return pts, normals, labels


def estimate_normals(
    points: np.ndarray, k: int = 12, viewpoint: np.ndarray | None = None
) -> np.ndarray:
    """Unit normals of a bare cloud: PCA of k neighbours, oriented consistently.

    With a `viewpoint` (the camera of a single-view scan) each normal is turned toward it. Without,
    orientation propagates along a minimum spanning tree whose edge cost grows with both the angle
    between normals and the offset across the tangent plane, so it follows each sheet of a thin
    wall instead of jumping through it (a mug's inner wall keeps normals facing the cavity); each
    connected component starts from its point farthest from its centroid, facing outward. That
    needs a wall thicker than about twice the point spacing (a 4 mm mug wall: ~20k points on the
    mug), and its start can face in; so the tree's answer is checked against each point's local
    evidence (`_orient_locally`) and, where they disagree, the local orientation is used (at
    4096 points: 86-100% of normals right per object over 14 categories, against about half for
    thin walls and whole objects inside out with the tree alone).
    """
    pts = np.asarray(points, dtype=float)
    k = min(k, len(pts) - 1)
    tree = cKDTree(pts)
    dist, nbr = tree.query(pts, k=k + 1)
    local = pts[nbr] - pts[nbr].mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", local, local)
    _, vecs = np.linalg.eigh(cov)
    normals = vecs[:, :, 0]
    if viewpoint is not None:
        flip = np.einsum("ij,ij->i", normals, np.asarray(viewpoint) - pts) < 0
        normals[flip] *= -1
        return normals
    local = _orient_locally(pts, normals, tree)
    mst = _orient_mst(pts, normals, nbr[:, 1:], dist[:, 1:])
    agree = float((np.einsum("ij,ij->i", mst, local) > 0).mean())
    if agree >= MST_AGREEMENT:
        return mst
    if agree <= 1.0 - MST_AGREEMENT:  # the tree followed the sheets but started facing in
        return -mst
    return local


# Share of the points on whose side the spanning tree and the local evidence must agree for the
# tree's orientation to be used. Local orientation is right for 86-100% of the points of every
# category at 2k-20k points; the tree for 98-100% of most dense clouds (it follows each sheet),
# but for about half of a sparse thin wall (a 4096-point mug: it jumps between the wall's sheets),
# and a wrong start turns a whole object inside out.
MST_AGREEMENT = 0.8
LOCAL_RADIUS = 0.008  # m: about twice a thin wall (mug, bowl, glass: 2-6 mm)


def _orient_locally(pts: np.ndarray, normals: np.ndarray, tree: cKDTree, k: int = 24) -> np.ndarray:
    """Each normal turned away from its neighbours' mean offset along it. The neighbours of a
    point on a convex surface lie behind its tangent plane, and on a thin wall the other sheet
    lies behind it, so the offset says which side is outside without any propagation (which a
    sparse thin wall defeats); it is weak on flat and concave patches only."""
    # at least LOCAL_RADIUS around each point: a wall's other sheet and the surface's curvature
    # must be inside the neighbourhood however dense the cloud
    reach = float(np.median(tree.query(pts[:: max(1, len(pts) // 500)], k=k + 1)[0][:, -1]))
    k = int(np.clip(k * (LOCAL_RADIUS / max(reach, 1e-9)) ** 2, k, 160))
    _, nbr = tree.query(pts, k=min(k, len(pts) - 1) + 1)
    offset = np.einsum("nkj,nj->n", pts[nbr[:, 1:]] - pts[:, None], normals) / (nbr.shape[1] - 1)
    out = normals.copy()
    out[offset > 0] *= -1
    return out


def _orient_mst(
    pts: np.ndarray, normals: np.ndarray, nbr: np.ndarray, dist: np.ndarray
) -> np.ndarray:
    n, k = nbr.shape
    rows = np.repeat(np.arange(n), k)
    cols = nbr.ravel()
    offs = pts[cols] - pts[rows]
    across = np.abs(np.einsum("ij,ij->i", offs, normals[rows])) / np.maximum(dist.ravel(), 1e-12)
    bend = 1.0 - np.abs(np.einsum("ij,ij->i", normals[rows], normals[cols]))
    graph = coo_matrix((bend + across + 1e-6, (rows, cols)), shape=(n, n)).tocsr()
    graph = graph.maximum(graph.T)
    tree = minimum_spanning_tree(graph)
    tree = tree + tree.T
    ncomp, comp = connected_components(tree, directed=False)
    out = normals.copy()
    for c in range(ncomp):
        members = np.flatnonzero(comp == c)
        centre = pts[members].mean(0)
        root = members[np.argmax(np.linalg.norm(pts[members] - centre, axis=1))]
        if out[root] @ (pts[root] - centre) < 0:
            out[root] *= -1
        order, pred = breadth_first_order(tree, root, directed=False)
        for i in order[1:]:
            if out[i] @ out[pred[i]] < 0:
                out[i] *= -1
    return out


def farthest_point_indices(points: np.ndarray, n: int) -> np.ndarray:
    """Indices of n farthest-point samples, starting from the point farthest from the centroid.

    Deterministic (no random start), so the same object always gives the same 512 points.
    """
    pts = np.asarray(points, dtype=float)
    n = min(n, len(pts))
    idx = np.empty(n, dtype=np.int64)
    idx[0] = int(np.argmax(np.linalg.norm(pts - pts.mean(0), axis=1)))
    d = np.linalg.norm(pts - pts[idx[0]], axis=1)
    for i in range(1, n):
        idx[i] = int(np.argmax(d))
        d = np.minimum(d, np.linalg.norm(pts - pts[idx[i]], axis=1))
    return idx
