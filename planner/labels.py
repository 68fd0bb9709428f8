"""Which part a grasp touches: the voting rule of DESIGN.md."""

from __future__ import annotations

from collections import Counter

import numpy as np

VOTE_RADIUS = 0.05  # m: a fingertip farther than this from the object votes by part centroid


def fingertip_parts(
    tips: np.ndarray, points: np.ndarray, labels: np.ndarray, part_names: tuple[str, ...]
) -> list[str]:
    """Each fingertip's part: that of the nearest object point if closer than 5 cm, else the
    part whose centroid is nearest."""
    out = []
    centroids = {k: points[labels == k].mean(axis=0) for k in np.unique(labels)}
    for tip in np.asarray(tips):
        dist = np.linalg.norm(points - tip, axis=1)
        i = int(np.argmin(dist))
        if dist[i] < VOTE_RADIUS:
            out.append(part_names[labels[i]])
        else:
            k = min(centroids, key=lambda c: np.linalg.norm(centroids[c] - tip))
            out.append(part_names[k])
    return out


def voted_part(
    tips: np.ndarray, points: np.ndarray, labels: np.ndarray, part_names: tuple[str, ...]
) -> str:
    """The grasp's part: the majority over fingertips (ties go to the thumb-first order)."""
    votes = fingertip_parts(tips, points, labels, part_names)
    counts = Counter(votes)
    best = max(counts.values())
    return next(v for v in votes if counts[v] == best)


def grasp_part(hand, wrist: np.ndarray, q: np.ndarray, obj) -> str | None:
    """The part a hand configuration touches on a labelled object: `voted_part` of every
    fingertip at wrist [x, y, z, qw, qx, qy, qz] and joints q; None on an unlabelled object."""
    if not obj.labelled:
        return None
    import torch

    wrist_t = torch.tensor(np.asarray(wrist, dtype=np.float64)[None])
    q_t = torch.tensor(np.asarray(q, dtype=np.float64)[None])
    tips = hand.fingertip_positions(wrist_t, q_t)[0].numpy()
    return voted_part(tips, obj.points, obj.point_labels, obj.part_names)
