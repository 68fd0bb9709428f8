"""Grasp quality from contacts: the epsilon metric (Ferrari-Canny) used to rank solved
candidates before the costlier MuJoCo validation.

A contact pushes along the object's inward normal within a friction cone (a pyramid of
`edges` generators); the grasp wrench space is the convex hull of every generator's wrench
(torque divided by a characteristic length so units match). Epsilon is the radius of the
largest ball about the origin inside that hull: positive means force closure.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull, QhullError


def friction_wrenches(
    points: np.ndarray,
    inward_normals: np.ndarray,
    centre: np.ndarray,
    mu: float,
    edges: int,
    length: float,
) -> np.ndarray:
    """(contacts * edges, 6) unit-force wrenches on the object at its friction-cone edges."""
    out = []
    for p, n in zip(points, inward_normals, strict=True):
        n = n / np.linalg.norm(n)
        t1 = np.cross(n, [1.0, 0, 0] if abs(n[0]) < 0.9 else [0, 1.0, 0])
        t1 /= np.linalg.norm(t1)
        t2 = np.cross(n, t1)
        for k in range(edges):
            a = 2 * np.pi * k / edges
            f = n + mu * (np.cos(a) * t1 + np.sin(a) * t2)
            f /= np.linalg.norm(f)
            out.append(np.concatenate([f, np.cross(p - centre, f) / length]))
    return np.asarray(out)


def epsilon_quality(
    points: np.ndarray,
    inward_normals: np.ndarray,
    centre: np.ndarray,
    mu: float = 0.6,
    edges: int = 6,
    length: float | None = None,
) -> float:
    """Largest wrench-ball radius inside the hull (negative: the origin is outside by that
    much, so no force closure). `length` defaults to the contacts' mean distance to `centre`."""
    points = np.asarray(points, dtype=float)
    if len(points) < 2:
        return -1.0
    if length is None:
        length = max(float(np.mean(np.linalg.norm(points - centre, axis=1))), 1e-3)
    wrenches = friction_wrenches(points, np.asarray(inward_normals), centre, mu, edges, length)
    try:
        hull = ConvexHull(wrenches)
    except QhullError:  # flat wrench set (e.g. collinear contacts): no force closure
        return -1.0
    # hull.equations: normal . x + offset <= 0 inside; distance of the origin to each facet
    return float(np.min(-hull.equations[:, -1]))
