"""Does a grasp do what its intent asks? `check_intent` measures a grasp against the intent
definitions of models.objects.intents (Use, Hold, Handover, Liftup) and says, per criterion,
what it measured and whether that passes.

Every measure is taken at the grasp configuration (the wrist and `Grasp.grasp` joints, where
the planner's contacts are; not the squeeze, which pushes the fingers on into the object, nor
the pregrasp): the hand's 512 fixed surface points (`hand.surface_points`), the points of each
fingertip's rigid body (the distal link carrying the hand.json fingertip), the palm frame of
hand.json (centre and outward normal, moved by the wrist), against the object's dense labelled
surface points and its centre of mass. Distances between sampled points are at most a few
millimetres longer than between the surfaces (the hand's points are 3-6 mm apart), which the
definitions' 1-2 cm margins absorb.

Imports: models, and planner.quality for the force-closure metric the planner itself uses
(numpy and scipy only; nothing of the planner's proposal or program code).
"""

from __future__ import annotations

import copy
import weakref
from collections.abc import Iterable
from dataclasses import asdict, dataclass, replace

import numpy as np
import torch
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from models.errors import InstructionError
from models.grasp import Grasp
from models.hands import HandModel
from models.objects import Instruction, ObjectModel, parse_instruction
from models.objects.intents import (
    RULES,
    Definition,
    FunctionalElement,
    Region,
    Rules,
    definition,
    resolve_fingers,
)
from planner.quality import contact_quality

# m: a hand touching the object at a surface point has one of its own surface points within
# this of it (the hand's 512 points are 3-6 mm apart; `unmeetable`)
TOUCH_REACH = 0.006


@dataclass(frozen=True)
class Criterion:
    """One sub-criterion: its measured value (metres, degrees or epsilon, as `limit` says),
    whether it passes, and a few words on what was measured."""

    name: str
    passed: bool
    value: float
    limit: str
    note: str = ""


@dataclass(frozen=True)
class IntentCheck:
    """The verdict on one grasp: ok when every criterion passes (an intent with nothing to
    measure on this object is ok), each criterion, and a short reason."""

    intent: str
    ok: bool
    criteria: tuple[Criterion, ...]
    reason: str

    def __getitem__(self, name: str) -> Criterion:
        for c in self.criteria:
            if c.name == name:
                return c
        raise KeyError(f"{self.intent} has no criterion {name!r}")

    def __contains__(self, name: str) -> bool:
        return any(c.name == name for c in self.criteria)

    def to_dict(self) -> dict:
        return {
            "intent": self.intent,
            "ok": self.ok,
            "reason": self.reason,
            # JSON has no infinity: an unmeasurable value ("no free end") is null
            "criteria": {
                c.name: asdict(c) | {"value": c.value if np.isfinite(c.value) else None}
                for c in self.criteria
            },
        }


# ---- object and hand facts, computed once ----------------------------------------------------
def mass_centre(obj: ObjectModel) -> np.ndarray:
    """The centre of mass at uniform density, as MuJoCo computes it for validation: the
    volume-weighted centroid of the construction pieces where the object has them, else of a
    watertight mesh, else the mean of the surface points (a bare cloud or an open mesh)."""
    if obj.construction_pieces is not None:
        pieces = obj.collision_pieces("construction")
        volumes = np.array([p.volume for p in pieces])
        centres = np.array([p.center_mass for p in pieces])
        return volumes @ centres / volumes.sum()
    if obj.mesh is not None and obj.mesh.is_watertight and obj.mesh.volume > 0:
        return np.asarray(obj.mesh.center_mass, dtype=float)
    return obj.points.mean(axis=0)


