"""The model-based functional planner: part-labelled object + instruction -> validated grasp.

Until the learned priors exist this is how a wrist pose and anchors are proposed: the
instructed part's points are analysed (principal axes), the thumb is put on one side of the
part and the three other anchor fingers on the opposite side, spread along the part's long
axis at the hand's own finger spacing, with the palm facing the part from every direction
around that axis. Anchors keep off the part's border with other parts, and where the hand
cannot span the part the thumb pinches its near edge from across. Proposals whose anchors give
the best force closure are solved first; each
goes through the Drake grasp program and MuJoCo validation. Solved candidates are validated
best first (force-closure quality of their contacts), and the first grasp that holds and
touches the instructed part is returned with every candidate's outcome.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any

import numpy as np
import torch
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from models.errors import InstructionError, PlanningError
from models.grasp import Grasp
from models.hands import HandModel, load_hand
from models.objects import INTENTS, Instruction, ObjectModel, load_object, parse_instruction
from models.objects.intents import RULES, Definition
from models.reproducible import rounded, rounded_within
from planner.grasp_program import (
    GraspProgram,
    GraspTargets,
    ProgramSettings,
    SolveResult,
    anchored,
    grasp_program,
)
from planner.intent import IntentCheck, check_configuration, intent_definition, region_points
from planner.labels import voted_part
from planner.quality import contact_quality
from planner.schedule import run_schedule
from planner.validation import validate


@dataclass(frozen=True)
class PlannerSettings:
    max_candidates: int = 8  # grasps validated at most (the costly step)
    max_proposals: int = 16  # wrist poses + anchors solved at most
    approach_step_deg: float = 45.0  # approach directions around the part's long axis
    protocol: str = "paper"
    approach_clearance: float = 0.06  # m from the anchors' centre to test the palm's free space
    palm_margin: float = 0.004  # m between the palm target and the part's near surface
    # anchors keep this far (m) from the instructed part's border with other parts, or half the
    # part's widest border distance where the part is smaller: the outermost points of a bowl's
    # body lie just below its rim, and grasps there voted "rim" though they held
    border_margin: float = 0.005
    # anchors planned farther apart (thumb to the fingers' mean) than this many times the
    # hand's half-closed thumb-finger span cannot be reached (a pan's body, 17-19 cm across):
    # the fingers then go to the part's side nearest the palm and the thumb straight across
    # the part from them, pinching its near edge or wall
    span_factor: float = 1.25
    # May proposals on parts thinner than an anchor fingertip (pens, knife handles) carry a palm
    # target? None: as the hand's hand.json `palm_on_thin_parts` says (default true; false for
    # Allegro, docs/planner_log.md "No palm target on thin parts").
    palm_on_thin_parts: bool | None = None
    use_palm: bool = True
    # pinch proposals (thumb and the next two anchor fingers, the last anchor finger free)
    # solved after the max_proposals regular ones; None: as the hand's hand.json
    # `pinch_proposals` says (default 0; 8 for LEAP, docs/planner_log.md "Pinch proposals")
    pinch_proposals: int | None = None
    # proposals solved before the best of them are validated. With the anchor-closure order the
    # first proposals are the likeliest to hold, so small batches waste fewer solves: on the 300
    # test pairs 2 vs 4 gave the same returned rates, first-candidate 65/69/68% vs 70/70/68%
    # and 6.3/7.8/7.9 vs 7.6/8.8/9.1 solves per returned grasp (1: 62/69/70%, 5.9/7.3/7.6).
    solve_batch: int = 2
    # epsilon below this: validated only when nothing better is left. Weak force closure
    # (0.02-0.1) mostly slips and used up the validations before a later batch's strong
    # candidates were reached (mug handles); 0.1 vs 0.02 on the 100 Allegro and LEAP test pairs
    # of `--objects-per-category 1`: returned success 82/76% vs 74/72%.
    min_quality: float = 0.1
    # ... but only for the first `gate_solves` solves: after them the weak candidates join the
    # validation queue (best task metric first) instead of waiting until every proposal is
    # solved. Replayed on all-validated records of the validation split, 6 vs never gave
    # returned success 85/95/95% vs 86/93/93% with 4.1/5.1/4.0 vs 6.7/7.9/7.2 solves per
    # returned grasp (docs/planner_log.md, "Gate on the first solves").
    gate_solves: int = 6
    # After this many validations without a grasp that holds on the part, every remaining
    # proposal is solved before the next validation (even in the middle of a batch's queue), so
    # the rest of the `max_candidates` go to the best of all of them (task metric) instead of
    # to whichever batch comes next. Replayed on all-validated records of the validation split,
    # 3 gave 94/95/100% held on the part against 93/95/99% at 4 and 86/93/95% without a sweep
    # (docs/planner_log.md, "Sweep after failed validations").
    # None: batch by batch to the end.
    sweep_after: int | None = 3
    contact_distance: float = 0.006  # m: hand geometry this close to the object counts as contact
    # Validate every candidate within max_candidates instead of stopping at the first grasp that
    # holds on the part: solves are already paid for, so each extra validation is the cheapest
    # way to another grasp (dataset generation keeps them all, see PlanResult.holding).
    validate_all: bool = False
    mass_centred: bool = True  # anchors near the object's centre of mass along the part
    ranking: str = "task"  # validation order: "task" or "epsilon" (planner.quality)
    # solve order of the proposals: "anchors" (force closure of the planned anchors, best
    # first) or "clearance" (free space for the palm, the earlier order)
    proposal_order: str = "anchors"
    # Shape proposals by the instruction's intent (models/objects/intents.py): Liftup from
    # above, Handover and Use with anchors kept off the parts the hand must leave free, and
    # validate candidates whose solved configuration meets the intent first (planner.schedule).
    # False: proposals by part alone, as before the intent definitions.
    intent_aware: bool = True
    # validations in which candidates meeting the intent go first; then by quality alone
    intent_first: int = 4
    # after a grasp held on the part but missed its intent: proposals solved at most to find
    # one that meets it (None: all of them). On the 150 test pairs of `--objects-per-category
    # 1`, 4 gave 65/49/66% (allegro/leap/shadow) of the grasps held on the part meeting their
    # intent; searching every proposal (before the by-part proposals were added in turn),
    # 83/65/77% (docs/intent_log.md)
    intent_search: int | None = None
    # Liftup: palm directions (palm -> object) tilted this far from straight down, besides
    # straight down, at `liftup_azimuths` azimuths
    liftup_tilt_deg: float = 20.0
    liftup_azimuths: int = 4
    # Liftup: anchors lie this far (m) below the part's top at most, where it is taller: fingers
    # reaching down from above
    liftup_reach: float = 0.045
    # The grasp program's weights per intent (ProgramSettings field -> value), over `program`:
    # Hold pulls the palm onto its target harder (palm contact), Liftup keeps the proposal's
    # palm-down wrist rotation
    intent_program: tuple[tuple[str, str, float], ...] = (
        ("Hold", "palm_weight", 200.0),
        ("Liftup", "wrist_rotation_weight", 1.0),
    )
    # Liftup: the grasp program keeps the hand above a table slab under the object (the
    # definition: no hand point below the object's lowest point); the table is no contact
    liftup_table: bool = True
    # Where proposals come from: "model" (the geometric proposer of this module: needs part
    # labels and a "[Intent] a [Object] by [Part]" instruction), "learned" (interaction
    # diffusion -> D(R,O), planner.learned_proposer: any cloud, any sentence) or "auto": model
    # where the object has part labels and the instruction parses, learned otherwise. The model-based proposer stays the default for labelled input until the learned
    # one beats it in `python -m eval.benchmark` (README, "Learned stages").
    proposer: str = "auto"
    learned_samples: int = 8  # interaction samples (proposals) the learned proposer draws
    learned_dro: bool = True  # D(R,O) point targets in the program (False: wrist + anchors)
    learned_seed: int = 0  # the samples' seed: the same seed, the same proposals
    learned_guidance: float | None = None  # classifier-free guidance; None: the model's own
    program: ProgramSettings = field(default_factory=ProgramSettings)

    def __post_init__(self) -> None:
        if self.ranking not in RANKINGS:
            raise PlanningError(f"unknown ranking {self.ranking!r}; use one of {RANKINGS}")
        if self.pinch_proposals is not None and self.pinch_proposals < 0:
            raise PlanningError(f"pinch_proposals must be 0 or more, got {self.pinch_proposals}")
        if self.proposal_order not in PROPOSAL_ORDERS:
            raise PlanningError(
                f"unknown proposal_order {self.proposal_order!r}; use one of {PROPOSAL_ORDERS}"
            )
        if not 0 <= self.liftup_tilt_deg < 60 or self.liftup_azimuths < 0:
            raise PlanningError(
                "liftup_tilt_deg must be in [0, 60) and liftup_azimuths 0 or more, got "
                f"{self.liftup_tilt_deg} and {self.liftup_azimuths}"
            )
        for intent, name, _ in self.intent_program:
            if intent not in INTENTS or name not in ProgramSettings.__dataclass_fields__:
                raise PlanningError(
                    f"intent_program entry ({intent!r}, {name!r}): expected an intent of "
                    f"{INTENTS} and a ProgramSettings field"
                )
        if self.intent_first < 0 or (self.intent_search is not None and self.intent_search < 0):
            raise PlanningError(
                "intent_first and intent_search must be 0 or more (intent_search None: no "
                f"limit), got {self.intent_first} and {self.intent_search}"
            )
        if self.proposer not in PROPOSERS:
            raise PlanningError(f"unknown proposer {self.proposer!r}; use one of {PROPOSERS}")
        if self.liftup_reach <= 0:
            raise PlanningError(f"liftup_reach must be positive, got {self.liftup_reach}")


RANKINGS = ("task", "epsilon")
PROPOSERS = ("auto", "model", "learned")
PROPOSAL_ORDERS = ("anchors", "clearance")


@dataclass
class Proposal:
    wrist: np.ndarray  # [x, y, z, qw, qx, qy, qz]
    q: np.ndarray
    anchors: np.ndarray  # (4, 3) in anchor-finger order
    normals: np.ndarray  # (4, 3)
    score: float  # free space for the palm plus outwardness: breaks anchor-quality ties
    palm_target: np.ndarray | None = None
    # epsilon (planner.quality) of the anchors pushing along their inward normals, about the
    # object's centre of mass: the solve order, best first (set with proposal_order="anchors")
    anchor_quality: float = -1.0
    # "row": thumb against a row of the other anchor fingers; "pinch": thumb and the next
    # two anchor fingers, the last one free; "palm": a power grasp, palm first (Hold)
    kind: str = "row"
    # placed for the instruction's intent (not by part alone): solved with the intent's
    # program settings (`intent_program`) and, for Liftup, above a table
    shaped: bool = False
    # targets for hand surface points (learned proposals: D(R,O) after multilateration), with
    # their weights (GraspTargets.point_targets); None: none
    point_index: np.ndarray | None = None
    point_targets: np.ndarray | None = None
    point_weights: np.ndarray | None = None


@dataclass
class CandidateResult:
    rank: int
    proposal: Proposal
    solve: SolveResult
    grasp: Grasp | None = None
    success: bool = False
    part: str | None = None
    validation: dict[str, Any] | None = None
    quality: float = -1.0  # epsilon (force-closure) quality of the solved contacts
    task_quality: float = -1.0  # largest test force the contacts resist (planner.quality)
    order: int | None = None  # position in the validation order, if validated
    times: dict[str, float] = field(default_factory=dict)
    # the solved configuration against the instruction's intent (planner.intent); None when
    # not checked (unsolved, or planned without intent awareness)
    intent: IntentCheck | None = None

    @property
    def intent_ok(self) -> bool | None:
        return None if self.intent is None else self.intent.ok

    def summary(self) -> dict[str, Any]:
        return {
            "rank": self.rank,
            "kind": self.proposal.kind,
            "solved": self.solve.ok,
            "intent_ok": self.intent_ok,
            "intent_failed": (
                None
                if self.intent is None
                else [c.name for c in self.intent.criteria if not c.passed]
            ),
            "solve_message": self.solve.message,
            "success": self.success,
            "part": self.part,
            "quality": self.quality,
            "task_quality": self.task_quality,
            "validated_as": self.order,
            "pregrasp_penetration_mm": (
                None if self.validation is None else 1000 * self.validation["pregrasp_penetration"]
            ),
            "anchor_error_mm": 1000 * self.solve.anchor_error,
            "min_distance_mm": 1000 * self.solve.min_distance,
            # the recorded squeeze: the hand's, or the retry's where only that one held
            "squeeze_depth": None if self.grasp is None else self.grasp.metrics["squeeze_depth"],
            "times": self.times,
        }


@dataclass
class PlanResult:
    instruction: Instruction
    hand: str
    grasp: Grasp | None
    candidates: list[CandidateResult]
    notes: list[str] = field(default_factory=list)
    proposer: str = "model"  # where the proposals came from: "model" or "learned"
    # how the sentence was read (learned.understand.Understood.to_dict); None: parsed as given
    understood: dict[str, Any] | None = None

    @property
    def best(self) -> CandidateResult | None:
        """The candidate whose grasp is returned; None when no grasp is (unvalidated
        candidates also have no grasp, so they must not match)."""
        if self.grasp is None:
            return None
        return next((c for c in self.candidates if c.grasp is self.grasp), None)

    @property
    def success(self) -> bool:
        return self.best is not None and self.best.success

    @property
    def holding(self) -> list[CandidateResult]:
        """Every validated candidate that held and touched the instructed part, in validation
        order (the returned grasp first). On an unlabelled object (no part voted) every
        validated candidate that held."""
        held = [c for c in self.candidates if c.success and c.part in (self.instruction.part, None)]
        return sorted(held, key=lambda c: c.order if c.order is not None else -1)

    @property
    def part_touched(self) -> str | None:
        return None if self.best is None else self.best.part

    @property
    def intent_ok(self) -> bool | None:
        """Does the returned grasp meet its intent's definition (None: no grasp, or not
        checked)?"""
        return None if self.best is None else self.best.intent_ok

    def stage_times(self) -> dict[str, float]:
        total: dict[str, float] = {}
        for c in self.candidates:
            for k, v in c.times.items():
                total[k] = total.get(k, 0.0) + v
        return total

    def summary(self) -> dict[str, Any]:
        best = self.best
        return {
            "instruction": self.instruction.text,
            "hand": self.hand,
            "success": self.success,
            "proposer": self.proposer,
            "understood": self.understood,
            "part_instructed": self.instruction.part,
            "part_touched": self.part_touched,
            "intent_ok": self.intent_ok,
            "intent": None if best is None or best.intent is None else best.intent.reason,
            "anchor_error_mm": None if best is None else 1000 * best.solve.anchor_error,
            "candidates_solved": len(self.candidates),
            "candidates_validated": sum(c.order is not None for c in self.candidates),
            "chosen_rank": None if best is None else best.rank,
            "chosen_kind": None if best is None else best.proposal.kind,
            "chosen_validated_as": None if best is None else best.order,
            "chosen_squeeze_depth": None if best is None else best.grasp.metrics["squeeze_depth"],
            "times_s": self.stage_times(),
            "notes": self.notes,
        }


@dataclass(frozen=True)
class _Shape:
    """Where proposals go: the part's points anchors may use, the (palm direction, finger row
    axis, row sign) frames, the point whose position along the row axis the anchors centre on
    (None: the object's centre of mass) and how much anchors favour the part's side nearest
    the palm (FunctionalPlanner._proposal's `toward_palm`)."""

    away: np.ndarray
    frames: list[tuple]
    target: np.ndarray | None = None
    toward_palm: float = 0.0
    palm_first: bool = False  # Hold: power grasps with the palm on the part (_palm_first)
    # proposals from this shape and by part alone in turn (FunctionalPlanner.propose): where
    # the intent's proposals all slip, the part still gets a grasp
    mix: bool = False
    # the regular and pinch proposals of this shape differ from those by part alone
    shaped_rows: bool = False


class HandGeometry:
    """Facts about a hand used to place proposals, computed once from its files."""

    def __init__(self, hand: HandModel):
        self.hand = hand
        closing = hand.closing_direction
        span = hand.upper - hand.lower
        self.q_half = rounded_within(hand.open_pose + 0.35 * closing * span, hand.lower, hand.upper)
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


class FunctionalPlanner:
    """Plans functional grasps on part-labelled objects for one hand."""

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
        where one is given and `intent_aware` is set (`_Shape`)."""
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
        palm_on_thin = self.settings.palm_on_thin_parts
        if palm_on_thin is None:
            palm_on_thin = self.hand.meta.palm_on_thin_parts
        # a palm target unless the planner does without, or the part is too thin for this hand
        with_palm = self.settings.use_palm and (
            palm_on_thin or not self._thin(pts - centre, e2, e3)
        )
        # Anchors sit on the part as near the object's centre of mass as the part allows: a
        # handle held at its far end lets gravity twist a knife or pan out of the fingers.
        com = points.mean(axis=0)
        plain = _Shape(self._away_from_border(points[~mask], pts), self._frames(e1, e2, e3))
        shape = plain
        if intent is not None and self.settings.intent_aware:
            shape = self._shape(obj, mask, intent, plain, (e1, e2, e3))
        pinches = self.settings.pinch_proposals
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
                    t_mass = float((com - centre) @ axis) if self.settings.mass_centred else 0.0
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
        most = self.settings.max_proposals
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
        for theta in np.deg2rad(np.arange(0, 360, self.settings.approach_step_deg)):
            v = rounded(np.cos(theta) * e2 + np.sin(theta) * e3)
            frames += [(v, e1, 1.0), (v, e1, -1.0)]
        return frames

    def _liftup_frames(self, e1: np.ndarray, e2: np.ndarray) -> list[tuple]:
        """Liftup: the palm facing down (straight, and tilted by `liftup_tilt_deg` at
        `liftup_azimuths` azimuths), the finger row along the part's long axis as seen from
        above and at 45-degree steps from it."""
        s = self.settings
        down = np.array([0.0, 0.0, -1.0])
        dirs = [down]
        tilt = np.deg2rad(s.liftup_tilt_deg)
        for k in range(s.liftup_azimuths if tilt > 0 else 0):
            a = 2 * np.pi * k / s.liftup_azimuths
            dirs.append(
                np.array([np.sin(tilt) * np.cos(a), np.sin(tilt) * np.sin(a), -np.cos(tilt)])
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
                axis = rounded(
                    Rotation.from_rotvec(turn * v).apply(base)
                )  # stays perpendicular to v
                frames += [(v, axis, 1.0), (v, axis, -1.0)]
        return frames

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
        part's end away from the receiver's parts, and the palm on the side away from them.
        Liftup: the palm facing down, anchors within `liftup_reach` below the part's top and
        on the part's upper side. Hold: power grasps with the palm on the part (where it is
        as wide as the Hold rule asks) beside the regular proposals, all solved with Hold's
        program."""
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
            return _Shape(away, frames, target=target, mix=True, shaped_rows=True)
        if intent.intent == "Liftup":
            height = pts[:, 2]
            if np.ptp(height) > self.settings.liftup_reach:
                upper = away & (height >= height.max() - self.settings.liftup_reach)
                away = upper if upper.sum() >= 8 else away
            frames = self._liftup_frames(axes[0], axes[1])
            return _Shape(away, frames, toward_palm=0.5, mix=True, shaped_rows=True)
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
        if self.settings.proposal_order == "anchors":
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
        return border >= min(self.settings.border_margin, 0.5 * float(border.max()))

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
        palm_target = nearest - v * self.settings.palm_margin
        position = palm_target - rot.apply(np.asarray(self.hand.meta.palm.center, dtype=float))
        tips = rot.apply(geo.half_tips) + position
        allowed = np.flatnonzero(away)
        _, snap = cKDTree(pts[allowed]).query(tips)
        chosen = allowed[snap]
        anchors, normals = pts[chosen], nrm[chosen]
        palm_clear = min(
            float(tree.query(palm_target - v * self.settings.approach_clearance)[0]), 0.1
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
        if span > self.settings.span_factor * geo.span:
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
        palm = centres.mean(axis=0) - v * self.settings.approach_clearance
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
            palm_target = nearest - v * self.settings.palm_margin
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

    # ---- planning -------------------------------------------------------------------------
    def plan(self, obj: ObjectModel, instruction: Instruction | str) -> PlanResult:
        """Try proposals in order; return the first grasp that holds and touches the part.

        The proposals come from the model-based proposer of this module or from the learned
        stages (planner.learned_proposer), as `settings.proposer` says; solving, the schedule
        and validation are the same for both."""
        text = instruction if isinstance(instruction, str) else instruction.text
        if self.proposer_for(obj, instruction) == "learned":
            return self._plan_learned(obj, text)
        if isinstance(instruction, str):
            instruction = parse_instruction(instruction)
        part = instruction.part
        if not obj.labelled:
            raise PlanningError(
                "the object has no part labels, so the model-based planner cannot find the "
                f"{part!r}; give labelled input (--part-labels) or a library object, or plan "
                "with the learned proposer (--proposer learned, PlannerSettings(proposer="
                '"learned"))'
            )
        if part not in obj.part_names:
            raise InstructionError(
                f"part {part!r} is not a part of this object; its parts are {', '.join(obj.part_names)}"
            )
        start = time.perf_counter()
        meaning = intent_definition(obj, instruction) if self.settings.intent_aware else None
        program = grasp_program(self.hand, obj.collision_pieces(), self.settings.program)
        build = time.perf_counter() - start
        proposals = self.propose(obj, part, meaning)
        propose_time = time.perf_counter() - start - build
        shaped_program, table_top = program, None
        if meaning is not None and any(p.shaped for p in proposals):
            shaped_program, table_top = self._intent_program(obj, meaning)
            build = time.perf_counter() - start - propose_time
        times = {"build": build, "propose": propose_time}
        programs = (program, shaped_program, table_top)
        return self._run(obj, instruction, part, meaning is not None, proposals, programs, times)

    def proposer_for(self, obj: ObjectModel, instruction: Instruction | str) -> str:
        """The proposer to use, "model" or "learned": `settings.proposer`, with "auto"
        resolved: model where the object has part labels and the instruction parses (a part
        the object lacks is then the user's error, said by the model-based planner), learned
        otherwise."""
        if self.settings.proposer != "auto":
            return self.settings.proposer
        if not obj.labelled:
            return "learned"
        if isinstance(instruction, str):
            try:
                parse_instruction(instruction)
            except InstructionError:
                return "learned"
        return "model"

    def _plan_learned(self, obj: ObjectModel, text: str) -> PlanResult:
        """Plan on the learned stages' proposals. The sentence is read as the nearest table
        instruction (learned.understand); its part is what the grasp must touch, and its
        intent is checked, only where the object has part labels that name that part: on an
        unlabelled cloud a grasp that holds is success."""
        from learned.understand import understand
        from planner.learned_proposer import anchor_closure, learned_proposals

        s = self.settings
        start = time.perf_counter()
        understood = understand(text)
        instruction = understood.instruction
        known = obj.labelled and instruction.part in obj.part_names
        part = instruction.part if known else None
        program = grasp_program(self.hand, obj.collision_pieces(), s.program)
        build = time.perf_counter() - start
        drawn = learned_proposals(
            obj,
            text,
            self.hand,
            s.learned_samples,
            s.learned_seed,
            s.learned_guidance,
            s.learned_dro,
        )
        proposals = []
        for i in range(len(drawn.wrists)):
            target = drawn.targets[i]
            proposals.append(
                Proposal(
                    rounded(drawn.wrists[i]),
                    self.hand.open_pose.astype(np.float64).copy(),
                    rounded(drawn.anchors[i]),
                    rounded(drawn.normals[i]),
                    0.0,
                    anchor_quality=anchor_closure(drawn.anchors[i], drawn.normals[i], obj),
                    kind="learned",
                    point_index=None if target is None else target.index,
                    point_targets=None if target is None else rounded(target.targets),
                    point_weights=None if target is None else target.weights,
                )
            )
        proposals.sort(key=lambda p: -p.anchor_quality)  # stable: sample order breaks ties
        times = {"build": build, **drawn.times}
        result = self._run(
            obj,
            instruction,
            part,
            known and s.intent_aware,
            proposals,
            (program, program, None),
            times,
        )
        result.understood = understood.to_dict()
        result.proposer = "learned"
        return result

    def _run(
        self,
        obj: ObjectModel,
        instruction: Instruction,
        part: str | None,
        check_intent: bool,
        proposals: list[Proposal],
        programs: tuple[GraspProgram, GraspProgram, float | None],
        times: dict[str, float],
    ) -> PlanResult:
        """Solve, schedule and validate the proposals (planner.schedule). `programs`: the
        program, the one for proposals shaped by the intent, and that one's table top; `times`
        (building and proposing) go to the first candidate. `part` None: any part counts."""
        notes = []
        program, shaped_program, table_top = programs

        def program_of(rank: int) -> GraspProgram:
            return shaped_program if proposals[rank].shaped else program

        def solve(rank: int) -> CandidateResult:
            proposal = proposals[rank]
            top = table_top if proposal.shaped else None
            cand = self._solve(program_of(rank), obj, rank, proposal, top)
            if rank == 0:
                cand.times.update(times)
            if check_intent and cand.solve.ok:
                t0 = time.perf_counter()
                cand.intent = check_configuration(
                    cand.solve.wrist, cand.solve.q, obj, self.hand, instruction
                )
                cand.times["intent"] = time.perf_counter() - t0
            return cand

        def validate(cand: CandidateResult) -> None:
            self._validate(program_of(cand.rank), obj, instruction, cand)

        scheduled = run_schedule(len(proposals), solve, validate, part, self.settings)
        candidates = scheduled.candidates
        if scheduled.on_part is not None:
            chosen = scheduled.on_part
            if scheduled.found is None:
                notes.append(
                    f"no holding grasp on the {part} met the {instruction.intent} definition; "
                    f"returning one that does not ({chosen.intent.reason})"
                )
            return PlanResult(instruction, self.hand.name, chosen.grasp, candidates, notes)
        fallback = scheduled.fallback
        if fallback is not None:
            notes.append(
                f"no holding grasp touched the {part}; returning one that touches {fallback.part}"
            )
            return PlanResult(instruction, self.hand.name, fallback.grasp, candidates, notes)
        return PlanResult(instruction, self.hand.name, None, candidates, notes)

    def _intent_program(
        self, obj: ObjectModel, meaning: Definition
    ) -> tuple[GraspProgram, float | None]:
        """The grasp program for proposals placed for the intent (its `intent_program`
        settings and, for Liftup, a table under the object: `liftup_table`) and the table's
        top height (None: no table)."""
        changes = {k: v for i, k, v in self.settings.intent_program if i == meaning.intent}
        pieces, top = list(obj.collision_pieces()), None
        if meaning.intent == "Liftup" and self.settings.liftup_table:
            table = table_under(obj)
            pieces.append(table)
            top = float(table[:, 2].max())
        return grasp_program(self.hand, pieces, replace(self.settings.program, **changes)), top

    def _solve(self, program, obj, rank, proposal, table_top=None) -> CandidateResult:
        """Solve one proposal and score its contacts (epsilon and task quality at the grasp)."""
        solved = program.solve(
            GraspTargets(
                proposal.wrist,
                proposal.q,
                proposal.anchors,
                proposal.normals,
                point_index=proposal.point_index,
                point_targets=proposal.point_targets,
                point_weights=proposal.point_weights,
                palm_target=proposal.palm_target,
            )
        )
        cand = CandidateResult(rank, proposal, solved, times={"solve": solved.solve_time})
        if solved.ok:
            t0 = time.perf_counter()
            points, inward = program.contacts(
                solved.wrist, solved.q, self.settings.contact_distance
            )
            if table_top is not None:  # the table is no contact with the object
                on_table = (points[:, 2] <= table_top + 1e-4) & (inward[:, 2] < -0.9)
                points, inward = points[~on_table], inward[~on_table]
            quality = contact_quality(points, inward, obj.points.mean(axis=0))
            cand.quality, cand.task_quality = rounded(quality.epsilon), rounded(quality.task)
            cand.times["quality"] = time.perf_counter() - t0
        return cand

    def _validate(self, program, obj, instruction, cand: CandidateResult) -> None:
        """Complete the candidate's grasp, validate it and vote its part (fills `cand`)."""
        done = finish_grasp(program, obj, cand.solve, instruction.text, self.settings.protocol)
        done.grasp.metrics["epsilon"] = cand.quality
        if cand.intent is not None:
            done.grasp.metrics["intent_ok"] = cand.intent.ok
            done.grasp.metrics["intent"] = cand.intent.to_dict()
        cand.grasp, cand.success, cand.part = done.grasp, done.success, done.part
        cand.validation = done.validation
        cand.times.update(done.times)


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


@dataclass
class FinishedGrasp:
    """A solved program turned into a validated, labelled grasp."""

    grasp: Grasp
    success: bool
    part: str | None  # None: the object has no part labels
    validation: dict[str, Any]
    times: dict[str, float]


def finish_grasp(
    program: GraspProgram, obj: ObjectModel, solved: SolveResult, instruction: str, protocol: str
) -> FinishedGrasp:
    """Pregrasp (anchor fingertips about 1 cm off the surface, offsets set by balanced squeeze
    forces and shrunk where a link, or the closing's path, would be inside the object:
    GraspProgram.closing), BODex squeeze (as deep as the unshrunk offsets), the Grasp record, MuJoCo validation and the voted part: every planned or
    transferred grasp goes through these same steps. A grasp that slips is validated once more
    with the deeper squeeze of `program.retry_squeeze_depth`, where the hand has one, and the
    squeeze that held is the one recorded (`metrics["squeeze_depth"]`)."""
    t1 = time.perf_counter()
    hand = program.hand
    wrist_t = torch.tensor(solved.wrist[None])
    q_t = torch.tensor(solved.q[None])
    tips = hand.fingertip_positions(wrist_t, q_t, list(hand.meta.anchor_fingers))[0].numpy()
    nearest = np.argmin(np.linalg.norm(obj.points[None] - tips[:, None], axis=2), axis=1)
    pre, scale = program.closing(solved.wrist, solved.q, obj.normals[nearest])
    grasp = Grasp(
        hand=hand.name,
        wrist_pos=solved.wrist[:3],
        wrist_quat=solved.wrist[3:7],
        grasp=solved.q,
        pregrasp=pre,
        squeeze=program.squeeze(solved.q, pre, scale=scale),
        joint_names=tuple(hand.joint_names),
        anchors=obj.points[nearest],
        instruction=instruction,
    )
    t2 = time.perf_counter()
    pieces = obj.collision_pieces()
    result = validate(grasp, pieces, hand, protocol)
    depth = program.squeeze_depth
    times = {"pregrasp": t2 - t1, "validate": time.perf_counter() - t2}
    retry = program.retry_squeeze_depth
    if not result.success and retry is not None:
        t3 = time.perf_counter()
        deeper = replace(grasp, squeeze=program.squeeze(solved.q, pre, retry, scale), metrics={})
        again = validate(deeper, pieces, hand, protocol)
        times["retry"] = time.perf_counter() - t3
        if again.success:
            grasp, result, depth = deeper, again, retry
    all_tips = hand.fingertip_positions(wrist_t, q_t)[0].numpy()
    part = (  # no labels: no part to vote (an unlabelled cloud)
        voted_part(all_tips, obj.points, obj.point_labels, obj.part_names) if obj.labelled else None
    )
    validation = result.to_dict()
    grasp.metrics.update(
        {
            "success": bool(result.success),
            "part": part,
            "anchor_error": solved.anchor_error,
            "min_distance": solved.min_distance,
            "squeeze_depth": depth,
            "validation": validation,
        }
    )
    return FinishedGrasp(grasp, bool(result.success), part, validation, times)


def plan_grasp(
    obj: ObjectModel | np.ndarray | str,
    text: str,
    hand: HandModel | str,
    settings: PlannerSettings | None = None,
) -> PlanResult:
    """Plan a functional grasp: `from planner import plan_grasp`.

    obj: an ObjectModel (e.g. models.objects.make_object("mug", 3)), a mesh/cloud file or an
    (N, 3) array in metres; text: "[Intent] a [Object] by [Part]"; hand: name or HandModel."""
    if not isinstance(text, str) or not text.strip():
        raise InstructionError('the instruction is empty; write e.g. "Use a mug by handle"')
    if not isinstance(obj, ObjectModel):
        obj = load_object(obj)
    return FunctionalPlanner(hand, settings).plan(obj, parse_instruction(text))
