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
back comes out up to 8 mm too near), and a plane fills only the half it mirrors.

Objects that stand on their axis (bottles, cups, bowls, glasses, a mug's body) are completed by
revolution first: a vertical axis fitted to circles through horizontal slices of the view, each
seen point swept around it, the copies the image contradicts dropped. Seen points whose copies
the image contradicts too often (a mug's handle) are not swept; they are mirrored through the
vertical plane through the axis along them (a handle's own plane), or as above where the image
contradicts that plane. A swept object's underside, which a camera above never sees, is closed
by a disc. A view whose sweep the image contradicts overall (a knife lying down) is only
mirrored.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
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
# revolution: the view cut into horizontal slices this thick (m); a slice counts toward the axis
# when a circle fits its points to CIRCLE_FIT of its radius (rms) over an arc of ARC_DEG or more
SLICE = 0.01
CIRCLE_FIT = 0.08
ARC_DEG = 100.0
COPIES = 16  # rotations of each seen point about the axis
# a seen point is swept when the image contradicts at most POINT_CONFLICT of its copies; the
# sweep is trusted when MIN_SWEPT of the seen points are and the image contradicts at most
# SWEEP_MAX_CONFLICT of their copies (test views: cups, bottles, bowls, glasses, lotion pumps
# 0.2-0.8%, a mug's body, a pan's or a teapot's 0.4-1.7%, spray bottles 3.5-5.7%)
POINT_CONFLICT = 0.2
MIN_SWEPT = 0.6
SWEEP_MAX_CONFLICT = 0.03
# m: a seen point this near one that does not sweep is not swept either (the few points of a
# mug's handle whose copies happen to hide behind the body would ring it with phantom handles)
UNSWEPT_MARGIN = 0.005
# the plane through the axis for what a sweep leaves: tried this far either side of the left
# points' principal direction, in these steps (degrees)
AXIAL_SPAN_DEG = 10.0
AXIAL_STEP_DEG = 0.5
# the underside of a swept object (never in view from above) is closed by a disc at its lowest
# point, as wide as the points within BASE_LAYER of it reach (90th percentile)
BASE_LAYER = 0.004
THIN = 2.0  # the swept copies are thinned to one per cell of this many seen point spacings


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


@dataclass(frozen=True)
class Revolution:
    """A vertical axis through `centre` (x, y) and which seen points sweep around it: `swept`
    (N,) per seen point, `keep` (N, COPIES - 1) per copy (not contradicted by the image);
    `conflict` the share of the swept points' copies the image contradicts."""

    centre: np.ndarray
    swept: np.ndarray
    keep: np.ndarray
    conflict: float


def _circle(xy: np.ndarray) -> tuple[np.ndarray, float, float]:
    """Least-squares circle through 2-D points (Kasa): centre, radius, rms residual."""
    a = np.column_stack([2.0 * xy, np.ones(len(xy))])
    sol = np.linalg.lstsq(a, (xy**2).sum(axis=1), rcond=None)[0]
    centre = sol[:2]
    radius = float(np.sqrt(max(sol[2] + centre @ centre, 0.0)))
    rms = float(np.sqrt(np.mean((np.linalg.norm(xy - centre, axis=1) - radius) ** 2)))
    return centre, radius, rms


def find_axis(points: np.ndarray) -> np.ndarray | None:
    """The (x, y) of a vertical axis that the view's horizontal slices are circles about (the
    median of the slices' centres), or None when fewer than two slices are circular arcs."""
    z = points[:, 2]
    centres = []
    for low in np.arange(z.min(), z.max(), SLICE):
        xy = points[(z >= low) & (z < low + SLICE), :2]
        if len(xy) < 20:
            continue
        centre, radius, rms = _circle(xy)
        if radius < 0.003 or rms > CIRCLE_FIT * radius:
            continue
        angles = np.sort(np.arctan2(*(xy - centre).T[::-1]))
        gaps = np.diff(np.concatenate([angles, angles[:1] + 2 * np.pi]))
        if np.degrees(2 * np.pi - gaps.max()) >= ARC_DEG:
            centres.append(centre)
    if len(centres) < 2:
        return None
    return np.median(np.array(centres), axis=0)


def _rotations() -> np.ndarray:
    angles = 2.0 * np.pi * np.arange(1, COPIES) / COPIES
    c, s = np.cos(angles), np.sin(angles)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)  # (COPIES - 1, 2, 2)


def revolve(points: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """(N, COPIES - 1, 3) every point turned about the vertical axis through `centre` (x, y);
    for normals pass a zero centre."""
    rel = points[:, :2] - centre
    turned = np.einsum("kij,nj->nki", _rotations(), rel) + centre
    z = np.repeat(points[:, None, 2:], COPIES - 1, axis=1)
    return np.concatenate([turned, z], axis=2)


def find_revolution(
    points: np.ndarray, eye: np.ndarray, image: _DepthImage | None = None
) -> Revolution | None:
    """The sweep of the view about its fitted vertical axis, or None when no axis fits, fewer
    than MIN_SWEPT of the points sweep, or the image contradicts more than SWEEP_MAX_CONFLICT
    of the swept points' copies. `image`: the view's depth image where already made."""
    centre = find_axis(points)
    if centre is None:
        return None
    if image is None:
        image = _DepthImage(points, eye)
    copies = revolve(points, centre)
    conflicts = image.conflicts(copies.reshape(-1, 3)).reshape(copies.shape[:2])
    swept = conflicts.mean(axis=1) <= POINT_CONFLICT
    if (~swept).any():
        near = cKDTree(points[~swept]).query(points, distance_upper_bound=UNSWEPT_MARGIN)[0]
        swept &= np.isinf(near)
    if swept.mean() < MIN_SWEPT:
        return None
    conflict = float(conflicts[swept].mean())
    if conflict > SWEEP_MAX_CONFLICT:
        return None
    return Revolution(centre, swept, ~conflicts & swept[:, None], conflict)


def _thin(points: np.ndarray, spacing: float, seen: cKDTree) -> np.ndarray:
    """Indices of `points`, one per cell of a `spacing` grid, farther than `spacing` from the
    seen ones (copies pile up near the axis and over what was seen)."""
    cells = np.floor(points / spacing).astype(np.int64)
    cells -= cells.min(axis=0)
    size = cells.max(axis=0) + 1
    _, first = np.unique(
        cells[:, 0] + size[0] * (cells[:, 1] + size[1] * cells[:, 2]), return_index=True
    )
    first = np.sort(first)
    gap = seen.query(points[first], distance_upper_bound=spacing)[0]
    return first[np.isinf(gap)]


def base(points: np.ndarray, centre: np.ndarray, spacing: float) -> np.ndarray:
    """Points of the disc closing a swept object's underside: a grid of `spacing` at the lowest
    height of `points` (the completed cloud), about the axis at `centre` (x, y), out to a
    spacing inside the rim the lowest layer reaches, less the grid points already near the
    cloud. Bottles, cups and mugs stand on a flat base; without it the fingers may be planned
    under a rim into the hollow a base would fill."""
    low = float(points[:, 2].min())
    layer = points[points[:, 2] < low + BASE_LAYER, :2] - centre
    radius = float(np.percentile(np.linalg.norm(layer, axis=1), 90)) - spacing
    if radius <= spacing:
        return np.empty((0, 3))
    ticks = np.arange(-radius, radius + 1e-12, spacing)
    grid = np.stack(np.meshgrid(ticks, ticks), axis=-1).reshape(-1, 2)
    grid = grid[np.linalg.norm(grid, axis=1) <= radius] + centre
    disc = np.column_stack([grid, np.full(len(grid), low)])
    return disc[cKDTree(points).query(disc)[0] > spacing]


def reflect(points: np.ndarray, normal: np.ndarray, offset: float) -> np.ndarray:
    return points + 2.0 * (offset - points @ normal)[:, None] * normal


def _probe(points: np.ndarray) -> np.ndarray:
    """At most about 1500 of the points, evenly by index: enough to score a plane."""
    return points[:: max(1, len(points) // 1500)]


def _best_plane(
    probe: np.ndarray, planes: Iterable[tuple[np.ndarray, float]], image: _DepthImage
) -> Mirror | None:
    """Of the planes (normal, offset), the one whose reflection of `probe` scores best (its
    share of contradicted points less NOVELTY_WEIGHT times its share adding surface, farther
    than two point spacings from the probe), or None when that one's contradicted share
    exceeds MAX_CONFLICT. Earlier planes win ties."""
    tree = cKDTree(probe)
    apart = 2.0 * float(np.median(tree.query(probe, k=2)[0][:, 1]))
    best, best_score = None, np.inf
    for normal, offset in planes:
        mirrored = reflect(probe, normal, offset)
        conflict = float(image.conflicts(mirrored).mean())
        novel = float((tree.query(mirrored)[0] > apart).mean())
        score = conflict - NOVELTY_WEIGHT * novel
        if score < best_score - 1e-9:
            best, best_score = Mirror(normal, float(offset), conflict), score
    if best is None or best.conflict > MAX_CONFLICT:
        return None
    return best


def find_mirror(
    points: np.ndarray, eye: np.ndarray, image: _DepthImage | None = None
) -> Mirror | None:
    """The best-scoring plane (few contradictions, much added surface) for the view of
    `points` from `eye`, or None when its reflection contradicts the image at more than
    MAX_CONFLICT of the points. `image`: the view's depth image where already made."""
    if image is None:
        image = _DepthImage(points, eye)
    probe = _probe(points)
    view = image.axis.copy()
    view[2] = 0.0
    normals = []
    if np.linalg.norm(view) > 0.2:  # not looking straight down: vertical planes
        view /= np.linalg.norm(view)
        for yaw in np.radians(YAWS_DEG):  # facing the camera first, so it wins ties
            c, s = np.cos(yaw), np.sin(yaw)
            normals.append(np.array([c * view[0] - s * view[1], s * view[0] + c * view[1], 0.0]))
    normals.append(np.array([0.0, 0.0, -1.0]))  # the unseen underside

    def planes() -> Iterator[tuple[np.ndarray, float]]:
        for normal in normals:
            depth = probe @ normal
            front = float(np.percentile(depth, 2))
            # a symmetric object's plane lies about as deep as the seen part reaches (a
            # cylinder's seen sides sit at its axis): offsets up to 1.5 times that depth
            span = max(float(np.percentile(depth, 98)) - front, 1e-3)
            for offset in front + np.linspace(0.05, 1.5, OFFSETS) * span:
                yield normal, float(offset)

    return _best_plane(probe, planes(), image)


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


@dataclass(frozen=True)
class Completion:
    """How a view is completed: the sweep about a vertical axis (or None) and the mirror plane
    for the points it does not sweep (or None); `axial` when that plane is the one through the
    axis along the unswept points."""

    revolution: Revolution | None
    mirror: Mirror | None
    axial: bool = False

    @property
    def kind(self) -> str:
        """ "swept", "swept+mirrored", "mirrored" or "as seen" (nothing added)."""
        parts = ["swept"] if self.revolution is not None else []
        parts += ["mirrored"] if self.mirror is not None else []
        return "+".join(parts) or "as seen"


def axial_mirror(points: np.ndarray, centre: np.ndarray, image: _DepthImage) -> Mirror | None:
    """The vertical plane through the axis at `centre` (x, y) along which `points` lie (what a
    sweep leaves: a mug's handle, a pan's handle, a teapot's handle and spout), or None when its
    reflection contradicts the image at more than MAX_CONFLICT of them. Such parts are symmetric
    about that plane; the plane chosen for the whole view (facing the camera) would put their
    mirror images 15-20 mm (median) away, behind the body. The planes within AXIAL_SPAN_DEG of
    the points' principal direction are scored as `find_mirror` scores its planes: a handle
    seen edge on is contradicted by a plane 3 degrees off its own."""
    probe = _probe(points)
    rel = probe[:, :2] - centre
    _, vectors = np.linalg.eigh(rel.T @ rel)
    principal = np.arctan2(vectors[1, 1], vectors[0, 1])
    planes = []
    for delta in np.radians(np.arange(-AXIAL_SPAN_DEG, AXIAL_SPAN_DEG + 1e-9, AXIAL_STEP_DEG)):
        normal = np.array([-np.sin(principal + delta), np.cos(principal + delta), 0.0])
        planes.append((normal, float(centre @ normal[:2])))
    return _best_plane(probe, planes, image)


def find_completion(points: np.ndarray, eye: np.ndarray) -> Completion:
    """The sweep (`find_revolution`) and, for what it leaves, the plane through its axis
    (`axial_mirror`), else the view's own plane (`find_mirror`)."""
    image = _DepthImage(points, eye)
    turn = find_revolution(points, eye, image)
    rest = np.ones(len(points), dtype=bool) if turn is None else ~turn.swept
    if not rest.any():
        return Completion(turn, None)
    if turn is not None:
        axial = axial_mirror(points[rest], turn.centre, image)
        if axial is not None:
            return Completion(turn, axial, axial=True)
    return Completion(turn, find_mirror(points, eye, image))


def complete_view(obj: ObjectModel) -> ObjectModel:
    """A single-view cloud (an ObjectModel with a `viewpoint`) smoothed (`smooth`) and with its
    hidden side added (`find_completion`): the points the sweep takes turned about its axis and
    a swept object's underside closed (`base`), the others reflected through the mirror plane
    (points, normals and part labels alike), the copies the depth image contradicts dropped;
    only smoothed when nothing explains the view; `completed_by` says which. Anything else (a
    mesh, a cloud without a viewpoint) comes back unchanged."""
    from .loading import load_object

    if obj.mesh is not None or obj.viewpoint is None:
        return obj
    points, normals, labels = smooth(obj.points), obj.normals, obj.point_labels
    eye = np.asarray(obj.viewpoint, dtype=float)
    seen = len(points)
    add_p, add_n, add_src = [], [], []
    mirrored = np.ones(seen, dtype=bool)
    plan = find_completion(points, eye)
    turn = plan.revolution
    if turn is not None:
        copies = revolve(points, turn.centre)[turn.keep]
        turned = revolve(normals, np.zeros(2))[turn.keep]
        source = np.broadcast_to(np.arange(seen)[:, None], turn.keep.shape)[turn.keep]
        tree = cKDTree(points)
        spacing = THIN * float(np.median(tree.query(points, k=2)[0][:, 1]))
        pick = _thin(copies, spacing, tree)
        add_p.append(copies[pick])
        add_n.append(turned[pick])
        add_src.append(source[pick])
        mirrored = ~turn.swept
    if plan.mirror is not None:
        n = plan.mirror.normal
        src = np.flatnonzero(mirrored)
        add_p.append(reflect(points[src], n, plan.mirror.offset))
        add_n.append(normals[src] - 2.0 * (normals[src] @ n)[:, None] * n)
        add_src.append(src)
    if add_p:
        src = np.concatenate(add_src)
        points = np.vstack([points, *add_p])
        normals = np.vstack([normals, *add_n])
        labels = None if labels is None else np.concatenate([labels, labels[src]])
    if turn is not None:
        disc = base(points, turn.centre, spacing)
        if labels is not None:  # the base takes the label of its rim
            labels = np.concatenate([labels, labels[cKDTree(points).query(disc)[1]]])
        points = np.vstack([points, disc])
        normals = np.vstack([normals, np.tile([0.0, 0.0, -1.0], (len(disc), 1))])
    done = load_object(
        points,
        name=f"{obj.name}_completed",
        normals=normals,
        labels=labels,
        part_names=obj.part_names if labels is not None else (),
    )
    done.completed_by = plan.kind
    return done