class _ObjectFacts:
    def __init__(self, obj: ObjectModel):
        self.points = obj.points
        self.normals = obj.normals
        self.labels = obj.point_labels
        self.part_names = obj.part_names
        self.tree = cKDTree(self.points)
        self.com = mass_centre(obj)
        src = obj.mesh.vertices if obj.mesh is not None else obj.points
        self.bottom = float(np.min(src[:, 2]))
        self._trees: dict = {}

    def mask(self, part: str) -> np.ndarray:
        return self.labels == self.part_names.index(part)

    def tree_of(self, key, points: np.ndarray) -> cKDTree:
        if key not in self._trees:
            self._trees[key] = cKDTree(points)
        return self._trees[key]

    def region(self, region: Region) -> np.ndarray:
        """The points of a working part or of its working end."""
        pts = self.points[self.mask(region.part)]
        if region.end is None:
            return pts
        if region.end == "free":
            others = self.points[~self.mask(region.part)]
            far, _ = self.tree_of(("not", region.part), others).query(pts)
            return pts[far >= far.max() - region.length]
        axis = "xyz".index(region.end[1])
        along = pts[:, axis] * (1.0 if region.end[0] == "+" else -1.0)
        return pts[along >= along.max() - region.length]

    def lobes(self, part: str) -> tuple[np.ndarray, np.ndarray]:
        """A part of two lobes (scissors loops) split in two by 2-means; of the splits started
        along each of the part's two main axes, the tighter one."""
        key = ("lobes", part)
        if key not in self._trees:
            pts = self.points[self.mask(part)]
            centre = pts.mean(axis=0)
            _, _, axes = np.linalg.svd(pts - centre, full_matrices=False)
            best = None
            for axis in axes[:2]:
                side = (pts - centre) @ axis > 0
                for _ in range(50):
                    if side.all() or not side.any():
                        break
                    a, b = pts[side].mean(axis=0), pts[~side].mean(axis=0)
                    new = np.linalg.norm(pts - a, axis=1) < np.linalg.norm(pts - b, axis=1)
                    if np.array_equal(new, side):
                        break
                    side = new
                if side.all() or not side.any():
                    continue
                spread = sum(
                    float(np.sum((s - s.mean(axis=0)) ** 2)) for s in (pts[side], pts[~side])
                )
                if best is None or spread < best[0]:
                    best = (spread, side)
            side = best[1] if best is not None else np.arange(len(pts)) < len(pts) // 2
            self._trees[key] = (pts[side], pts[~side])
        return self._trees[key]


class _HandFacts:
    def __init__(self, hand: HandModel):
        link_index, local = hand.surface
        rigid = np.array([hand.tree.rigid_link(n) for n in hand.link_names])[link_index]
        palm = hand.meta.palm
        self.palm_centre = np.asarray(palm.center, dtype=float)
        self.palm_normal = np.asarray(palm.normal, dtype=float) / np.linalg.norm(palm.normal)
        # the palm body's points and how far each lies behind the palm plane
        self.palm_body = rigid == hand.tree.rigid_link(hand.root_link)
        self.behind = -(local - self.palm_centre) @ self.palm_normal
        self.tip_points = {
            t.name: rigid == hand.tree.rigid_link(t.link) for t in hand.meta.fingertips
        }
        self.tip_names = [t.name for t in hand.meta.fingertips]
        self.roles = resolve_fingers(hand.meta.anchor_fingers, self.tip_names)
        self.rigid = rigid
        self.bodies = sorted(set(rigid))


_OBJECTS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
# a region's facts with its object's centre of mass and bottom (`_region_facts`): a copy of
# the region's own (`_object_facts` of it, as `unmeetable` and the keep-outs take them)
_REGIONS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_HANDS: dict[tuple[str, str], _HandFacts] = {}


def _object_facts(obj: ObjectModel) -> _ObjectFacts:
    if obj not in _OBJECTS:
        _OBJECTS[obj] = _ObjectFacts(obj)
    return _OBJECTS[obj]


def _region_facts(obj: ObjectModel, region: ObjectModel) -> _ObjectFacts:
    """The points and labels of `region` (a region object, or the object's points labelled by
    the interaction model) with the object's own centre of mass and lowest point: `region` is
    a bare cloud, whose point mean is not the mass centre of the object's mesh or pieces."""
    if region not in _REGIONS:
        # the region's own facts (its trees built once), with the object's mass centre and bottom
        facts, shape = copy.copy(_object_facts(region)), _object_facts(obj)
        facts.com, facts.bottom = shape.com, shape.bottom
        _REGIONS[region] = facts
    return _REGIONS[region]


