"""Watertight primitive solids that also know their own convex decomposition.

Every builder returns a `Solid`: a manifold3d solid for the mesh, and the convex pieces (point sets
whose hulls lie inside the solid and cover it) for collision. The pieces come from the
construction itself, so a generated object never needs CoACD (seconds per mesh) to be planned on.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import manifold3d as m3
import numpy as np

Manifold = m3.Manifold


@dataclass
class Solid:
    """One watertight solid and the convex point sets that decompose it."""

    manifold: Manifold
    pieces: list[np.ndarray] = field(default_factory=list)

    def transformed(self, matrix: np.ndarray) -> Solid:
        """Apply a 4x4 rigid transform to the solid and its pieces."""
        m = np.asarray(matrix, dtype=float)
        return Solid(
            self.manifold.transform(m[:3, :4]),
            [p @ m[:3, :3].T + m[:3, 3] for p in self.pieces],
        )

    def translated(self, offset: Sequence[float]) -> Solid:
        t = np.eye(4)
        t[:3, 3] = offset
        return self.transformed(t)


def rotation(axis: str, degrees: float) -> np.ndarray:
    """4x4 rotation about a principal axis ('x', 'y' or 'z')."""
    a = np.radians(degrees)
    c, s = np.cos(a), np.sin(a)
    i, j = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}[axis]
    r = np.eye(4)
    r[i, i], r[i, j], r[j, i], r[j, j] = c, -s, s, c
    return r


def hull(points: np.ndarray) -> Solid:
    """The convex hull of a point set: one solid, one piece."""
    pts = np.asarray(points, dtype=float)
    return Solid(Manifold.hull_points(pts), [pts])


def circle(radius: float | tuple[float, float], sides: int) -> np.ndarray:
    """Points of a circle (or ellipse with radii (a, b)) in the xy-plane, counter-clockwise."""
    a, b = (radius, radius) if np.isscalar(radius) else radius
    t = np.linspace(0.0, 2.0 * np.pi, sides, endpoint=False)
    return np.stack([a * np.cos(t), b * np.sin(t), np.zeros(sides)], axis=1)


def cylinder_z(r_low: float, r_high: float, z0: float, z1: float, sides: int = 48) -> Solid:
    """A (possibly tapered) cylinder or frustum along z between heights z0 and z1."""
    lo = circle(r_low, sides) + [0, 0, z0]
    hi = circle(r_high, sides) + [0, 0, z1]
    return hull(np.vstack([lo, hi]))


def dome_z(radius: float, height: float, z0: float, sides: int = 48, rings: int = 8) -> Solid:
    """A half-ellipsoid cap with its flat side at z0, rising to z0 + height."""
    pts = [circle(radius, sides) + [0, 0, z0]]
    for k in range(1, rings):
        phi = 0.5 * np.pi * k / rings
        pts.append(circle(radius * np.cos(phi), sides) + [0, 0, z0 + height * np.sin(phi)])
    pts.append(np.array([[0.0, 0.0, z0 + height]]))
    return hull(np.vstack(pts))


def revolve(
    outline: np.ndarray,
    pieces: Sequence[np.ndarray],
    segments: int = 64,
    sectors: int = 16,
) -> Solid:
    """Solid of revolution about z of a profile polygon in (r, z).

    `outline` is the whole profile (any simple polygon, r >= 0) and gives the mesh; `pieces` are
    convex polygons in (r, z) whose union is the profile. A piece touching the axis revolves to one
    convex solid; any other piece is cut into `sectors` wedges, each convex.
    """
    outline = np.asarray(outline, dtype=float)
    manifold = m3.CrossSection([outline]).revolve(segments)
    if manifold.is_empty():
        raise ValueError("revolve: profile gave an empty solid (wrong orientation?)")
    per_sector = max(1, segments // sectors)
    convex: list[np.ndarray] = []
    for poly in pieces:
        poly = np.asarray(poly, dtype=float)
        if poly[:, 0].min() <= 1e-9:
            angles = np.linspace(0, 2 * np.pi, segments, endpoint=False)
            convex.append(_spin(poly, angles))
            continue
        for j in range(sectors):
            k = np.arange(j * per_sector, (j + 1) * per_sector + 1)
            convex.append(_spin(poly, 2 * np.pi * k / (sectors * per_sector)))
    return Solid(manifold, convex)


def _spin(poly: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Points of a (r, z) polygon rotated about z to each angle."""
    r, z = poly[:, 0], poly[:, 1]
    c, s = np.cos(angles)[:, None], np.sin(angles)[:, None]
    pts = np.stack([r[None, :] * c, r[None, :] * s, np.broadcast_to(z, c.shape[:1] + z.shape)], -1)
    pts = pts.reshape(-1, 3)
    return np.unique(np.round(pts, 12), axis=0)


def tube(
    path: np.ndarray,
    radius: float | tuple[float, float] | np.ndarray,
    sides: int = 16,
    closed: bool = False,
    per_piece: int = 2,
) -> Solid:
    """A tube swept along a polyline through elliptic cross-sections, capped unless closed.

    `radius` is a scalar, an (a, b) ellipse (a in the path's curvature plane), or one value per
    path point (a taper). Frames follow the path by parallel transport, so the tube never twists.
    Each collision piece is the hull of the rings of `per_piece` consecutive segments.
    """
    path = np.asarray(path, dtype=float)
    n = len(path)
    radii = np.asarray(radius, dtype=float)
    if radii.ndim == 0 or radii.shape == (2,):
        radii = np.broadcast_to(radii, (n,) + radii.shape)
    rings, _ = _rings(path, radii, sides, closed)
    manifold = Manifold(_sweep_mesh(np.asarray(rings), closed))
    if manifold.status() != m3.Error.NoError or manifold.is_empty():
        raise ValueError(f"tube: swept mesh is not a valid solid ({manifold.status()})")
    count = n if closed else n - 1
    pieces = [
        np.vstack([rings[(i + k) % n] for k in range(per_piece + 1) if closed or i + k < n])
        for i in range(0, count, per_piece)
    ]
    return Solid(manifold, pieces)


