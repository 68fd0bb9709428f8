"""What planning produces: proposals, solved candidates and the plan's result.

Shared by the proposers (planner.model_proposer, planner.learned_proposer), the schedule
(planner.schedule) and the planner (planner.functional), so none of them imports another
for its data.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from models.grasp import Grasp
from models.objects import Instruction
from planner.grasp_program import SolveResult
from planner.intent import IntentCheck


def is_uncertain(success: bool | None, validation: dict[str, Any] | None) -> bool:
    """A grasp that held on a bare cloud's own collision pieces but slipped on one of its
    piece variants (finish_grasp's cloud checks): it may or may not hold on the real object.
    From a candidate's verdict or a grasp's `metrics["success"]` and `["validation"]`."""
    checks = None if validation is None else validation.get("cloud_checks")
    return success is False and checks is not None and checks["held"] < checks["of"]


@dataclass
class Proposal:
    wrist: np.ndarray  # [x, y, z, qw, qx, qy, qz]
    q: np.ndarray
    anchors: np.ndarray  # (4, 3) in anchor-finger order
    normals: np.ndarray  # (4, 3)
    score: float  # free space for the palm plus outwardness: breaks anchor-quality ties
    palm_target: np.ndarray | None = None
    # epsilon (planner.quality) of the anchors pushing along their inward normals, about the
    # object's centre of mass: the solve order, best first (with
    # proposals.proposal_order="anchors")
    anchor_quality: float = -1.0
    # "row": thumb against a row of the other anchor fingers; "pinch": thumb and the next
    # two anchor fingers, the last one free; "palm": a power grasp, palm first (Hold)
    kind: str = "row"
    # placed for the instruction's intent (not by part alone): solved with the intent's
    # program settings (`intent.program`) and, for Liftup, above a table
    shaped: bool = False
    # targets for hand surface points (learned proposals: D(R,O) after multilateration), with
    # their weights (GraspTargets.point_targets); None: none
    point_index: np.ndarray | None = None
    point_targets: np.ndarray | None = None
    point_weights: np.ndarray | None = None
    # a learned proposal's D(R,O) targets, made when it is solved (planner.learned_proposer.
    # dro_targets): returns LearnedTargets, which fill the three fields above
    pending_targets: Callable[[], Any] | None = None


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

    @property
    def cloud_checks(self) -> dict[str, int] | None:
        """{"held", "of"}: the piece variants a bare cloud's grasp that held was checked on
        (finish_grasp); None: not checked."""
        return None if self.validation is None else self.validation.get("cloud_checks")

    @property
    def uncertain(self) -> bool:
        return is_uncertain(self.success, self.validation)

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
            # held of the piece variants checked (a bare cloud's grasp that held), else None
            "cloud_checks": self.cloud_checks,
            "pregrasp_penetration_mm": (
                None if self.validation is None else 1000 * self.validation["pregrasp_penetration"]
            ),
            "anchor_error_mm": 1000 * self.solve.anchor_error,
            "min_distance_mm": 1000 * self.solve.min_distance,
            # the recorded closing: the hand's, or the retry's where only that one held
            "squeeze_depth": None if self.grasp is None else self.grasp.metrics["squeeze_depth"],
            "pregrasp_rule": None if self.grasp is None else self.grasp.metrics["pregrasp_rule"],
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
    # why no grasp on the instructed part can meet the intent's definition on this object
    # (planner.intent.unmeetable: a cup's rim for Handover); None: one may
    unmeetable: str | None = None
    # proposals passed over unsolved in the search for a grasp meeting the intent after one
    # held without it (planner.schedule, planner.intent.proposal_misses): rank -> why
    passed: dict[int, str] = field(default_factory=dict)
    # planned on a completed single view: how its hidden side was guessed
    # (ObjectModel.completed_by); None: planned on what was given
    completed_by: str | None = None

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
    def status(self) -> str:
        """ "holds"; "uncertain": no grasp passed the cloud checks and the returned one held on
        the bare cloud's own pieces but slipped on a piece variant (CandidateResult.uncertain);
        "none": no grasp returned."""
        if self.success:
            return "holds"
        return "none" if self.best is None else "uncertain"

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
            "status": self.status,
            "proposer": self.proposer,
            "understood": self.understood,
            "part_instructed": self.instruction.part,
            "part_touched": self.part_touched,
            "intent_ok": self.intent_ok,
            "intent": None if best is None or best.intent is None else best.intent.reason,
            "intent_unmeetable": self.unmeetable,
            "anchor_error_mm": None if best is None else 1000 * best.solve.anchor_error,
            "candidates_solved": len(self.candidates),
            "candidates_passed": len(self.passed),
            "candidates_validated": sum(c.order is not None for c in self.candidates),
            "chosen_rank": None if best is None else best.rank,
            "chosen_kind": None if best is None else best.proposal.kind,
            "chosen_validated_as": None if best is None else best.order,
            "chosen_squeeze_depth": None if best is None else best.grasp.metrics["squeeze_depth"],
            "chosen_pregrasp_rule": None if best is None else best.grasp.metrics["pregrasp_rule"],
            "times_s": self.stage_times(),
            "notes": self.notes,
            "completed_by": self.completed_by,
        }