def _hand_facts(hand: HandModel) -> _HandFacts:
    key = (str(hand.folder), hand.name)
    if key not in _HANDS:
        _HANDS[key] = _HandFacts(hand)
    return _HANDS[key]


@dataclass(frozen=True)
class _Config:
    """One hand configuration in the world."""

    wrist: np.ndarray  # [x, y, z, qw, qx, qy, qz]
    points: np.ndarray  # (512, 3) hand surface points
    tips: np.ndarray  # (F, 3) fingertip sphere centres, hand.json order
    palm_centre: np.ndarray
    palm_normal: np.ndarray  # outward


def _configure(hand: HandModel, facts: _HandFacts, wrist: np.ndarray, q: np.ndarray) -> _Config:
    w = torch.as_tensor(np.asarray(wrist, dtype=float)[None])
    qt = torch.as_tensor(np.asarray(q, dtype=float)[None])
    points = hand.surface_points(w, qt)[0].numpy()
    tips = hand.fingertip_positions(w, qt)[0].numpy()
    rot = Rotation.from_quat(np.asarray(wrist[3:7], dtype=float), scalar_first=True)
    return _Config(
        np.asarray(wrist, dtype=float),
        points,
        tips,
        rot.apply(facts.palm_centre) + np.asarray(wrist[:3], dtype=float),
        rot.apply(facts.palm_normal),
    )


# ---- the criteria ----------------------------------------------------------------------------
def _finger_on(
    of: _ObjectFacts, hf: _HandFacts, cfg: _Config, tip: str, part_points: np.ndarray
) -> float:
    """Distance (m) from a fingertip body's surface points to the part's points, counting only
    the finger's points whose nearest object point is on the part (the part, not another part
    in front of it, is what the finger touches there); inf when none is."""
    gap, nearest = of.tree.query(cfg.points[hf.tip_points[tip]])
    on = part_points[nearest]
    return float(np.min(gap[on])) if on.any() else float("inf")


def _element(
    of: _ObjectFacts, hf: _HandFacts, cfg: _Config, el: FunctionalElement, rules: Rules
) -> Criterion:
    limit = f"<= {rules.use.finger_contact * 1000:.0f} mm"
    mask = of.mask(el.part)
    missing = [r for r in el.fingers if r not in hf.roles]
    if missing:
        return Criterion(
            "finger_on_element", False, float("inf"), limit, f"the hand has no {missing} finger"
        )
    if el.rule == "split":
        return _split(of, hf, cfg, el, rules, limit)
    per_role = {
        role: min(_finger_on(of, hf, cfg, tip, mask) for tip in hf.roles[role])
        for role in el.fingers
    }
    value = max(per_role.values()) if el.rule == "all" else min(per_role.values())
    passed = value <= rules.use.finger_contact
    what = el.what or el.part
    words = ", ".join(f"{r} {_mm(d)}" for r, d in per_role.items())
    join = " and " if el.rule == "all" else " or "
    note = f"{join.join(el.fingers)} on the {what}: {words}"
    return Criterion("finger_on_element", passed, value, limit, note)


