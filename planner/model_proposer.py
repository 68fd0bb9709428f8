"""The model-based proposer: a part-labelled object + the instructed part -> proposals.

The instructed part's points are analysed (principal axes), the thumb is put on one side of the
part and the three other anchor fingers on the opposite side, spread along the part's long
axis at the hand's own finger spacing, with the palm facing the part from every direction
around that axis. Anchors keep off the part's border with other parts, and where the hand
cannot span the part the thumb pinches its near edge from across. With an intent's definition
the proposals are shaped for it (Liftup from above, Handover and Use clear of the parts the
hand must leave free, Hold palm first). Proposals whose anchors give the best force closure
come first.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np
import torch
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from models.errors import PlanningError
from models.hands import HandModel, load_hand
from models.objects import ObjectModel
from models.objects.intents import RULES, Definition
from models.reproducible import rounded, rounded_within
from planner.grasp_program import anchored
from planner.intent import region_points
from planner.quality import contact_quality
from planner.results import Proposal
from planner.settings import PlannerSettings

# Where the model-based proposals start the fingers: the open pose closed this fraction of each
# joint's range (HandModel.closed_pose)
HALF_CLOSURE = 0.35


@dataclass(frozen=True)
class _Shape:
    """Where proposals go: the part's points anchors may use, the (palm direction, finger row
    axis, row sign) frames, the point whose position along the row axis the anchors centre on
    (None: the object's centre of mass) and how much anchors favour the part's side nearest
    the palm (ModelProposer._proposal's `toward_palm`)."""

    away: np.ndarray
    frames: list[tuple]
    target: np.ndarray | None = None
    toward_palm: float = 0.0
    palm_first: bool = False  # Hold: power grasps with the palm on the part (_palm_first)
    # proposals from this shape and by part alone in turn (ModelProposer.propose): where
    # the intent's proposals all slip, the part still gets a grasp
    mix: bool = False
    # the regular and pinch proposals of this shape differ from those by part alone
    shaped_rows: bool = False


class HandGeometry:
    """Facts about a hand used to place proposals, computed once from its files."""

    def __init__(self, hand: HandModel):
        self.hand = hand
        self.q_half = rounded_within(hand.closed_pose(HALF_CLOSURE), hand.lower, hand.upper)
        names = list(hand.meta.anchor_fingers)
        identity = torch.tensor([[0, 0, 0, 1.0, 0, 0, 0]], dtype=torch.float64)
        half = hand.fingertip_positions(identity, torch.tensor(self.q_half[None]), names)[0].numpy()
        opened = hand.fingertip_positions(identity, torch.tensor(hand.open_pose[None]), names)[0]
        opened = opened.numpy()
        n = hand.meta.palm.normal
        lateral = opened[-1] - opened[1]  # first to last non-thumb anchor finger
        lateral -= n * (lateral @ n)
        self.lateral = lateral / np.linalg.norm(lateral)
        # thumb -> fingers across the grasped part: off the finger row and the palm normal
        thumb_to_fingers = opened[1:].mean(axis=0) - opened[0]
        across = np.cross(n, self.lateral)
        self.opposition = across * np.sign(thumb_to_fingers @ across)
        self.normal = n
        self.half_tips = half  # anchor fingertips at the half-closed pose, in the wrist frame
        self.spacing = float(np.mean(np.linalg.norm(np.diff(opened[1:], axis=0), axis=1)))
        # the widest thumb-finger fingertip distance of the half-closed pose
        self.span = float(np.max(np.linalg.norm(half[1:] - half[0], axis=1)))
        self.tip_radii = np.array([hand.meta.fingertip(n).radius for n in names])


class ModelProposer:
    """Proposals on part-labelled objects for one hand (the planner's "model" proposer)."""

    def __init__(self, hand: HandModel | str, settings: PlannerSettings | None = None):
        self.hand = hand if isinstance(hand, HandModel) else load_hand(hand)
        self.settings = settings or PlannerSettings()

    @cached_property
    def geometry(self) -> HandGeometry:
        return HandGeometry(self.hand)

    # ---- proposals ------------------------------------------------------------------------
    def propose(
        self, obj: ObjectModel, part: str, intent: Definition | None = None
    ) -> list[Proposal]:
        """Wrist poses and anchors on `part`, best first; shaped by the intent's definition
        where one is given and `intent.aware` is set (`_Shape`)."""
        points, normals, labels = obj.points, obj.normals, obj.point_labels
        mask = labels == obj.part_names.index(part)
        pts, nrm = points[mask], normals[mask]
        if len(pts) < 8:
            raise PlanningError(
                f"part {part!r} has only {len(pts)} surface points; cannot place anchors"
            )
        centre = pts.mean(axis=0)
        _, _, axes = np.linalg.svd(pts - centre, full_matrices=False)
        e1, e2, e3 = _canonical_axes(axes)
        geo = self.geometry
        tree = cKDTree(points)
        palm_on_thin = self.settings.proposals.palm_on_thin_parts
        if palm_on_thin is None:
            palm_on_thin = self.hand.meta.palm_on_thin_parts
        # a palm target unless the planner does without, or the part is too thin for this hand
        with_palm = self.settings.proposals.use_palm and (
            palm_on_thin or not self._thin(pts - centre, e2, e3)
        )
        # Anchors sit on the part as near the object's centre of mass as the part allows: a
        # handle held at its far end lets gravity twist a knife or pan out of the fingers.
        com = points.mean(axis=0)
        plain = _Shape(self._away_from_border(points[~mask], pts), self._frames(e1, e2, e3))
        shape = plain
        if intent is not None and self.settings.intent.aware:
            shape = self._shape(obj, mask, intent, plain, (e1, e2, e3))
        pinches = self.settings.proposals.pinch_proposals
        if pinches is None:
            pinches = self.hand.meta.pinch_proposals

        def build(shape: _Shape) -> tuple[list[Proposal], list[Proposal], list[Proposal]]:
            """Regular, pinch and palm-first proposals of every frame of `shape`."""
            rows, pinch, palm = [], [], []
            for v, axis, lateral_sign in shape.frames:
                rot, _ = Rotation.align_vectors(
                    [v, lateral_sign * axis], [geo.normal, geo.lateral], weights=[10, 1]
                )
                u = rounded(rot.apply(geo.opposition))  # thumb -> fingers, in the world
                t = (pts - centre) @ axis
                if shape.target is not None:
                    t_mass = float((shape.target - centre) @ axis)
                else:
                    t_mass = (
                        float((com - centre) @ axis)
                        if self.settings.proposals.mass_centred
                        else 0.0
                    )
                spacing = min(geo.spacing, max(np.ptp(t) / 3, 0.005))
                frame = (pts, nrm, t, shape.away, t_mass, centre, rot, u, v, axis)
                rows.append(self._proposal(*frame, spacing, tree, with_palm, shape.toward_palm))
                if shape.palm_first:
                    palm.append(
                        self._palm_first(pts, nrm, shape.away, t_mass, centre, rot, v, axis, tree)
                    )
                if pinches:
                    # the two pinch fingers sit closer together than a row's ends, in the part
                    pinch_spacing = min(geo.spacing, max(np.ptp(t) / 2, 0.005))
                    pinch.append(
                        self._proposal(
                            *frame, pinch_spacing, tree, with_palm, shape.toward_palm, pinch=True
                        )
                    )
            for proposal in rows + pinch:
                proposal.shaped = shape.shaped_rows
            return rows, pinch, palm

        rows, pinch, palm = build(shape)
        # Pinches come after every regular proposal: mixed into their ranking by anchor closure
        # they did worse for every hand on the val replays (docs/planner_log.md "Pinch proposals").
        pinch = self._ordered(pinch, com)[:pinches]
        most = self.settings.proposals.max_proposals
        if palm:  # Hold: power grasps and regular proposals in turn
            rows = _alternate(self._ordered(palm, com), self._ordered(rows, com))
        elif shape.mix:  # the intent's proposals and proposals by part alone in turn
            rows = _alternate(self._ordered(rows, com), self._ordered(build(plain)[0], com))
        else:
            rows = self._ordered(rows, com)
        return rows[:most] + pinch

    def _frames(self, e1: np.ndarray, e2: np.ndarray, e3: np.ndarray) -> list[tuple]:
        """(palm -> object direction, finger row axis, row sign): the palm facing the part from
        every `approach_step_deg` around its long axis, the finger row along it either way."""
        frames = []
        for theta in np.deg2rad(np.arange(0, 360, self.settings.proposals.approach_step_deg)):
            v = rounded(np.cos(theta) * e2 + np.sin(theta) * e3)
            frames += [(v, e1, 1.0), (v, e1, -1.0)]
        return frames

    def _liftup_frames(self, e1: np.ndarray, e2: np.ndarray) -> list[tuple]:
        """Liftup: the palm facing down (straight, and tilted by `liftup_tilt_deg` at
        `liftup_azimuths` azimuths), the finger row along the part's long axis as seen from
        above and at 45-degree steps from it."""
        s = self.settings.intent
        down = np.array([0.0, 0.0, -1.0])
        return _cap_frames(down, s.liftup_tilt_deg, s.liftup_azimuths, e1, e2)

    def _shape(
        self,
        obj: ObjectModel,
        mask: np.ndarray,
        intent: Definition,
        shape: _Shape,
        axes: tuple[np.ndarray, np.ndarray, np.ndarray],
    ) -> _Shape:
        """Proposals for the intent's definition (models/objects/intents.py).

        Use: anchors a fingertip's width beyond the working clearance from the working parts.
        Handover: anchors 2 cm plus a fingertip's width from every other part (or 1 cm short of
        the part's farthest point from them, where it is smaller: a bottle's neck), toward the
        part's end away from the receiver's parts, and the palm on the side away from them:
        beyond that end, facing them, where the allowed points fit in the hand's span
        (`intent.handover_end_on`).
        Liftup: the palm facing down, anchors within `liftup_reach` below the part's top,
        `intent.liftup_toward_palm` up from the part's widest points. Hold: power grasps with
        the palm on the part (where it is as wide as the Hold rule asks) beside the regular
        proposals, all solved with Hold's program."""
        pts = obj.points[mask]
        tip = float(np.mean(self.geometry.tip_radii))
        away = shape.away

        def clear_of(others: np.ndarray, distance: float) -> np.ndarray:
            if len(others) == 0:
                return away
            gap, _ = cKDTree(others).query(pts)
            keep = away & (gap >= min(distance, float(gap.max()) - 0.01))
            return keep if keep.sum() >= 8 else away

        if intent.intent == "Use" and intent.working:
            working = np.vstack([region_points(obj, r) for r in intent.working])
            away = clear_of(working, RULES.use.working_clearance + tip)
            return _Shape(away, shape.frames, shaped_rows=True)
        if intent.intent == "Handover":
            others = obj.points[~mask]
            away = clear_of(others, RULES.handover.other_part_clearance + tip)
            free = np.isin(obj.point_labels, [obj.part_names.index(p) for p in intent.receiver])
            if not free.any():
                return _Shape(away, shape.frames, mix=True, shaped_rows=True)
            held = pts.mean(axis=0)
            toward = obj.points[free].mean(axis=0) - held
            toward /= np.linalg.norm(toward)
            # the anchors' centre at the allowed points' far end from the receiver
            far = pts[away][np.argmin(pts[away] @ toward)]
            target = held + ((far - held) @ toward) * toward
            frames = [f for f in shape.frames if f[0] @ toward >= -0.2] or shape.frames
            end_on = self.settings.intent.handover_end_on
            if end_on != "off" and _width_across(pts[away], toward) <= self.geometry.span:
                # the palm beyond the held part's far end, facing the receiver's parts: the
                # whole hand then stays on the held part's side (a pen's cap, a knife's blade,
                # a hammer's head); only where the allowed points fit between thumb and fingers
                tilt = self.settings.intent.liftup_tilt_deg
                cap = _cap_frames(toward, tilt, self.settings.intent.liftup_azimuths, *axes[:2])
                frames = cap if end_on == "only" else frames + cap
            return _Shape(away, frames, target=target, mix=True, shaped_rows=True)
        if intent.intent == "Liftup":
            height = pts[:, 2]
            if np.ptp(height) > self.settings.intent.liftup_reach:
                upper = away & (height >= height.max() - self.settings.intent.liftup_reach)
                away = upper if upper.sum() >= 8 else away
            frames = self._liftup_frames(axes[0], axes[1])
            toward_palm = self.settings.intent.liftup_toward_palm
            return _Shape(away, frames, toward_palm=toward_palm, mix=True, shaped_rows=True)
        if intent.intent == "Hold":
            offsets = pts - pts.mean(axis=0)
            width = max(np.ptp(offsets @ axes[1]), np.ptp(offsets @ axes[2]))
            # palm contact is asked where the part is as wide as the Hold rule says; every Hold
            # proposal is solved with Hold's program (the palm pulled onto its target)
            return replace(
                shape, palm_first=bool(width >= RULES.hold.palm_min_width), shaped_rows=True
            )
        return shape

    def _ordered(self, proposals: list[Proposal], com: np.ndarray) -> list[Proposal]:
        """Best anchor force closure first: on 150 train pairs with every candidate validated,
        the top quarter of proposals by anchor epsilon held 30-70% of the time (bottom quarter
        5-9%), while the palm-clearance score did not predict holding (docs/planner_log.md,
        "Proposal order")."""
        if self.settings.proposals.proposal_order == "anchors":
            for p in proposals:  # about 5 ms each (a 6-D hull of 24 cone edges)
                used = anchored(p.anchors)
                p.anchor_quality = rounded(
                    contact_quality(p.anchors[used], -p.normals[used], com).epsilon
                )
            # stable: ties keep order
            return sorted(proposals, key=lambda p: (-p.anchor_quality, -p.score))
        return sorted(proposals, key=lambda p: -p.score)

    def _thin(self, offsets: np.ndarray, e2: np.ndarray, e3: np.ndarray) -> bool:
        """Is the part narrower across its long axis than an anchor fingertip is wide?"""
        width = 2 * float(np.mean(self.geometry.tip_radii))
        return max(np.ptp(offsets @ e2), np.ptp(offsets @ e3)) < width

    def _away_from_border(self, others: np.ndarray, pts: np.ndarray) -> np.ndarray:
        """Mask of the part's points that anchors may use: `border_margin` from every other
        part's points (or half the largest such distance on a part narrower than that)."""
        if len(others) == 0:
            return np.ones(len(pts), dtype=bool)
        border, _ = cKDTree(others).query(pts)
        return border >= min(self.settings.proposals.border_margin, 0.5 * float(border.max()))

    def _palm_first(self, pts, nrm, away, t_mass, centre, rot, v, axis, tree) -> Proposal:
        """A power grasp for Hold: the palm centre `palm_margin` off the part's near side
        (across from the part's centre of mass along the row axis), and the anchors where the
        half-closed fingertips then are, snapped to the part's allowed points."""
        geo = self.geometry
        t = (pts - centre) @ axis
        line = centre + float(np.clip(t_mass, t.min(), t.max())) * axis
        off_axis = (pts - line) - np.outer((pts - line) @ v, v)
        near_line = np.linalg.norm(off_axis, axis=1) < 0.015
        if not near_line.any():
            near_line = np.ones(len(pts), dtype=bool)
        nearest = pts[near_line][np.argmin(pts[near_line] @ v)]
        palm_target = nearest - v * self.settings.proposals.palm_margin
        position = palm_target - rot.apply(np.asarray(self.hand.meta.palm.center, dtype=float))
        tips = rot.apply(geo.half_tips) + position
        allowed = np.flatnonzero(away)
        _, snap = cKDTree(pts[allowed]).query(tips)
        chosen = allowed[snap]
        anchors, normals = pts[chosen], nrm[chosen]
        palm_clear = min(
            float(tree.query(palm_target - v * self.settings.proposals.approach_clearance)[0]), 0.1
        )
        wrist = np.concatenate([position, rot.as_quat(scalar_first=True)])
        return Proposal(
            rounded(wrist),
            geo.q_half.copy(),
            rounded(anchors),
            rounded(normals),
            rounded(palm_clear),
            rounded(palm_target),
            kind="palm",
            shaped=True,
        )

    def _proposal(
        self,
        pts,
        nrm,
        t,
        away,
        t_mass,
        centre,
        rot,
        u,
        v,
        axis,
        spacing,
        tree,
        with_palm,
        toward_palm=0.0,
        pinch=False,
    ) -> Proposal:
        geo = self.geometry
        lateral_sign = np.sign(rot.apply(geo.lateral) @ axis) or 1.0
        half_width = max(0.006, 0.15 * (t.max() - t.min()))
        t_mid = (
            float(np.clip(t_mass, t.min() + spacing, t.max() - spacing))
            if np.ptp(t) > 2 * spacing
            else 0.0
        )

        def extreme(t_at: float, direction: np.ndarray, toward_palm: float = toward_palm) -> int:
            gap = np.where(away, np.abs(t - t_at), np.inf)
            near = gap < half_width
            if not near.any():
                near = gap <= gap.min() + 1e-9
            idx = np.flatnonzero(near)
            # rounded, so that points level to within a nanometre tie the same way everywhere
            height = rounded(pts[idx] @ direction - toward_palm * (pts[idx] @ v))
            return int(idx[np.argmax(height)])

        def fingers(toward_palm: float = toward_palm) -> list[int]:
            steps = (-0.5, 0.5) if pinch else (-1, 0, 1)
            offsets = [t_mid + k * lateral_sign * spacing for k in steps]
            return [extreme(t_at, u, toward_palm) for t_at in offsets]

        chosen = [extreme(t_mid, -u), *fingers()]
        span = np.linalg.norm(pts[chosen[1:]].mean(axis=0) - pts[chosen[0]])
        if span > self.settings.proposals.span_factor * geo.span:
            row = fingers(toward_palm=1.0)
            thumb = _across(pts, nrm, away, pts[row[1]], -u)
            if thumb is not None:
                chosen = [thumb, *row]
        anchors, normals = pts[chosen], nrm[chosen]
        n_used = len(chosen)
        centres = anchors + normals * geo.tip_radii[:n_used, None]
        position = centres.mean(axis=0) - rot.apply(geo.half_tips[:n_used].mean(axis=0))
        free = np.full((len(geo.tip_radii) - n_used, 3), np.nan)  # a pinch's free fingers
        anchors, normals = np.vstack([anchors, free]), np.vstack([normals, free])
        palm = centres.mean(axis=0) - v * self.settings.proposals.approach_clearance
        clearance = min(float(tree.query(palm)[0]), 0.1)
        mid = pts[chosen].mean(axis=0)
        outward = float(-v @ (mid - centre))
        wrist = np.concatenate([position, rot.as_quat(scalar_first=True)])
        # the palm rests on the part's near side, behind the anchors: an enclosing grasp
        off_axis = (pts - mid) - np.outer((pts - mid) @ v, v)
        near_line = np.linalg.norm(off_axis, axis=1) < 0.015
        palm_target = None
        if with_palm and near_line.any():
            nearest = pts[near_line][np.argmin(pts[near_line] @ v)]
            palm_target = nearest - v * self.settings.proposals.palm_margin
        score = clearance + 0.1 * outward
        # rounded: proposals are the same on every machine (models.reproducible)
        return Proposal(
            rounded(wrist),
            geo.q_half.copy(),  # rounded once, in HandGeometry
            rounded(anchors),
            rounded(normals),
            rounded(score),
            None if palm_target is None else rounded(palm_target),
            kind="pinch" if pinch else "row",
        )


def _cap_frames(
    direction: np.ndarray, tilt_deg: float, azimuths: int, e1: np.ndarray, e2: np.ndarray
) -> list[tuple]:
    """Frames with the palm facing `direction` (palm -> object; straight, and tilted by
    `tilt_deg` at `azimuths` azimuths around it), the finger row along e1 (or e2, where e1 is
    nearly along the palm direction) as seen along it and at 45-degree steps from that."""
    direction = direction / np.linalg.norm(direction)
    # the tilts' azimuth 0 toward world x (for straight down: x, then y)
    side, other = _plane_basis(direction)
    dirs = [direction]
    tilt = np.deg2rad(tilt_deg)
    for k in range(azimuths if tilt > 0 else 0):
        a = 2 * np.pi * k / azimuths
        dirs.append(
            np.cos(tilt) * direction + np.sin(tilt) * (np.cos(a) * side + np.sin(a) * other)
        )
    frames = []
    for v in dirs:
        v = rounded(v)
        base = next(
            (b - (b @ v) * v for b in (e1, e2) if np.linalg.norm(b - (b @ v) * v) > 0.5),
            np.cross(v, [1.0, 0.0, 0.0]),
        )
        base = base / np.linalg.norm(base)
        for turn in np.deg2rad([0.0, 45.0, 90.0, 135.0]):
            axis = rounded(Rotation.from_rotvec(turn * v).apply(base))  # perpendicular to v
            frames += [(v, axis, 1.0), (v, axis, -1.0)]
    return frames


def _plane_basis(direction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors spanning the plane perpendicular to the unit `direction`: world x
    projected into it (world y where the direction is near x), then that turned a right angle
    about `-direction`."""
    ref = np.array([1.0, 0.0, 0.0]) if abs(direction[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    a = ref - (ref @ direction) * direction
    a /= np.linalg.norm(a)
    return a, np.cross(a, direction)


def _width_across(points: np.ndarray, direction: np.ndarray, steps: int = 12) -> float:
    """The points' largest extent across the unit `direction` (within 1.5% of it: the widest
    of `steps` directions in the plane perpendicular to it)."""
    a, b = _plane_basis(direction)
    angles = np.linspace(0.0, np.pi, steps, endpoint=False)
    dirs = np.outer(np.cos(angles), a) + np.outer(np.sin(angles), b)
    return float(np.ptp(points @ dirs.T, axis=0).max())


def _alternate(a: list[Proposal], b: list[Proposal]) -> list[Proposal]:
    """a[0], b[0], a[1], b[1], ...: every window of the ranking holds both kinds (a batch of
    two solves one of each; a dataset variant's window of four, two of each)."""
    out = [x for pair in zip(a, b, strict=False) for x in pair]
    return out + a[len(b) :] + b[len(a) :]


def _across(
    pts: np.ndarray, nrm: np.ndarray, allowed: np.ndarray, origin: np.ndarray, direction: np.ndarray
) -> int | None:
    """The first allowed surface point facing `direction` on the ray from `origin` along it
    (within 1 cm of the ray): where a thumb opposing a finger at `origin` presses back."""
    d = pts - origin
    s = d @ direction
    off = np.linalg.norm(d - np.outer(s, direction), axis=1)
    hit = allowed & (s > 0.002) & (off < 0.01) & (nrm @ direction > 0.3)
    if not hit.any():
        return None
    idx = np.flatnonzero(hit)
    return int(idx[np.argmin(rounded(s[idx]))])


def _canonical_axes(axes: np.ndarray) -> np.ndarray:
    """Principal axes (rows) with a fixed sign, each one's largest component positive, and
    rounded: LAPACK may return either sign, and which one depends on the CPU's kernels."""
    signs = np.sign(axes[np.arange(len(axes)), np.argmax(np.abs(axes), axis=1)])
    return rounded(axes * signs[:, None])
