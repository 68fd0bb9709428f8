"""Point targets of one rigid link pooled into four points with the same cost.

The grasp program pulls hand surface points toward targets with one weighted position cost
per point (D(R,O) gives ShadowHand about 100 a solve, and every cost is evaluated, with its
Jacobian, at every SNOPT iteration). Where a link's targets are a rigid motion of its points
(D(R,O)'s targets are: multilateration + per-body Kabsch, learned.dro.place_hand), the summed
cost sum_i w_i |X(p_i) - X*(p_i)|^2 over the link's poses X depends on the points only through
their total weight, weighted mean and weighted covariance; four points with those moments (a
regular tetrahedron stretched by the covariance's square root) and the targets X*(q_j) give the
same cost for every pose. Links whose targets are not rigid within RIGID_TOLERANCE keep their
costs per point.

numpy only, no torch: the grasp program's solves run in forked processes (planner.parallel),
and torch in a child forked after the parent ran torch's OpenMP threads hangs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

RIGID_TOLERANCE = 1e-6  # m: largest residual of a link's targets from one rigid motion
# unit vertices of a regular tetrahedron: they sum to 0 and sum v v^T = 4/3 I
TETRAHEDRON = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]]) / np.sqrt(3.0)


@dataclass
class PointCosts:
    """Position costs for the grasp program: per cost, the hand surface point whose link it
    is on (`point`, an index into the hand's surface points), the point in that link's frame,
    its target (world) and its weight."""

    point: np.ndarray  # (K,) int
    local: np.ndarray  # (K, 3)
    targets: np.ndarray  # (K, 3)
    weights: np.ndarray  # (K,)


def pooled(
    link: np.ndarray,
    local: np.ndarray,
    index: np.ndarray,
    targets: np.ndarray,
    weights: np.ndarray,
) -> PointCosts:
    """The costs of the point targets `targets` (K, 3) with `weights` (K,) on the hand's
    surface points `index` (K,), whose links are `link[index]` and link-frame positions
    `local[index]`: four per link where the link has more than four targets that move
    rigidly, one per target elsewhere. Zero weights are dropped."""
    index, targets, weights = np.asarray(index), np.asarray(targets), np.asarray(weights)
    use = weights > 0
    index, targets, weights = index[use], targets[use], weights[use]
    out: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
    for k in np.unique(link[index]):
        on = np.flatnonzero(link[index] == k)
        p, t, w = local[index[on]], targets[on], weights[on]
        four = _four_points(p, t, w) if len(on) > 4 else None
        if four is None:
            out.append((index[on], p, t, w))
        else:
            q, qt = four
            out.append((np.full(4, index[on[0]]), q, qt, np.full(4, w.sum() / 4)))
    if not out:
        return PointCosts(np.zeros(0, int), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))
    return PointCosts(*(np.concatenate(parts) for parts in zip(*out, strict=True)))


def _rigid_motion(p: np.ndarray, t: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rotation and translation minimising sum w |R p + s - t|^2 (weighted Kabsch, a
    reflection turned into the nearest rotation), as learned.multilateration.kabsch computes
    it for batches in torch."""
    wn = w / max(float(w.sum()), 1e-12)
    cp, ct = wn @ p, wn @ t
    u, _, vt = np.linalg.svd((wn[:, None] * (p - cp)).T @ (t - ct))
    fix = np.ones(3)
    det = np.linalg.det(vt.T @ u.T)
    fix[2] = np.sign(det) + (det == 0)
    rot = vt.T @ (fix[:, None] * u.T)
    return rot, ct - rot @ cp


def _four_points(
    p: np.ndarray, t: np.ndarray, w: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """Four points with the weighted mean and covariance of `p` (N, 3) and their targets under
    the rigid motion carrying `p` onto `t`; None where no rigid motion does (within
    RIGID_TOLERANCE)."""
    rot, shift = _rigid_motion(p, t, w)
    if np.abs(p @ rot.T + shift - t).max() > RIGID_TOLERANCE:
        return None
    wn = w / w.sum()
    mean = wn @ p
    cov = (wn[:, None] * (p - mean)).T @ (p - mean)
    vals, vecs = np.linalg.eigh(cov)
    root = vecs @ np.diag(np.sqrt(3 * np.clip(vals, 0, None))) @ vecs.T
    q = mean + TETRAHEDRON @ root.T
    return q, q @ rot.T + shift