def _split(of, hf, cfg, el, rules, limit) -> Criterion:
    """Thumb in (or on) one lobe, another finger in (or on) the other."""
    lobe_a, lobe_b = of.lobes(el.part)
    thumbs = hf.roles["thumb"]
    others = hf.roles["fingers"]

    def dist(tip: str, lobe: np.ndarray, key: str) -> float:
        tree = of.tree_of(("lobe", el.part, key), lobe)
        return float(np.min(tree.query(cfg.points[hf.tip_points[tip]])[0]))

    def through(tip: str, lobe: np.ndarray) -> bool:
        """The fingertip centre within the lobe's hole (approximately: the hole about the
        lobe's centroid, as wide as its nearest point to that centroid)."""
        centre = lobe.mean(axis=0)
        _, _, axes = np.linalg.svd(lobe - centre, full_matrices=False)
        normal = axes[2]
        inner = float(
            np.min(
                np.linalg.norm((lobe - centre) - np.outer((lobe - centre) @ normal, normal), axis=1)
            )
        )
        x = cfg.tips[hf.tip_names.index(tip)] - centre
        depth = float(x @ normal)
        radial = float(np.linalg.norm(x - depth * normal))
        return abs(depth) <= rules.use.loop_depth and radial < inner

    t_a = min(dist(t, lobe_a, "a") for t in thumbs)
    t_b = min(dist(t, lobe_b, "b") for t in thumbs)
    f_a = min(dist(t, lobe_a, "a") for t in others)
    f_b = min(dist(t, lobe_b, "b") for t in others)
    value = min(max(t_a, f_b), max(t_b, f_a))
    threaded = any(
        any(through(t, la) for t in thumbs) and any(through(t, lb) for t in others)
        for la, lb in ((lobe_a, lobe_b), (lobe_b, lobe_a))
    )
    passed = threaded or value <= rules.use.finger_contact
    how = (
        "thumb and a finger through the two loops"
        if threaded
        else "thumb on one loop, a finger on the other"
    )
    return Criterion("finger_on_element", passed, value, limit, f"{how}: {_mm(value)}")


def _working(of: _ObjectFacts, cfg: _Config, regions: Iterable[Region], rules: Rules) -> Criterion:
    limit = f">= {rules.use.working_clearance * 1000:.0f} mm"
    gaps = {}
    for r in regions:
        tree = of.tree_of(("region", r), of.region(r))
        gaps[r.what] = float(np.min(tree.query(cfg.points)[0]))
    worst = min(gaps, key=gaps.get)
    value = gaps[worst]
    note = ", ".join(f"{w} {_mm(d)}" for w, d in gaps.items()) + " from the hand"
    return Criterion(
        "working_parts_clear", value >= rules.use.working_clearance, value, limit, note
    )


def _palm(of, hf, cfg, part, rules) -> Criterion:
    rule = rules.hold
    limit = f"<= {rule.palm_contact * 1000:.0f} mm where the part is >= {rule.palm_min_width * 100:.0f} cm wide"
    pts = of.points[of.mask(part)]
    centre = pts.mean(axis=0)
    _, _, axes = np.linalg.svd(pts - centre, full_matrices=False)
    width = float(np.max(np.ptp((pts - centre) @ axes[1:].T, axis=0)))
    tree = of.tree_of(("part", part), pts)
    face = hf.palm_body & (hf.behind <= rule.palm_face_depth)
    gap = float(np.min(tree.query(cfg.points[face])[0]))
    if width < rule.palm_min_width:
        return Criterion(
            "palm_contact",
            True,
            gap,
            limit,
            f"the {part} is {width * 100:.1f} cm wide: too narrow for the palm, not required",
        )
    return Criterion(
        "palm_contact",
        gap <= rule.palm_contact,
        gap,
        limit,
        f"palm {_mm(gap)} from the {part} ({width * 100:.1f} cm wide)",
    )


def contacts(
    of: _ObjectFacts, hf: _HandFacts, cfg: _Config, distance: float
) -> tuple[np.ndarray, np.ndarray]:
    """Contacts of a configuration, about as the planner's Drake program finds them (one per
    touching hand geometry and object piece): one per hand body and object part that come
    within `distance`, at the object point nearest to that body, pushed along the inward
    normal there."""
    gap, nearest = of.tree.query(cfg.points)
    close = gap <= distance
    points, inward = [], []
    for body in hf.bodies:
        mine = np.flatnonzero((hf.rigid == body) & close)
        labels = of.labels[nearest[mine]]
        for label in np.unique(labels):
            same = mine[labels == label]
            k = same[np.argmin(gap[same])]
            points.append(of.points[nearest[k]])
            inward.append(-of.normals[nearest[k]])
    return np.asarray(points).reshape(-1, 3), np.asarray(inward).reshape(-1, 3)


