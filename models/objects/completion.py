"""Completing a single-view cloud by mirror symmetry, checked against what the camera saw.

A depth camera sees the front of an object; a planner given only that shell plans fingers
through the unseen back (they end centimetres inside the real object) and closes on a shell
that is not there. Most graspable things are mirror-symmetric about some plane (a mug, a
bottle, a bowl about any vertical plane through their axis; a knife or a pen about the plane
through its length), so the hidden half is well guessed by reflecting the seen half (Bohg et
al., "Mind the gap", ICRA 2011). Which plane and where: candidate planes (vertical ones at yaws
around the viewing direction, the horizontal one below) and offsets are scored by free space,
the one fact a depth image gives about the unseen: a reflected point that the camera would
have seen (on a ray that hit nothing, or in front of the surface the ray hit) contradicts the
image. The score is the share of contradicting reflected points less a small weight on the
share that adds surface, so that among the planes the image allows the one filling most of what
was hidden wins; a view no plane explains is returned as it was. The frame's z axis is taken
as up (objects stand or lie on something), as everywhere in this package. The plane of a
rotationally symmetric object tends to sit a few millimetres toward the camera (a bottle's
back comes out up to 8 mm too near).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from .model import ObjectModel

YAWS_DEG = (0.0, -30.0, 30.0, -60.0, 60.0)  # vertical planes about the view, facing it first
OFFSETS = 30  # plane positions tried per candidate, across the seen part's depth
GROW = 2  # cells
DEPTH_TOLERANCE = 0.004  # m: a reflected point this far in front of the seen surface is free
# a plane's score is its share of contradicting reflected points less this weight times the
# share of reflected points that add surface (farther than two point spacings from the seen
# ones): among planes the image allows, the one that fills most of what was hidden
NOVELTY_WEIGHT = 0.05
MAX_CONFLICT = 0.08  # share of contradicting reflected points above which no plane is trusted
SMOOTH_NEIGHBOURS = 16  # each seen point moves onto the plane fitted to this many neighbours


@dataclass(frozen=True)
class Mirror:
    """The chosen mirror plane {x : x . normal = offset} and its share of contradictions."""

    normal: np.ndarray
    offset: float
    conflict: float


class _DepthImage:
    """What the camera at `eye` saw: per image cell (pinhole coordinates, cells about 1.5
    point spacings wide) the nearest seen depth. An empty cell within GROW cells of seen ones
    takes their depth: sampling gaps and the silhouette's ragged edge are not free space."""

    def __init__(self, points: np.ndarray, eye: np.ndarray) -> None:
        self.eye = eye
        axis = points.mean(axis=0) - eye
        self.axis = axis / np.linalg.norm(axis)
        side = np.cross(self.axis, [0.0, 0.0, 1.0])
        if np.linalg.norm(side) < 1e-6:  # looking straight down
            side = np.cross(self.axis, [1.0, 0.0, 0.0])
        self.e1 = side / np.linalg.norm(side)
        self.e2 = np.cross(self.e1, self.axis)
        uv, depth = self.project(points)
        spacing = float(np.median(cKDTree(uv).query(uv, k=2)[0][:, 1]))
        self.cell = max(1.5 * spacing, 1e-5)
        self.low = uv.min(axis=0) - (GROW + 1) * self.cell
        ij = self._cells(uv)
        shape = tuple(ij.max(axis=0) + GROW + 2)
        seen = np.full(shape, np.inf)
        np.minimum.at(seen, (ij[:, 0], ij[:, 1]), depth)
        grown = seen.copy()
        for di in range(-GROW, GROW + 1):
            for dj in range(-GROW, GROW + 1):
                grown = np.minimum(grown, np.roll(np.roll(seen, di, axis=0), dj, axis=1))
        self.depth = np.where(np.isinf(seen), grown, seen)  # neighbours fill gaps only

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        rel = points - self.eye
        z = rel @ self.axis
        uv = np.stack([rel @ self.e1 / z, rel @ self.e2 / z], axis=1)
        return uv, np.linalg.norm(rel, axis=1)

    def _cells(self, uv: np.ndarray) -> np.ndarray:
        return np.floor((uv - self.low) / self.cell).astype(int)

    def conflicts(self, points: np.ndarray) -> np.ndarray:
        """True where the camera would have seen the point: on a ray that hit nothing (or
        outside the seen image), or clearly in front of the surface its ray hit."""
        uv, depth = self.project(points)
        ij = self._cells(uv)
        inside = (ij >= 0).all(axis=1) & (ij < np.array(self.depth.shape)).all(axis=1)
        out = np.ones(len(points), dtype=bool)
        seen = self.depth[ij[inside, 0], ij[inside, 1]]
        out[inside] = depth[inside] < seen - DEPTH_TOLERANCE
        return out


