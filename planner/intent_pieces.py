"""Collision pieces an instruction's intent adds to the grasp program of the proposals shaped
for it: Liftup's table under the object, Use's and Handover's keep-outs around what the hand
must leave free. None of them is a contact (GraspProgram.contacts(pieces=...))."""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from models.objects import ObjectModel
from models.objects.intents import RULES, Definition
from models.reproducible import rounded
from planner.intent import region_points
from planner.settings import IntentSettings

TABLE_GAP = 0.001  # m: the table's top above the object's lowest point (hand 1.5 mm above)


def table_under(obj: ObjectModel) -> np.ndarray:
    """The 8 corners of a 60 x 60 x 2 cm slab whose top is `TABLE_GAP` above the object's
    lowest point, centred under it: a collision piece for Liftup's grasp program."""
    src = obj.mesh.vertices if obj.mesh is not None else obj.points  # as planner.intent
    low, high = src.min(axis=0), src.max(axis=0)
    cx, cy = (low[:2] + high[:2]) / 2
    top = low[2] + TABLE_GAP
    corners = np.array([[x, y, z] for x in (-0.3, 0.3) for y in (-0.3, 0.3) for z in (-0.02, 0)])
    return rounded(corners + [cx, cy, top])


def keep_out(
    obj: ObjectModel, meaning: Definition, settings: IntentSettings | None = None
) -> list[np.ndarray]:
    """Collision pieces that keep the whole hand, not only the anchors the proposals place,
    clear of what the intent leaves free (none on an unlabelled object), as `settings` (None:
    the defaults) asks: for Use (`use_keep_out`) each working part (a cup's opening, a glass's
    bowl, a knife's blade) grown by the working clearance; for Handover (`handover_keep_out`)
    each other part grown by the other-part clearance, where that leaves at least the share
    `handover_keep_out_outside` of the held part outside (a knife's handle for its blade; not a
    cup's body, which grown by 2 cm swallows its rim), and none where together they leave less
    of it (a bottle's neck between its body and cap)."""
    settings = settings or IntentSettings()
    if not obj.labelled:
        return []
    if meaning.intent == "Use" and settings.use_keep_out:
        regions = [region_points(obj, r) for r in meaning.working]
        grown = [grown_hull(pts, RULES.use.working_clearance) for pts in regions]
        return [g for g in grown if g is not None]
    if meaning.intent != "Handover" or not settings.handover_keep_out:
        return []
    outside = settings.handover_keep_out_outside
    labels = obj.point_labels
    held = obj.points[labels == obj.part_names.index(meaning.part)]
    pieces, covered = [], np.zeros(len(held), dtype=bool)
    for i, name in enumerate(obj.part_names):
        if name == meaning.part:
            continue
        hull = grown_hull(obj.points[labels == i], RULES.handover.other_part_clearance)
        inside = None if hull is None else inside_hull(hull, held)
        if inside is not None and inside.mean() < 1 - outside:
            pieces.append(hull)
            covered |= inside
    # no room left on the held part between them (a bottle's neck between its body and cap):
    # the solves could not meet them, only spend SNOPT's iterations trying
    return pieces if covered.mean() < 1 - outside else []


_GROWTH = np.array([d for d in np.ndindex(3, 3, 3) if d != (1, 1, 1)], dtype=float) - 1
_GROWTH /= np.linalg.norm(_GROWTH, axis=1, keepdims=True)


def grown_hull(points: np.ndarray, grow: float) -> np.ndarray | None:
    """The corners of the points' convex hull grown by `grow` (each hull vertex moved along 26
    directions: at least 0.8 `grow` everywhere); None for fewer than 4 points."""
    if len(points) < 4:
        return None
    try:
        corners = points[ConvexHull(points).vertices]
    except QhullError:  # flat or degenerate: the points themselves
        corners = points
    grown = (corners[:, None, :] + grow * _GROWTH[None]).reshape(-1, 3)
    return rounded(grown[ConvexHull(grown).vertices])


def inside_hull(corners: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Mask of the points inside the convex hull of `corners`."""
    eq = ConvexHull(corners).equations
    return (points @ eq[:, :3].T + eq[:, 3] <= 0).all(axis=1)