def _closure(of, hf, cfg, rules) -> Criterion:
    rule = rules.hold
    pts, inward = contacts(of, hf, cfg, rule.contact_distance)
    eps = contact_quality(pts, inward, of.com, mu=rule.friction).epsilon if len(pts) else -1.0
    return Criterion(
        "force_closure",
        eps >= rule.min_epsilon,
        float(eps),
        f">= {rule.min_epsilon:.3g}",
        f"epsilon {eps:.3f} from {len(pts)} contacts",
    )


def _others_clear(of, cfg, part, rules) -> Criterion:
    rule = rules.handover
    others = ~of.mask(part)
    limit = f">= {rule.other_part_clearance * 1000:.0f} mm"
    if not others.any():
        return Criterion("other_parts_clear", True, float("inf"), limit, "no other part")
    tree = of.tree_of(("not", part), of.points[others])
    gap, idx = tree.query(cfg.points)
    k = int(np.argmin(gap))
    closest = of.part_names[of.labels[np.flatnonzero(others)[idx[k]]]]
    value = float(gap[k])
    return Criterion(
        "other_parts_clear",
        value >= rule.other_part_clearance,
        value,
        limit,
        f"hand {_mm(value)} from the {closest}",
    )


def _away(of, cfg, part, receiver, rules) -> Criterion:
    rule = rules.handover
    limit = f"<= {rule.max_side_offset * 1000:.0f} mm toward the free end"
    held = of.points[of.mask(part)].mean(axis=0)
    free_mask = np.isin(of.labels, [of.part_names.index(p) for p in receiver])
    if not free_mask.any():
        return Criterion("away_from_free_end", True, float("-inf"), limit, "no free end")
    toward = of.points[free_mask].mean(axis=0) - held
    toward /= np.linalg.norm(toward)
    value = float((cfg.palm_centre - held) @ toward)
    side = "toward" if value > 0 else "away from"
    return Criterion(
        "away_from_free_end",
        value <= rule.max_side_offset,
        value,
        limit,
        f"palm {_mm(abs(value))} {side} the {'/'.join(receiver)} side of the {part}'s centre",
    )


def _liftup(of, cfg, rules) -> list[Criterion]:
    rule = rules.liftup
    above = float(cfg.wrist[2] - of.com[2])
    tilt = float(np.degrees(np.arccos(np.clip(-cfg.palm_normal[2], -1.0, 1.0))))
    low = float(np.min(cfg.points[:, 2]) - of.bottom)
    return [
        Criterion(
            "wrist_above_com",
            above >= rule.wrist_above_com,
            above,
            f">= {rule.wrist_above_com * 1000:.0f} mm",
            f"wrist {_mm(abs(above))} {'above' if above >= 0 else 'below'} the centre of mass",
        ),
        Criterion(
            "palm_down",
            tilt <= rule.max_palm_tilt_deg,
            tilt,
            f"<= {rule.max_palm_tilt_deg:g} deg",
            f"palm normal {tilt:.0f} deg from straight down",
        ),
        Criterion(
            "above_table",
            low >= -rule.table_tolerance,
            low,
            f">= {-rule.table_tolerance * 1000:.0f} mm",
            f"lowest hand point {_mm(abs(low))} {'above' if low >= 0 else 'below'} the object's bottom",
        ),
    ]


def _mm(d: float) -> str:
    return "none" if not np.isfinite(d) else f"{d * 1000:.0f} mm"