def reflect(points: np.ndarray, normal: np.ndarray, offset: float) -> np.ndarray:
    return points + 2.0 * (offset - points @ normal)[:, None] * normal


def find_mirror(points: np.ndarray, eye: np.ndarray) -> Mirror | None:
    """The best-scoring plane (few contradictions, much added surface) for the view of
    `points` from `eye`, or None when its reflection contradicts the image at more than
    MAX_CONFLICT of the points."""
    image = _DepthImage(points, eye)
    probe = points[:: max(1, len(points) // 1500)]
    view = image.axis.copy()
    view[2] = 0.0
    normals = []
    if np.linalg.norm(view) > 0.2:  # not looking straight down: vertical planes
        view /= np.linalg.norm(view)
        for yaw in np.radians(YAWS_DEG):
            c, s = np.cos(yaw), np.sin(yaw)
            normals.append(np.array([c * view[0] - s * view[1], s * view[0] + c * view[1], 0.0]))
    normals.append(np.array([0.0, 0.0, -1.0]))  # the unseen underside
    tree = cKDTree(probe)
    apart = 2.0 * float(np.median(tree.query(probe, k=2)[0][:, 1]))
    best, best_score = None, np.inf
    for normal in normals:
        depth = probe @ normal
        front = float(np.percentile(depth, 2))
        # a symmetric object's plane lies about as deep as the seen part reaches (a cylinder's
        # seen sides sit at its axis): offsets up to 1.5 times that depth
        span = max(float(np.percentile(depth, 98)) - front, 1e-3)
        for offset in front + np.linspace(0.05, 1.5, OFFSETS) * span:
            mirrored = reflect(probe, normal, offset)
            conflict = float(image.conflicts(mirrored).mean())
            novel = float((tree.query(mirrored)[0] > apart).mean())
            score = conflict - NOVELTY_WEIGHT * novel
            if score < best_score - 1e-9:  # earlier planes (facing the camera) win ties
                best, best_score = Mirror(normal, float(offset), conflict), score
    if best is None or best.conflict > MAX_CONFLICT:
        return None
    return best


def smooth(points: np.ndarray, k: int = SMOOTH_NEIGHBOURS) -> np.ndarray:
    """Each point moved onto the plane fitted to its k nearest neighbours. A depth camera's
    noise (about 1 mm along the rays) would otherwise make every convex collision piece bulge
    out to its outermost noisy points, 2-3 mm above the real surface, and fingers planned
    against it stop short of the object."""
    pts = np.asarray(points, dtype=float)
    k = min(k, len(pts))
    near = pts[cKDTree(pts).query(pts, k=k)[1]]
    centre = near.mean(axis=1)
    spread = near - centre[:, None, :]
    _, vectors = np.linalg.eigh(np.einsum("nki,nkj->nij", spread, spread))
    normal = vectors[:, :, 0]  # smallest variance: the local surface normal
    return pts - np.einsum("ni,ni->n", pts - centre, normal)[:, None] * normal


def complete_view(obj: ObjectModel) -> ObjectModel:
    """A single-view cloud (an ObjectModel with a `viewpoint`) smoothed (`smooth`) and with its
    mirrored half added: points, normals and part labels reflected through `find_mirror`'s
    plane (only smoothed when no plane explains the view). Anything else (a mesh, a cloud
    without a viewpoint) comes back unchanged."""
    from .loading import load_object

    if obj.mesh is not None or obj.viewpoint is None:
        return obj
    points, normals, labels = smooth(obj.points), obj.normals, obj.point_labels
    mirror = find_mirror(points, np.asarray(obj.viewpoint, dtype=float))
    if mirror is not None:
        n = mirror.normal
        points = np.vstack([points, reflect(points, n, mirror.offset)])
        normals = np.vstack([normals, normals - 2.0 * (normals @ n)[:, None] * n])
        labels = None if labels is None else np.concatenate([labels, labels])
    return load_object(
        points,
        name=f"{obj.name}_completed",
        normals=normals,
        labels=labels,
        part_names=obj.part_names if labels is not None else (),
    )
