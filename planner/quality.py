"""Grasp quality from contacts, used to rank solved candidates before the costlier MuJoCo
validation: the epsilon metric (Ferrari-Canny) and a task metric for the validator's own test
(a force at the centre of mass along +-x, +-y, +-z).

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


AXES = np.concatenate([np.eye(3), -np.eye(3)])


def task_quality(
    points: np.ndarray,
    inward_normals: np.ndarray,
    centre: np.ndarray,
    directions: np.ndarray = AXES,
    mu: float = 0.6,
    edges: int = 6,
) -> float:
    """The smallest, over `directions`, of the largest pure force along it (at `centre`, no
    torque) inside the contact wrench hull of unit-force cone edges. Unlike epsilon it weighs
    torques only by what these forces demand of them (a far-off centre of mass costs quality),
    and does not depend on a characteristic length. <= 0: some direction cannot be resisted."""
    points = np.asarray(points, dtype=float)
    if len(points) < 2:
        return -1.0
    wrenches = friction_wrenches(points, np.asarray(inward_normals), centre, mu, edges, 1.0)
    try:
        hull = ConvexHull(wrenches)
    except QhullError:
        return -1.0
    normals, offsets = hull.equations[:, :-1], hull.equations[:, -1]
    if np.any(offsets > 0):  # the origin lies outside: no force closure at all
        return -float(np.max(offsets))
    reach = []
    for d in np.asarray(directions, dtype=float):
        w = np.concatenate([d / np.linalg.norm(d), np.zeros(3)])
        along = normals @ w
        ahead = along > 1e-12
        reach.append(float(np.min(-offsets[ahead] / along[ahead])) if ahead.any() else np.inf)
    return float(min(reach))