# ---- entry points ----------------------------------------------------------------------------
def intent_definition(obj: ObjectModel, instruction: Instruction | str) -> Definition:
    """The definition an instruction asks of this object (its category's, where the object
    or the instruction names a library category; else the intent's generic criteria). On an
    object without part labels only intents measured on the shape alone (Liftup) have one."""
    ins = parse_instruction(instruction) if isinstance(instruction, str) else instruction
    from models.objects.intents import CRITERIA, label_free

    if not obj.labelled:
        if label_free(ins.intent):  # Liftup: the shape alone decides
            return Definition(ins.category or obj.name, ins.intent, ins.part, CRITERIA[ins.intent])
        raise InstructionError(
            f"{ins.intent} checks need a part-labelled object (only "
            f"{', '.join(i for i in CRITERIA if label_free(i))} can be checked without labels)"
        )
    if ins.part not in obj.part_names:
        raise InstructionError(
            f"part {ins.part!r} is not a part of this object; its parts are {', '.join(obj.part_names)}"
        )
    cat = ins.category or obj.category
    from models.objects.library import CATEGORIES

    if cat in CATEGORIES and tuple(CATEGORIES[cat].parts) == tuple(obj.part_names):
        return definition(cat, ins.intent, ins.part)
    # not a library object: no functional elements or working parts are known
    others = tuple(p for p in obj.part_names if p != ins.part)
    crit = () if ins.intent == "Use" else CRITERIA[ins.intent]
    return Definition(cat or obj.name, ins.intent, ins.part, crit, receiver=others)


def region_points(obj: ObjectModel, region: Region) -> np.ndarray:
    """The object's surface points of a working part or of its working end (a Use rule's
    `Region`), as the Use check measures them."""
    return _object_facts(obj).region(region)


def region_definition(region: ObjectModel, instruction: Instruction | str) -> Definition:
    """The definition of the instruction's intent with the region (an object whose first part
    is the region the learned samples point at, planner.learned_proposer.region_object)
    standing in for the instructed part: the generic criteria of the intent, no category's
    elements (models.objects.intents.region_checked says which intents this measures)."""
    ins = parse_instruction(instruction) if isinstance(instruction, str) else instruction
    ins = replace(ins, part=region.part_names[0], category=None)
    return intent_definition(region, ins)


def _kept_clear(
    of: _ObjectFacts, meaning: Definition, rules: Rules
) -> tuple[list[cKDTree], float, str] | None:
    """What the definition keeps clear of the whole hand (Handover's other parts, Use's working
    parts) as the trees its checks measure with (`_others_clear`, `_working`, cached per
    object), the clearance it asks and their names; None where it keeps nothing clear."""
    if meaning.part not in of.part_names or not of.mask(meaning.part).any():
        return None
    if meaning.intent == "Handover":
        others = ~of.mask(meaning.part)
        if not others.any():
            return None
        present = sorted(set(of.labels[others].tolist()))
        names = " and ".join(f"the {of.part_names[k]}" for k in present)
        trees = [of.tree_of(("not", meaning.part), of.points[others])]
        return trees, rules.handover.other_part_clearance, names
    if meaning.intent == "Use" and meaning.working:
        names = " and ".join(f"the {r.what}" for r in meaning.working)
        trees = [of.tree_of(("region", r), of.region(r)) for r in meaning.working]
        return trees, rules.use.working_clearance, names
    return None


def unmeetable(obj: ObjectModel, meaning: Definition, rules: Rules = RULES) -> str | None:
    """Why no grasp touching the instructed part can meet the definition on this object, or
    None where one might. A hand touching the part at a surface point has a surface point of
    its own within TOUCH_REACH of it, so where every point of the part lies nearer than a
    clearance less TOUCH_REACH to a part the definition keeps clear (Handover's other parts,
    Use's working parts), every such grasp fails it: a cup's or a bowl's rim is 7-8 mm deep,
    and Handover asks 2 cm. Planning stops searching for such an intent once a grasp holds on
    the part. On an object without the part's labels: None."""
    if not obj.labelled:
        return None
    of = _object_facts(obj)
    kept = _kept_clear(of, meaning, rules)
    if kept is None:
        return None
    trees, clearance, names = kept
    part = of.points[of.mask(meaning.part)]
    # how far the part's point farthest from everything kept clear lies from it
    depth = float(np.min([tree.query(part)[0] for tree in trees], axis=0).max())
    if depth + TOUCH_REACH >= clearance:
        return None
    return (
        f"{meaning.intent} cannot be met on the {meaning.part}: every point of it lies within "
        f"{_mm(depth)} of {names}, so no hand touching it keeps every point {_mm(clearance)} "
        f"from {'them' if ' and ' in names else 'it'} as the definition asks"
    )