def _sweep_mesh(rings: np.ndarray, closed: bool) -> m3.Mesh:
    """Triangle mesh of a tube through the rings (n, sides, 3), capped with fans when open."""
    n, sides = rings.shape[:2]
    verts = rings.reshape(-1, 3)
    idx = np.arange(n * sides).reshape(n, sides)
    nxt = np.roll(idx, -1, axis=1)
    count = n if closed else n - 1
    a, b = idx[:count], nxt[:count]
    c, d = np.roll(nxt, -1, axis=0)[:count], np.roll(idx, -1, axis=0)[:count]
    faces = [np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)]
    if not closed:
        centres = np.array([rings[0].mean(0), rings[-1].mean(0)])
        s0, s1 = len(verts), len(verts) + 1
        verts = np.vstack([verts, centres])
        faces.append(np.stack([np.full(sides, s0), nxt[0], idx[0]], 1))
        faces.append(np.stack([np.full(sides, s1), idx[-1], nxt[-1]], 1))
    tri = np.vstack(faces)
    # orient outward: the signed volume of a closed surface is positive when faces point out
    v = verts[tri]
    if np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() < 0:
        tri = tri[:, ::-1]
    return m3.Mesh(
        vert_properties=np.ascontiguousarray(verts, dtype=np.float32),
        tri_verts=np.ascontiguousarray(tri, dtype=np.uint32),
    )


def _rings(
    path: np.ndarray, radii: np.ndarray, sides: int, closed: bool
) -> tuple[list[np.ndarray], np.ndarray]:
    """Cross-section rings along the path, and the unit tangent at each path point."""
    n = len(path)
    if closed:
        tang = np.roll(path, -1, 0) - np.roll(path, 1, 0)
    else:
        tang = np.gradient(path, axis=0)
    tang /= np.linalg.norm(tang, axis=1, keepdims=True)
    # first normal: the direction of curvature if any, else any perpendicular
    bend = (path[min(2, n - 1)] - path[1 % n]) - (path[1 % n] - path[0]) if n > 2 else tang[0]
    normal = bend - tang[0] * (bend @ tang[0])
    if np.linalg.norm(normal) < 1e-9:
        normal = np.cross(tang[0], [0.0, 0.0, 1.0])
        if np.linalg.norm(normal) < 1e-9:
            normal = np.cross(tang[0], [0.0, 1.0, 0.0])
    normal /= np.linalg.norm(normal)
    theta = np.linspace(0.0, 2.0 * np.pi, sides, endpoint=False)
    rings = []
    for i in range(n):
        normal = normal - tang[i] * (normal @ tang[i])
        normal /= np.linalg.norm(normal)
        binormal = np.cross(tang[i], normal)
        r = radii[i]
        a, b = (r, r) if np.ndim(r) == 0 else (r[0], r[1])
        ring = (
            path[i]
            + (a * np.cos(theta))[:, None] * normal
            + (b * np.sin(theta))[:, None] * binormal
        )
        rings.append(ring)
    return rings, tang


def arc(
    center: Sequence[float],
    radii: tuple[float, float],
    start: float,
    stop: float,
    n: int,
    plane: str = "xz",
) -> np.ndarray:
    """Points of an elliptic arc (angles in degrees) in a principal plane through `center`."""
    t = np.radians(np.linspace(start, stop, n))
    u, v = radii[0] * np.cos(t), radii[1] * np.sin(t)
    pts = np.zeros((n, 3))
    i, j = {"xz": (0, 2), "xy": (0, 1), "yz": (1, 2)}[plane]
    pts[:, i], pts[:, j] = u, v
    return pts + np.asarray(center, dtype=float)


def shell_profile(outer: np.ndarray, inner: np.ndarray, coarse: int) -> tuple[np.ndarray, list]:
    """Outline and convex quads of a shell between two (r, z) curves running bottom to top.

    The quads (every `coarse` samples) become collision pieces. A straight chord of the inner
    curve would cut into the hollow, so each quad's inner corners move toward the outer curve by
    the chord's sagitta: the quad then stays in the wall.
    """
    outline = np.vstack([outer, inner[::-1]])
    idx = list(range(0, len(outer), coarse))
    if idx[-1] != len(outer) - 1:
        idx.append(len(outer) - 1)
    quads = []
    for a, b in zip(idx, idx[1:], strict=False):
        chord = inner[b] - inner[a]
        normal = np.array([chord[1], -chord[0]]) / max(np.linalg.norm(chord), 1e-12)
        if normal @ (outer[a] - inner[a]) < 0:
            normal = -normal  # toward the material
        sag = max(0.0, float(((inner[a : b + 1] - inner[a]) @ normal).max()))
        quads.append(
            np.array([outer[a], outer[b], inner[b] + sag * normal, inner[a] + sag * normal])
        )
    return outline, quads
