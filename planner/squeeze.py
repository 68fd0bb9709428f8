"""Balanced squeeze forces: what each anchor fingertip should push with so the squeeze holds
the object still instead of shoving or twisting it.

The validator drives the fingers to squeeze = 2 x grasp - pregrasp under position control, so
the joint offset grasp - pregrasp sets the joint torques, and with them the fingertip forces,
at the squeeze. Moving every fingertip back 1 cm along its normal (the old rule) gives forces
that differ by finger stiffness and need not balance: on knife and hammer handles the closing
alone turned the object past the 15 degree limit before any test force was applied. Here the
forces are chosen first (each in its friction cone, with at least a unit push along the
normal, net wrench as near zero as the cones allow) and the joint offsets follow from them.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import nnls

from planner.quality import cone_edges


def balanced_forces(
    points: np.ndarray,
    inward_normals: np.ndarray,
    mu: float = 0.5,
    edges: int = 6,
    regularization: float = 1e-2,
) -> tuple[np.ndarray, float]:
    """Contact forces (F, 3) on the object whose net wrench is as small as possible, each the
    unit inward normal plus a non-negative combination of its friction-cone edges (so every
    finger pushes at least unit force and stays inside its cone). Torques are divided by the
    contacts' mean distance to their centroid so force and torque weigh alike; the small
    `regularization` keeps the extra forces no larger than the balance needs.

    Returns the forces and the residual net wrench relative to that of the unit normals
    (0: balanced, 1: no better than equal normal pushes)."""
    points = np.asarray(points, dtype=float)
    inward = np.asarray(inward_normals, dtype=float)
    inward = inward / np.linalg.norm(inward, axis=1, keepdims=True)
    centre = points.mean(axis=0)
    length = max(float(np.mean(np.linalg.norm(points - centre, axis=1))), 1e-3)

    def wrench(p: np.ndarray, f: np.ndarray) -> np.ndarray:
        return np.concatenate([f, np.cross(p - centre, f) / length])

    base = sum(wrench(p, n) for p, n in zip(points, inward, strict=True))
    generators = [cone_edges(n, mu, edges) for n in inward]
    columns = np.array(
        [wrench(p, e) for p, gens in zip(points, generators, strict=True) for e in gens]
    ).T
    k = columns.shape[1]
    weights, _ = nnls(
        np.vstack([columns, np.sqrt(regularization) * np.eye(k)]),
        np.concatenate([-base, np.zeros(k)]),
    )
    extra = (weights.reshape(len(points), edges, 1) * np.stack(generators)).sum(axis=1)
    residual = float(np.linalg.norm(base + columns @ weights) / max(np.linalg.norm(base), 1e-12))
    return inward + extra, residual