def proposal_misses(
    wrist: np.ndarray,
    anchors: np.ndarray,
    obj: ObjectModel,
    hand: HandModel,
    meaning: Definition,
    labels: ObjectModel | None,
    anchor_share: float,
    tilt_margin_deg: float = 0.0,
    height_margin: float = 0.0,
    rules: Rules = RULES,
) -> str | None:
    """Why a proposal, as drawn (before its solve), will not meet the definition, or None
    where it might: a fingertip placed on an anchor nearer a part the definition keeps clear
    than `anchor_share` of the clearance it asks (Handover's 2 cm, Use's 1 cm) is deep inside
    it, and a wrist that fails a criterion the wrist and the palm rigid with it decide (Liftup's
    palm down, above the centre of mass; Handover's palm away from the free end) is rarely turned
    by a solve that starts there, by more than its margin (`tilt_margin_deg` beyond Liftup's
    palm tilt, `height_margin` below its wrist height: drawn near them, a solve sometimes
    turns them). `labels`: the labelled object the definition is measured on
    (the object itself or the interaction model's labels; None: nothing that needs labels is
    checked). For the search after a grasp held off its intent (planner.schedule):
    a guide to what is worth solving, not a verdict."""
    if labels is not None and labels.labelled:
        of = _object_facts(labels)
        kept = _kept_clear(of, meaning, rules)
        if kept is not None:
            trees, clearance, names = kept
            placed = np.asarray(anchors, dtype=float)
            placed = placed[np.isfinite(placed).all(axis=1)]  # a pinch's free finger: NaN
            gap = min((float(t.query(placed)[0].min()) for t in trees), default=np.inf)
            if len(placed) and gap < anchor_share * clearance:
                return f"an anchor lies {_mm(gap)} from {names} ({_mm(clearance)} asked)"
    from models.objects.intents import PALM_CRITERIA, label_free

    drawn = PALM_CRITERIA & set(meaning.criteria)
    if drawn and (label_free(meaning.intent) or (labels is not None and labels.labelled)):
        if labels is None or labels is obj:
            of = _object_facts(obj)
        else:  # the guessed labels, about the object's own mass centre
            of = _region_facts(obj, labels)
        lift = rules.liftup
        lenient = replace(
            rules,
            liftup=replace(
                lift,
                max_palm_tilt_deg=lift.max_palm_tilt_deg + tilt_margin_deg,
                wrist_above_com=lift.wrist_above_com - height_margin,
            ),
        )
        failed = _fails_as_drawn(wrist, hand, meaning, of, drawn, lenient)
        if failed:
            return f"the drawn wrist fails {', '.join(failed)}"
    return None


def _fails_as_drawn(
    wrist: np.ndarray,
    hand: HandModel,
    meaning: Definition,
    of: _ObjectFacts,
    names: Iterable[str],
    rules: Rules,
) -> list[str]:
    """Which of the criteria `names` the open hand at this wrist pose fails: those the wrist
    decides are known before the solve (`faces_intent`, `proposal_misses`)."""
    hf = _hand_facts(hand)
    cfg = _configure(hand, hf, np.asarray(wrist, dtype=float), hand.open_pose)
    check = _evaluate(meaning, of, hf, cfg, rules)
    return [c.name for c in check.criteria if c.name in names and not c.passed]


