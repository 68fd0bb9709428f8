"""Grasp quality from contacts, used to rank solved candidates before the costlier MuJoCo
validation: the epsilon metric (Ferrari-Canny) and a task metric for the validator's own test
(a force at the centre of mass along +-x, +-y, +-z).

A contact pushes along the object's inward normal within a friction cone (a pyramid of
`edges` generators); the grasp wrench space is the convex hull of every generator's wrench
(torque divided by a characteristic length so units match). Epsilon is the radius of the
largest ball about the origin inside that hull: positive means force closure.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull, QhullError

AXES = np.concatenate([np.eye(3), -np.eye(3)])  # the validator's test forces
# contacts whose points (m) and normals agree to this many decimals are one contact: a vertex
# of a convex piece reached through two hand geometries comes back 1e-14 apart
SAME_CONTACT_DECIMALS = 9


def cone_edges(inward: np.ndarray, mu: float, edges: int) -> np.ndarray:
    """(edges, 3) generators n + mu t of the linearised friction cone about the unit `inward`."""
    t1 = np.cross(inward, [1.0, 0, 0] if abs(inward[0]) < 0.9 else [0, 1.0, 0])
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(inward, t1)
    angles = 2 * np.pi * np.arange(edges) / edges
    return inward + mu * (np.cos(angles)[:, None] * t1 + np.sin(angles)[:, None] * t2)


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
        for f in cone_edges(n / np.linalg.norm(n), mu, edges):
            f = f / np.linalg.norm(f)
            out.append(np.concatenate([f, np.cross(p - centre, f) / length]))
    return np.asarray(out)


def wrench_hull(wrenches: np.ndarray) -> ConvexHull | None:
    """The convex hull of (M, 6) wrenches, or None where they span less than six dimensions
    (then no ball about the origin fits inside). Qhull's default merging first; joggled input
    where merging meets a precision error on a set that does span them."""
    if len(wrenches) < 7 or np.linalg.matrix_rank(wrenches[1:] - wrenches[0]) < 6:
        return None
    try:
        return ConvexHull(wrenches)
    except QhullError:
        try:
            return ConvexHull(wrenches, qhull_options="QJ")
        except QhullError:
            return None


@dataclass(frozen=True)
class ContactQuality:
    epsilon: float  # largest wrench ball about the origin inside the hull (<0: no closure)
    task: float  # smallest, over the test directions, largest pure force resisted (<0: none)


def contact_quality(
    points: np.ndarray,
    inward_normals: np.ndarray,
    centre: np.ndarray,
    mu: float = 0.6,
    edges: int = 6,
    directions: np.ndarray = AXES,
) -> ContactQuality:
    """Both metrics from one wrench hull (torques divided by the contacts' mean distance to
    `centre`). Epsilon: the radius of the largest ball about the origin inside the hull. Task:
    the smallest, over `directions`, of the largest pure force along it (at `centre`, no torque)
    inside the hull; a pure-force ray ignores the torque scaling, so unlike epsilon it weighs
    torques only by what these forces demand of them (a far-off centre of mass costs quality).
    Without force closure both are the (negative) distance of the origin outside the hull;
    a wrench set that spans less than the six dimensions (e.g. collinear contacts) has none.

    The same contact twice (two hand geometries nearest one vertex of a convex piece: about a
    quarter of the planner's contact sets, often 1e-14 apart) adds only copies of wrenches
    already there, and such near-copies made Qhull stop with a precision error on about 1 in
    130 solved grasps, which then read as no force closure however good the grasp; they are
    dropped first (the torque scale still counts every contact, as before), and a set of full
    rank that still meets a precision error is taken again with joggled input (QJ)."""
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    inward_normals = np.asarray(inward_normals, dtype=float).reshape(-1, 3)
    if len(points) < 2:
        return ContactQuality(-1.0, -1.0)
    length = max(float(np.mean(np.linalg.norm(points - centre, axis=1))), 1e-3)
    same = np.round(np.hstack([points, inward_normals]), SAME_CONTACT_DECIMALS)
    _, first = np.unique(same, axis=0, return_index=True)
    keep = np.sort(first)  # the contacts' own order: Qhull's arithmetic follows it
    points, inward_normals = points[keep], inward_normals[keep]
    wrenches = friction_wrenches(points, inward_normals, centre, mu, edges, length)
    hull = wrench_hull(wrenches)
    if hull is None:
        return ContactQuality(-1.0, -1.0)
    # hull.equations: normal . x + offset <= 0 inside; distance of the origin to each facet
    normals, offsets = hull.equations[:, :-1], hull.equations[:, -1]
    epsilon = float(np.min(-offsets))
    if epsilon <= 0:
        return ContactQuality(epsilon, epsilon)
    reach = []
    for d in np.asarray(directions, dtype=float):
        along = normals[:, :3] @ (d / np.linalg.norm(d))
        ahead = along > 1e-12
        reach.append(float(np.min(-offsets[ahead] / along[ahead])) if ahead.any() else np.inf)
    return ContactQuality(epsilon, float(min(reach)))
