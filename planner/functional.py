"""The functional planner: object + instruction + hand -> validated grasp.

Proposals (wrist pose, four anchors, point targets) come from the model-based proposer
(planner.model_proposer: needs part labels) or the learned stages (planner.learned_proposer:
any cloud, any sentence), as `PlannerSettings.proposer` says. Each goes through the Drake grasp
program; solved candidates are validated in MuJoCo best first (planner.schedule), and the
first grasp that holds, touches the instructed part and meets the intent is returned with
every candidate's outcome.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import cached_property, partial
from typing import Any

import numpy as np
import torch

from models.errors import InstructionError, PlanningError
from models.grasp import Grasp
from models.hands import HandModel, load_hand
from models.objects import Instruction, ObjectModel, parse_instruction
from models.objects.completion import complete_view
from models.objects.intents import WRIST_CRITERIA, Definition, label_free, region_checked
from models.reproducible import rounded
from planner.grasp_program import GraspProgram, GraspTargets, SolveResult, grasp_program
from planner.intent import (
    check_configuration,
    faces_intent,
    intent_definition,
    proposal_misses,
    region_definition,
    unmeetable,
)
from planner.intent_pieces import keep_out, table_under
from planner.labels import grasp_part
from planner.learned_proposer import (
    REGION_PART,
    anchor_closure,
    as_drawn,
    direct_proposals,
    dro_targets,
    fitted,
    learned_proposals,
    region_object,
    sample_start,
)
from planner.model_labels import model_labels
from planner.model_proposer import HandGeometry, ModelProposer
from planner.parallel import forked_map, processes
from planner.quality import contact_quality
from planner.results import CandidateResult, PlanResult, Proposal
from planner.schedule import run_schedule
from planner.settings import PROPOSERS, PlannerSettings
from planner.validation import validate

__all__ = [
    "PROPOSERS",
    "CandidateResult",
    "FunctionalPlanner",
    "HandGeometry",
    "PlanResult",
    "PlannerSettings",
    "Proposal",
    "finish_grasp",
]


class FunctionalPlanner:
    """Plans functional grasps for one hand."""

    def __init__(self, hand: HandModel | str, settings: PlannerSettings | None = None):
        self.hand = hand if isinstance(hand, HandModel) else load_hand(hand)
        self.settings = settings or PlannerSettings()

    @cached_property
    def proposer(self) -> ModelProposer:
        """The model-based proposer for this hand and these settings."""
        return ModelProposer(self.hand, self.settings)

    def propose(
        self, obj: ObjectModel, part: str, intent: Definition | None = None
    ) -> list[Proposal]:
        """The model-based proposals for the part (ModelProposer.propose)."""
        return self.proposer.propose(obj, part, intent)

    # ---- planning -------------------------------------------------------------------------
    def plan(self, obj: ObjectModel, instruction: Instruction | str) -> PlanResult:
        """Try proposals in order; return the first grasp that holds and touches the part.

        The proposals come from the model-based proposer of this module or from the learned
        stages (planner.learned_proposer), as `settings.proposer` says; solving, the schedule
        and validation are the same for both. A single view is completed first
        (`settings.complete_views`), and a grasp planned on it comes with a note of what its
        verdict rests on (`view_note`)."""
        if self.settings.complete_views:
            obj = complete_view(obj)
        result = self._plan(obj, instruction)
        result.completed_by = obj.completed_by
        if obj.completed_by is not None and result.grasp is not None:
            result.notes.append(view_note(obj.completed_by))
        return result

    def _plan(self, obj: ObjectModel, instruction: Instruction | str) -> PlanResult:
        text = instruction if isinstance(instruction, str) else instruction.text
        chosen = self.proposer_for(obj, instruction)
        if chosen in ("learned", "direct"):
            return self._plan_learned(obj, text, direct=chosen == "direct")
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
        meaning = intent_definition(obj, instruction) if self.settings.intent.aware else None
        program = grasp_program(self.hand, obj.collision_pieces(), self.settings.program)
        build = time.perf_counter() - start
        proposals = self.propose(obj, part, meaning)
        propose_time = time.perf_counter() - start - build
        shaped = None
        if meaning is not None and any(p.shaped for p in proposals):
            shaped = partial(self._intent_program, obj, meaning)
        times = {"build": build, "propose": propose_time}
        programs = (program, shaped)
        unmet = None if meaning is None else unmeetable(obj, meaning)
        checked = meaning is not None
        return self._run(obj, instruction, part, checked, proposals, programs, times, unmet=unmet)

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

    def _plan_learned(self, obj: ObjectModel, text: str, direct: bool = False) -> PlanResult:
        """Plan on the learned stages' proposals. The sentence is read as the nearest table
        instruction (learned.understand); its part is what the grasp must touch only where the
        object has part labels that name that part: on an unlabelled cloud a grasp that holds
        is success. Its intent is checked there too, and on any cloud where the definition
        needs no labels (Liftup): samples whose drawn wrist meets the criteria the wrist
        decides (palm down, above the centre of mass) are solved first, with the intent's
        program (Liftup's table), as the model-based proposer's shaped proposals are.
        `direct`: the direct-diffusion ablation's samples, validated as drawn."""
        from learned.understand import understand

        s = self.settings
        start = time.perf_counter()
        understood = understand(text)
        instruction = understood.instruction
        known = obj.labelled and instruction.part in obj.part_names
        part = instruction.part if known else None
        checked = s.intent.aware and (known or label_free(instruction.intent))
        meaning = intent_definition(obj, instruction) if checked else None
        # samples drawn facing the intent go first (where the wrist decides some criteria)
        facing = meaning is not None and bool(WRIST_CRITERIA & set(meaning.criteria))
        program = grasp_program(self.hand, obj.collision_pieces(), s.program)
        t0 = time.perf_counter()
        drawing = (obj, text, self.hand, s.learned.samples, s.learned.seed, s.learned.guidance)
        if direct:
            drawn = direct_proposals(*drawing, steps=s.learned.sample_steps)
        else:
            drawn = learned_proposals(
                *drawing, weights=s.learned.interaction_weights, steps=s.learned.sample_steps
            )
        drawn_time = time.perf_counter() - t0
        # Use and Handover need the other parts, and Hold (learned.labels_over_region) is
        # measured better on its whole part than on a patch of it: the interaction model's
        # labels stand in (planner.model_labels)
        labels = None
        wants_labels = not label_free(instruction.intent) and (
            s.learned.labels_over_region or not region_checked(instruction.intent)
        )
        if s.intent.aware and not known and wants_labels and not direct and s.learned.model_labels:
            t0 = time.perf_counter()
            labels = model_labels(
                obj,
                instruction,
                self.hand,
                drawn.anchors if understood.parsed else None,
                s.learned.seed,
                s.learned.interaction_weights,
                s.learned.sample_steps,
                s.learned.label_samples,
                s.learned.held_reach,
            )
            drawn.times["labels"] = time.perf_counter() - t0
            if labels is not None:
                checked, meaning = True, labels.meaning
        # else Hold is measured with the region the samples point at as its part
        # (models.objects.intents.region_checked)
        region = None
        if labels is None and s.intent.aware and not known and region_checked(instruction.intent):
            region = region_object(obj, drawn.anchors)
            if region is not None:
                checked, meaning = True, region_definition(region, instruction)
        kept_out = labels is not None and s.learned.sample_keep_outs
        proposals = []
        for i in range(len(drawn.wrists)):
            wrist, anchors = rounded(drawn.wrists[i]), rounded(drawn.anchors[i])
            pending = None
            if s.learned.dro and not direct:
                key = (s.learned.seed, i)
                pending = partial(
                    dro_targets,
                    obj,
                    text,
                    self.hand,
                    wrist,
                    anchors,
                    key,
                    weights=s.learned.dro_weights,
                )
            if drawn.q is None:  # the program starts from the hand's start for samples
                q = sample_start(self.hand)
            else:
                q = rounded(drawn.q[i])
            proposals.append(
                Proposal(
                    wrist,
                    q,
                    anchors,
                    rounded(drawn.normals[i]),
                    0.0,
                    anchor_quality=anchor_closure(drawn.anchors[i], drawn.normals[i], obj),
                    kind="direct" if direct else "learned",
                    pending_targets=pending,
                    # direct samples are not solved: the intent's program would only add its
                    # table to their measured distance
                    shaped=kept_out
                    or (facing and not direct and faces_intent(wrist, obj, self.hand, instruction)),
                )
            )
        # facing samples first, then best anchor closure; stable: sample order breaks ties
        proposals.sort(key=lambda p: (not p.shaped, -p.anchor_quality))
        # the region proposals come after the samples, made only if the search reaches them
        # shaped by the intent where it is measured without the object's labels: Liftup's, or
        # Hold's on the region (a labelled object's definitions name parts the region lacks)
        shape = None
        if meaning is not None and (label_free(meaning.intent) or region is not None):
            shape = meaning
        later = None
        if s.learned.region_proposals > 0 and s.learned.solver == "drake" and not direct:
            if labels is not None:  # the model-based proposer on the part as labelled
                later = partial(self._labelled_proposals, labels.obj, instruction.part, meaning)
            else:
                later = partial(self._region_proposals, obj, drawn.anchors, shape)
        region_shaped = later is not None and (shape is not None or labels is not None)
        shaped = None
        if any(p.shaped for p in proposals) or region_shaped:
            on = None if labels is None else labels.obj
            shaped = partial(self._intent_program, obj, meaning, on)
        elapsed = time.perf_counter() - start - drawn_time - drawn.times.get("labels", 0.0)
        times = {"build": elapsed, **drawn.times}
        voter = None
        if part is None and s.learned.region_vote > 0 and not direct:
            voter = region_object(obj, drawn.anchors, s.learned.region_vote, 1)
        # where the intent is measured on the part's labels (the object's or the model's),
        # whether it can be met there at all
        unmet = None
        if meaning is not None and region is None and (known or labels is not None):
            unmet = unmeetable(obj if labels is None else labels.obj, meaning)
        confirms = None
        if labels is not None and s.learned.switch_reach > 0:
            sure = labels.near_seed(s.learned.switch_reach)
            confirms = partial(touches_part, self.hand, sure, instruction.part)
        result = self._run(
            obj,
            instruction,
            part,
            checked,
            proposals,
            (program, shaped),
            times,
            voter,
            later,
            region,
            None if labels is None else labels.obj,
            unmet,
            confirms,
        )
        result.understood = understood.to_dict()
        if labels is not None:
            result.understood["model_labels"] = labels.seeds
        result.proposer = "direct" if direct else "learned"
        return result

    def _region_proposals(
        self, obj: ObjectModel, anchors: np.ndarray, shape: Definition | None
    ) -> list[Proposal]:
        """The model-based proposer's proposals on the region the samples point at
        (planner.learned_proposer.region_object), best `learned.region_proposals` of them,
        shaped by `shape` (Liftup's definition, or Hold's on the region,
        planner.intent.region_definition; None: by the region alone)."""
        region = region_object(obj, anchors)
        if region is None:
            return []
        found = self.propose(region, REGION_PART, shape)
        return found[: self.settings.learned.region_proposals]

    def _labelled_proposals(
        self, labelled: ObjectModel, part: str, meaning: Definition
    ) -> list[Proposal]:
        """The model-based proposer's proposals on the part of the object as the interaction
        model labelled it (planner.model_labels), shaped by the intent measured there; best
        `learned.region_proposals` of them."""
        found = self.propose(labelled, part, meaning)
        return found[: self.settings.learned.region_proposals]

    def _run(
        self,
        obj: ObjectModel,
        instruction: Instruction,
        part: str | None,
        check_intent: bool,
        proposals: list[Proposal],
        programs: tuple[GraspProgram, Callable[[], tuple[GraspProgram, int | None]] | None],
        times: dict[str, float],
        voter: ObjectModel | None = None,
        later: Callable[[], list[Proposal]] | None = None,
        intent_region: ObjectModel | None = None,
        intent_labels: ObjectModel | None = None,
        unmet: str | None = None,
        confirms: Callable[[CandidateResult], bool] | None = None,
    ) -> PlanResult:
        """Solve, schedule and validate the proposals (planner.schedule). `programs`: the
        program, and what makes the program for proposals shaped by the intent with the count
        of its pieces that are the object's own (None: no proposal is shaped), called when a
        shaped proposal is first solved; `times` (building and proposing) go to the first
        candidate. `part` None: any part counts,
        unless `voter` (the region the learned samples point at, `learned.region_vote`) says
        which held grasps count first; the candidates' `part` stays None. `later`: makes the
        proposals that follow these, if the search reaches them (planner.schedule `more`);
        the time it takes goes to the last candidate solved before, as stage "region".
        `intent_region`: the intent is checked with it standing in for the part
        (planner.intent.check_configuration); `intent_labels`: checked on its labels (the
        object's points, labelled by the interaction model: planner.model_labels).
        `unmet`: why no grasp on the part can meet the intent (planner.intent.unmeetable):
        the first grasp that holds on the part is returned, with no search for one meeting
        it. `confirms`: planner.schedule's (`learned.switch_reach`)."""
        notes = [] if unmet is None else [unmet]
        settings = self.settings
        if unmet is not None:
            settings = replace(settings, schedule=replace(settings.schedule, intent_search=0))
        program, make_shaped = programs
        built: list[tuple[GraspProgram, int | None]] = []  # the shaped program, once made

        def shaped() -> tuple[GraspProgram, int | None]:
            if not built:
                built.append((program, None) if make_shaped is None else make_shaped())
            return built[0]

        def program_of(rank: int) -> GraspProgram:
            return shaped()[0] if proposals[rank].shaped else program

        def solve(ranks: list[int]) -> list[CandidateResult]:
            """The proposals solved and scored, shared over `schedule.solve_processes`
            (planner.parallel); D(R,O)'s targets, the shaped program (built here, once, so
            the children inherit it) and the intent checks (torch) run here."""
            made = {rank: self._prepare(proposals[rank]) for rank in ranks}
            if not built and any(proposals[rank].shaped for rank in ranks):
                t0 = time.perf_counter()
                shaped()
                made[ranks[0]]["build"] = time.perf_counter() - t0
            drake = all(self._drake_solve(proposals[rank]) for rank in ranks)
            count = processes(self.settings.schedule.solve_processes) if drake else 1
            solved = forked_map(solve_one, ranks, count)
            return [finish(cand, made[cand.rank]) for cand in solved]

        def solve_one(rank: int) -> CandidateResult:
            proposal = proposals[rank]
            own = shaped()[1] if proposal.shaped else None
            return self._solve(program_of(rank), obj, rank, proposal, own)

        def more() -> int:
            t0 = time.perf_counter()
            found = later()
            if finished:  # the last candidate solved before carries the time
                finished[-1].times["region"] = time.perf_counter() - t0
            proposals.extend(found)
            return len(found)

        finished: list[CandidateResult] = []

        def finish(cand: CandidateResult, made: dict[str, float]) -> CandidateResult:
            cand.times.update(made)
            finished.append(cand)
            if cand.rank == 0:  # building and proposing (a lazy build adds to it)
                for stage, seconds in times.items():
                    cand.times[stage] = cand.times.get(stage, 0.0) + seconds
            if check_intent and cand.solve.ok:
                t0 = time.perf_counter()
                cand.intent = check_configuration(
                    cand.solve.wrist,
                    cand.solve.q,
                    obj,
                    self.hand,
                    instruction,
                    region=intent_region,
                    labels=intent_labels,
                )
                cand.times["intent"] = time.perf_counter() - t0
            return cand

        def validate(cand: CandidateResult) -> None:
            self._validate(program_of(cand.rank), obj, instruction, cand)
            if voter is not None:
                cand.part = grasp_part(self.hand, cand.solve.wrist, cand.solve.q, voter)

        misses = None
        measured_on = intent_labels if intent_labels is not None else obj
        if check_intent and intent_region is None and settings.schedule.pass_over_misses:
            meaning = intent_definition(measured_on, instruction)
            sched = settings.schedule

            def misses(rank: int) -> str | None:
                p = proposals[rank]
                return proposal_misses(
                    p.wrist,
                    p.anchors,
                    obj,
                    self.hand,
                    meaning,
                    measured_on,
                    sched.miss_anchor_share,
                    sched.miss_tilt_margin_deg,
                    sched.miss_height_margin,
                )

        wanted = REGION_PART if voter is not None else part
        scheduled = run_schedule(
            len(proposals),
            solve,
            validate,
            wanted,
            settings,
            more if later else None,
            misses,
            confirms,
        )
        candidates = scheduled.candidates
        unsure = least_unsure(candidates, wanted)
        if voter is not None:
            if scheduled.on_part is None and scheduled.fallback is not None:
                notes.append(
                    "no holding grasp touched the region the samples point at; returning one "
                    "elsewhere on the object"
                )
            for cand in candidates:
                cand.part = None
        returned = scheduled.on_part or scheduled.fallback or unsure
        if scheduled.on_part is not None:
            if scheduled.found is None:
                notes.append(
                    f"no holding grasp on the {part or 'object'} met the {instruction.intent} "
                    "definition; "
                    f"returning one that does not ({returned.intent.reason})"
                )
        elif scheduled.fallback is not None:
            if voter is None:
                notes.append(
                    f"no holding grasp touched the {part}; returning one that touches "
                    f"{returned.part}"
                )
        elif unsure is not None:
            checks = unsure.cloud_checks
            notes.append(
                "no grasp passed the cloud checks; returning one that held on the cloud's own "
                f"pieces but on only {checks['held']} of {checks['of']} other piece sets of it: "
                "it may slip on the real object"
            )
        grasp = None if returned is None else returned.grasp
        return PlanResult(
            instruction,
            self.hand.name,
            grasp,
            candidates,
            notes,
            unmeetable=unmet,
            passed=scheduled.passed,
        )

    def _intent_program(
        self, obj: ObjectModel, meaning: Definition, labelled: ObjectModel | None = None
    ) -> tuple[GraspProgram, int | None]:
        """The grasp program for proposals placed for the intent (its `intent.program`
        settings; for Liftup, a table under the object: `intent.liftup_table`; for Use and
        Handover, keep-outs: planner.intent_pieces.keep_out, from `labelled` where the labels
        are the interaction model's) and how many of its pieces are the object's own (None:
        all of them; the rest are no contact)."""
        changes = {k: v for i, k, v in self.settings.intent.program if i == meaning.intent}
        own = list(obj.collision_pieces())
        extra = []
        if meaning.intent == "Liftup" and self.settings.intent.liftup_table:
            extra.append(table_under(obj))
        extra.extend(keep_out(obj if labelled is None else labelled, meaning, self.settings.intent))
        program = grasp_program(self.hand, own + extra, replace(self.settings.program, **changes))
        return program, len(own) if extra else None

    def _prepare(self, proposal: Proposal) -> dict[str, float]:
        """Make the proposal's pending D(R,O) targets (learned samples: made when solved, in
        this process, as torch runs here); the time it took, as a stage."""
        if proposal.pending_targets is None:
            return {}
        t0 = time.perf_counter()
        made = proposal.pending_targets()
        proposal.point_index, proposal.point_targets = made.index, rounded(made.targets)
        proposal.point_weights, proposal.pending_targets = made.weights, None
        return {"dro": time.perf_counter() - t0}

    def _drake_solve(self, proposal: Proposal) -> bool:
        """Whether the proposal is solved by the Drake program (which may run in a forked
        process), not drawn as is or fitted by torch (which stay here)."""
        fit = proposal.kind == "learned" and self.settings.learned.solver == "fit"
        return proposal.kind != "direct" and not fit

    def _solve(
        self,
        program: GraspProgram,
        obj: ObjectModel,
        rank: int,
        proposal: Proposal,
        own_pieces: int | None = None,
    ) -> CandidateResult:
        """Solve one proposal (its D(R,O) targets already made: `_prepare`) and score its
        contacts: epsilon and task quality at the grasp, on the first `own_pieces` pieces only
        (the object's; not a Liftup table or a keep-out: planner.intent_pieces).
        A Drake solve uses no torch, so it may run in a forked process (planner.parallel); the
        ablations' samples (drawn as is, fitted by torch) are solved in this one."""
        if proposal.kind == "direct":
            solved = as_drawn(program, proposal)
        elif not self._drake_solve(proposal):
            solved = fitted(program, proposal)
        else:
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
            distance = self.settings.schedule.contact_distance
            points, inward = program.contacts(solved.wrist, solved.q, distance, own_pieces)
            quality = contact_quality(points, inward, obj.points.mean(axis=0))
            cand.quality, cand.task_quality = rounded(quality.epsilon), rounded(quality.task)
            cand.times["quality"] = time.perf_counter() - t0
        return cand

    def _validate(self, program, obj, instruction, cand: CandidateResult) -> None:
        """Complete the candidate's grasp, validate it and vote its part (fills `cand`)."""
        s = self.settings
        done = finish_grasp(program, obj, cand.solve, instruction.text, s.protocol, s.cloud_checks)
        done.grasp.metrics["epsilon"] = cand.quality
        if cand.intent is not None:
            done.grasp.metrics["intent_ok"] = cand.intent.ok
            done.grasp.metrics["intent"] = cand.intent.to_dict()
        cand.grasp, cand.success, cand.part = done.grasp, done.success, done.part
        cand.validation = done.validation
        cand.times.update(done.times)


_GUESSES = {
    "swept": "sweeping it about a vertical axis",
    "mirrored": "mirroring it through a symmetry plane",
    "swept+mirrored": "sweeping it about a vertical axis and mirroring the rest",
}


def touches_part(hand: HandModel, obj: ObjectModel, part: str, cand: CandidateResult) -> bool:
    """Whether the candidate's fingertips vote (planner.labels) for `part` of the labelled
    object."""
    return grasp_part(hand, cand.solve.wrist, cand.solve.q, obj) == part


def view_note(kind: str) -> str:
    """What a grasp planned on a completed single view rests on (Completion.kind): its
    verdict is on the guessed hidden side, which on real scans is often wrong in shape
    (README, "Real scanned meshes")."""
    if kind == "as seen":
        return (
            "planned on a single view that no sweep or mirror plane completes: its hidden back "
            "is open, the fingers may pass through the real one and the verdict says nothing "
            "of it; give a complete cloud or a mesh"
        )
    return (
        f"planned on a single view completed by {_GUESSES[kind]}: the verdict is on that "
        "guess of the hidden side, which on real objects is often wrong in shape; check the "
        "grasp on the real object"
    )


def least_unsure(candidates: list[CandidateResult], part: str | None) -> CandidateResult | None:
    """Of the candidates that held on a bare cloud's own pieces but slipped on a piece variant
    (CandidateResult.uncertain), the one to return when none held on them all: on the wanted
    part first, then the most variants held, then the first validated."""
    unsure = [c for c in candidates if c.uncertain]
    if not unsure:
        return None
    return min(
        unsure,
        key=lambda c: (
            c.part not in (part, None),
            -c.cloud_checks["held"],
            c.order if c.order is not None else len(candidates),
        ),
    )


@dataclass
class FinishedGrasp:
    """A solved program turned into a validated, labelled grasp."""

    grasp: Grasp
    success: bool
    part: str | None  # None: the object has no part labels
    validation: dict[str, Any]
    times: dict[str, float]


def finish_grasp(
    program: GraspProgram,
    obj: ObjectModel,
    solved: SolveResult,
    instruction: str,
    protocol: str,
    cloud_checks: int = 0,
) -> FinishedGrasp:
    """Pregrasp (anchor fingertips about 1 cm off the surface, offsets set by balanced squeeze
    forces and shrunk where a link, or the closing's path, would be inside the object:
    GraspProgram.closing), BODex squeeze (as deep as the unshrunk offsets), the Grasp record, MuJoCo validation and the voted part: every planned or
    transferred grasp goes through these same steps. A grasp that slips is validated again with
    each closing of `program.retry_closings()` in turn (other squeeze depths, then another
    pregrasp rule), up to the first that holds; the pregrasp and squeeze that held are the ones
    recorded (`metrics["squeeze_depth"]`, `metrics["pregrasp_rule"]`). On a bare cloud a grasp
    that held must hold on `cloud_checks` other piece sets of the cloud too
    (ObjectModel.piece_variants), or it counts as slipped (validation["cloud_checks"])."""
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
    rule = program.settings.pregrasp_rule
    for retry, retry_rule in program.retry_closings() if not result.success else ():
        t3 = time.perf_counter()
        pre2, scale2 = pre, scale
        if retry_rule != rule:  # another pregrasp, and the squeeze from it
            normals = obj.normals[nearest]
            pre2, scale2 = program.closing(solved.wrist, solved.q, normals, rule=retry_rule)
        squeeze = program.squeeze(solved.q, pre2, retry, scale2)
        other = replace(grasp, pregrasp=pre2, squeeze=squeeze, metrics={})
        again = validate(other, pieces, hand, protocol)
        times["retry"] = times.get("retry", 0.0) + time.perf_counter() - t3
        if again.success:
            grasp, result, depth, rule = other, again, retry, retry_rule
            break
    checked: dict[str, int] | None = None  # held of the piece variants, where checked
    if result.success and cloud_checks > 0:
        t4 = time.perf_counter()
        variants = obj.piece_variants(cloud_checks)
        held = [validate(grasp, variant, hand, protocol).success for variant in variants]
        if variants:  # a mesh has none: no stage to report
            times["cloud_checks"] = time.perf_counter() - t4
            checked = {"held": int(sum(held)), "of": len(held)}
            if not all(held):
                result.success, result.reason = False, "slipped on other pieces of the cloud"
    validation = result.to_dict()
    if checked is not None:
        validation["cloud_checks"] = checked
    part = grasp_part(hand, solved.wrist, solved.q, obj)  # None: an unlabelled object
    grasp.metrics.update(
        {
            "success": bool(result.success),
            "part": part,
            "anchor_error": solved.anchor_error,
            "min_distance": solved.min_distance,
            "squeeze_depth": depth,
            "pregrasp_rule": rule,
            "validation": validation,
        }
    )
    return FinishedGrasp(grasp, bool(result.success), part, validation, times)