def check_configuration(
    wrist: np.ndarray,
    q: np.ndarray,
    obj: ObjectModel,
    hand: HandModel,
    instruction: Instruction | str,
    rules: Rules = RULES,
    region: ObjectModel | None = None,
    labels: ObjectModel | None = None,
) -> IntentCheck:
    """`check_intent` on a bare configuration: wrist [x, y, z, qw, qx, qy, qz] and joints (for
    solved candidates that were never validated). On an object without labels, `region`: the
    region object that stands in for the part (`region_definition`), or `labels`: the
    object's points with part labels guessed for them (planner.model_labels), on which the
    definition is measured. Either way the object's own centre of mass and lowest point are
    kept (Hold's epsilon is taken about the centre of mass)."""
    if region is not None:
        d, of = region_definition(region, instruction), _region_facts(obj, region)
    elif labels is not None:
        d, of = intent_definition(labels, instruction), _region_facts(obj, labels)
    else:
        d, of = intent_definition(obj, instruction), _object_facts(obj)
    hf = _hand_facts(hand)
    cfg = _configure(hand, hf, np.asarray(wrist, dtype=float), np.asarray(q, dtype=float))
    return _evaluate(d, of, hf, cfg, rules)


def faces_intent(
    wrist: np.ndarray, obj: ObjectModel, hand: HandModel, instruction: Instruction | str
) -> bool:
    """Whether a wrist pose meets every criterion of the instruction's definition that the
    wrist alone decides (models.objects.intents.WRIST_CRITERIA: Liftup's wrist above the
    centre of mass and palm down); True where the definition has none. For ordering drawn
    samples before they are solved."""
    from models.objects.intents import WRIST_CRITERIA

    meaning = intent_definition(obj, instruction)
    return not _fails_as_drawn(wrist, hand, meaning, _object_facts(obj), WRIST_CRITERIA, RULES)


def _evaluate(
    d: Definition, of: _ObjectFacts, hf: _HandFacts, cfg: _Config, rules: Rules
) -> IntentCheck:
    """Every criterion of a definition on one configuration."""
    crits: list[Criterion] = []
    if d.intent == "Use":
        crits += [_element(of, hf, cfg, e, rules) for e in d.elements]
        if d.working:
            crits.append(_working(of, cfg, d.working, rules))
    elif d.intent == "Hold":
        crits += [_palm(of, hf, cfg, d.part, rules), _closure(of, hf, cfg, rules)]
    elif d.intent == "Handover":
        crits += [_others_clear(of, cfg, d.part, rules), _away(of, cfg, d.part, d.receiver, rules)]
    else:
        crits += _liftup(of, cfg, rules)
    failed = [c for c in crits if not c.passed]
    if not crits:
        reason = f"{d.intent}: nothing to measure on this object"
    elif failed:
        reason = "; ".join(f"{c.name}: {c.note} (needs {c.limit})" for c in failed)
    else:
        reason = f"{d.intent} ok: " + "; ".join(c.note for c in crits)
    return IntentCheck(d.intent, not failed, tuple(crits), reason)


def check_intent(
    grasp: Grasp,
    obj: ObjectModel,
    hand: HandModel,
    instruction: Instruction | str | None = None,
    rules: Rules = RULES,
) -> IntentCheck:
    """Measure a grasp against its intent's definition (models.objects.intents).

    grasp: a Grasp record of this hand; the grasp configuration is measured (wrist and
    `grasp.grasp` joints). instruction: parsed or text; default the grasp's own instruction.
    Hold's force closure is the epsilon metric of planner.quality (friction 0.6, about the
    centre of mass) on one contact per hand body and object part within 1 cm of the hand's
    surface points (`contacts`).
    """
    if instruction is None:
        instruction = grasp.instruction
    if not instruction:
        raise InstructionError("the grasp records no instruction; pass one to check_intent")
    hand.check_joints(np.asarray(grasp.grasp), "grasp joints")
    wrist = np.concatenate([grasp.wrist_pos, grasp.wrist_quat])
    return check_configuration(wrist, grasp.grasp, obj, hand, instruction, rules)


__all__ = [
    "Criterion",
    "IntentCheck",
    "check_configuration",
    "check_intent",
    "contacts",
    "faces_intent",
    "intent_definition",
    "mass_centre",
    "proposal_misses",
    "region_definition",
    "region_points",
    "unmeetable",
]
