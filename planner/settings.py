"""How the planner plans: every knob of FunctionalPlanner, with why each default is what it is.

Kept apart from the planner so the schedule (planner.schedule), the proposers and the API's
checks (planner.api.check_settings) can read them without importing the planner. The knobs
are grouped by concern: `schedule` (what is validated, in which order), `proposals` (the
model-based proposer), `intent` (shaping by the instruction's intent), `learned` (the learned
stages) and `program` (the grasp program); `with_overrides` sets them by dotted keys
(`schedule.solve_batch`, `intent.aware`, `program.major_iterations`, `protocol`).
"""

from __future__ import annotations

import dataclasses
import difflib
from collections.abc import Mapping
from dataclasses import dataclass, field

from models.errors import PlanningError
from models.objects import INTENTS
from planner.grasp_program import ProgramSettings


@dataclass(frozen=True)
class ScheduleSettings:
    """What is solved and validated, and in which order (planner.schedule)."""

    max_candidates: int = 8  # grasps validated at most (the costly step)
    # proposals solved before the best of them are validated. A solved candidate's force
    # closure predicts holding better than its proposal's rank (AUC 0.87 against 0.59 over the
    # learned proposer's 2167 validated samples, counted once from eval.benchmark's records:
    # docs/learned_log.md), so the first validation chooses among a few:
    # replayed on every-candidate-validated records (with intent_first 0), the model-based
    # planner's first candidate held for 78/70/64% of the 150 validation pairs at 4 against
    # 74/60/64% at 2 and 76/68/64% at 8 (test: 80/76/68% at 4, 72/70/58% at 2), with the same
    # returned and intent rates and 0.5-1 more solves a returned grasp; the learned samples'
    # first held on the part 64/68/64% at 4 against 62/70/60% at 2 (docs/planner_log.md,
    # "Validation order, again").
    solve_batch: int = 4
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
    ranking: str = "task"  # validation order: "task" or "epsilon" (planner.quality)
    # validations in which candidates meeting the intent go first; then by quality alone. Once
    # a grasp holds on the part without meeting its intent only candidates meeting it are
    # validated, so putting them first buys no intent: it only spends the first validations on
    # candidates that slip more often (Liftup from above). Replayed on the 150 validation pairs
    # (solve_batch 4), 0 vs 4: first candidate held 78/70/64% vs 60/58/56% (allegro/leap/
    # shadow), held on the part and meeting the intent 52/64/66% vs 52/68/64%, returned
    # 98/98/96% both.
    intent_first: int = 0
    # after a grasp held on the part but missed its intent: proposals solved at most to find
    # one that meets it (None: all of them). On the 150 test pairs of `--objects-per-category
    # 1`, 4 gave 65/49/66% (allegro/leap/shadow) of the grasps held on the part meeting their
    # intent; searching every proposal (before the by-part proposals were added in turn),
    # 83/65/77% (docs/intent_log.md)
    intent_search: int | None = None
    # ... and in that search, proposals that will miss the intent as drawn are passed over
    # unsolved (planner.intent.proposal_misses: an anchor nearer a part the intent keeps clear
    # than `miss_anchor_share` of the clearance it asks, Handover's 2 cm or Use's 1 cm, or a
    # drawn wrist failing what it decides: Liftup's palm down and wrist above the centre of
    # mass, Handover's palm away from the free end). On the main table's learned test pairs
    # (three seeds, 90dc607 and 5ae4bfd), of the candidates solved in that search with an
    # anchor within 5 mm of a part Handover keeps clear none met it (0 of 426; within 3 mm of
    # Use's working parts 2 of 79), of those drawn with the palm on Handover's free-end side
    # none (0 of 230), and of Liftup's samples drawn not facing it 16 of 835; every plan
    # returned the same with it (docs/learned_log.md, "Passing over proposals that will miss
    # the intent")
    pass_over_misses: bool = True
    miss_anchor_share: float = 0.25
    # ... Liftup's drawn wrist only beyond these margins of its limits (palm tilted 30 + 30
    # degrees from down, wrist 2 cm below the centre of mass): nearer them a solve sometimes
    # turns it. Of the samples drawn not facing Liftup and solved before a hold (test split,
    # three seeds, 8aee988) 6 of 119 with the palm 30-60 degrees from down met Liftup and 3 of
    # 455 beyond (held-out teapots: 8 of 53, 0 of 85); none drawn 2 cm or more below the mass
    # centre (0 of 203). Without the margins two held-out teapot plans lost the grasp that met
    # it (docs/learned_log.md)
    miss_tilt_margin_deg: float = 30.0
    miss_height_margin: float = 0.02
    # processes a batch of solves is shared over (planner.parallel: forked, results identical
    # to solving one by one). None: one per core this process may use, 1 in a pool worker
    # (eval.benchmark, batch jobs: their workers already share the cores).
    solve_processes: int | None = None

    def __post_init__(self) -> None:
        if self.ranking not in RANKINGS:
            raise PlanningError(f"unknown schedule.ranking {self.ranking!r}; use one of {RANKINGS}")
        if self.solve_processes is not None and self.solve_processes < 1:
            raise PlanningError(
                f"schedule.solve_processes must be 1 or more (or None: one per core), "
                f"got {self.solve_processes}"
            )
        if self.miss_tilt_margin_deg < 0 or self.miss_height_margin < 0:
            raise PlanningError(
                "schedule.miss_tilt_margin_deg and schedule.miss_height_margin must be 0 or "
                f"more, got {self.miss_tilt_margin_deg} and {self.miss_height_margin}"
            )
        if not 0 <= self.miss_anchor_share <= 1:
            raise PlanningError(
                f"schedule.miss_anchor_share must be in [0, 1], got {self.miss_anchor_share}"
            )
        if self.intent_first < 0 or (self.intent_search is not None and self.intent_search < 0):
            raise PlanningError(
                "schedule.intent_first and schedule.intent_search must be 0 or more "
                f"(intent_search None: no limit), got {self.intent_first} and {self.intent_search}"
            )


@dataclass(frozen=True)
class ProposalSettings:
    """The model-based proposer's wrist poses and anchors (planner.model_proposer)."""

    max_proposals: int = 16  # wrist poses + anchors solved at most
    approach_step_deg: float = 45.0  # approach directions around the part's long axis
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
    mass_centred: bool = True  # anchors near the object's centre of mass along the part
    # solve order of the proposals: "anchors" (force closure of the planned anchors, best
    # first) or "clearance" (free space for the palm, the earlier order)
    proposal_order: str = "anchors"

    def __post_init__(self) -> None:
        if self.pinch_proposals is not None and self.pinch_proposals < 0:
            raise PlanningError(
                f"proposals.pinch_proposals must be 0 or more, got {self.pinch_proposals}"
            )
        if self.proposal_order not in PROPOSAL_ORDERS:
            raise PlanningError(
                f"unknown proposals.proposal_order {self.proposal_order!r}; use one of "
                f"{PROPOSAL_ORDERS}"
            )


@dataclass(frozen=True)
class IntentSettings:
    """Proposals and programs shaped by the instruction's intent (models/objects/intents.py)."""

    # Shape proposals by the instruction's intent (models/objects/intents.py): Liftup from
    # above, Handover and Use with anchors kept off the parts the hand must leave free, and
    # validate candidates whose solved configuration meets the intent first (planner.schedule).
    # False: proposals by part alone, as before the intent definitions.
    aware: bool = True
    # Liftup: palm directions (palm -> object) tilted this far from straight down, besides
    # straight down, at `liftup_azimuths` azimuths
    liftup_tilt_deg: float = 20.0
    liftup_azimuths: int = 4
    # Liftup: anchors lie this far (m) below the part's top at most, where it is taller: fingers
    # reaching down from above
    liftup_reach: float = 0.045
    # Liftup: how far the anchors climb from the part's widest points toward the palm (the
    # weight of height against width when each fingertip's point is chosen; 0: the widest
    # points, where the thumb and fingers squeeze straight across; below 0 they start lower
    # and the table keeps the fingertips above the object's lowest point). At 0.5 (before)
    # fingertips high on a flat handle squeezed it down and out: of the 39 Liftup pairs of the
    # test split (and of the validation split), 21 (18) met Liftup at 0.5, 27 (29) at 0 and
    # 29 (30) at -0.5; 0.25 and -1 gave 25 and 26 on test (docs/intent_log.md).
    liftup_toward_palm: float = -0.5
    # Use: each working part's convex hull, grown by the working clearance, is a collision
    # piece of the shaped proposals' grasp program (planner.intent_pieces.keep_out): the whole
    # hand stays clear of it, not only the anchors
    use_keep_out: bool = True
    # Handover: each other part's convex hull, grown by the other-part clearance, likewise
    handover_keep_out: bool = True
    # ... where at least this share of the held part lies outside the grown parts: at 0.3 (0.5
    # before) a pen's cap, within 2 cm of its barrel for about half its 37 mm, gets the
    # barrel's; a bottle's neck, between its body and cap, still gets none
    handover_keep_out_outside: float = 0.3
    # Handover: the intent's proposals with the palm beyond the held part's far end, facing
    # the receiver's parts (tilted as Liftup's: `liftup_tilt_deg` at `liftup_azimuths`), so
    # the whole hand stays on the held part's side, where the part's allowed points fit in the
    # hand's span (a pen's cap, a knife's blade, a hammer's head; not a pan's body): "only"
    # (in place of the frames around the part), "both" or "off". With the keep-out share above,
    # on the validation split's Handover pairs (3 objects per category) Handover met 53/58/66%
    # (off, 0.5) -> 58/69/71% (both) -> 64/71/77% (only) of the grasps held on the part, first
    # candidates the same (docs/intent_log.md, "Handover from the far end")
    handover_end_on: str = "only"
    # The grasp program's weights per intent (ProgramSettings field -> value), over `program`:
    # Hold pulls the palm onto its target harder (palm contact), Liftup keeps the proposal's
    # palm-down wrist rotation
    program: tuple[tuple[str, str, float], ...] = (
        ("Hold", "palm_weight", 200.0),
        ("Liftup", "wrist_rotation_weight", 1.0),
    )
    # Liftup: the grasp program keeps the hand above a table slab under the object (the
    # definition: no hand point below the object's lowest point); the table is no contact
    liftup_table: bool = True

    def __post_init__(self) -> None:
        if not 0 <= self.liftup_tilt_deg < 60 or self.liftup_azimuths < 0:
            raise PlanningError(
                "intent.liftup_tilt_deg must be in [0, 60) and intent.liftup_azimuths 0 or "
                f"more, got {self.liftup_tilt_deg} and {self.liftup_azimuths}"
            )
        for intent, name, _ in self.program:
            if intent not in INTENTS or name not in ProgramSettings.__dataclass_fields__:
                raise PlanningError(
                    f"intent.program entry ({intent!r}, {name!r}): expected an intent of "
                    f"{INTENTS} and a ProgramSettings field"
                )
        if not -1 <= self.liftup_toward_palm <= 1:
            raise PlanningError(
                f"intent.liftup_toward_palm must be in [-1, 1], got {self.liftup_toward_palm}"
            )
        if self.handover_end_on not in HANDOVER_END_ON:
            raise PlanningError(
                f"intent.handover_end_on must be one of {HANDOVER_END_ON}, got "
                f"{self.handover_end_on!r}"
            )
        if not 0 < self.handover_keep_out_outside <= 1:
            raise PlanningError(
                "intent.handover_keep_out_outside must be in (0, 1], got "
                f"{self.handover_keep_out_outside}"
            )
        if self.liftup_reach <= 0:
            raise PlanningError(f"intent.liftup_reach must be positive, got {self.liftup_reach}")


@dataclass(frozen=True)
class LearnedSettings:
    """The learned stages: interaction diffusion -> D(R,O) -> solver (planner.learned_proposer)."""

    # interaction samples (proposals) the learned proposer draws. On the 150 test pairs
    # (`python -m eval.benchmark`, interim weights) 16 vs 8 samples: held on the instructed part
    # within 8 validations 70/82/66% vs 58/76/58% (allegro/leap/shadow), first sample about
    # the same, 1-2 s more per pair
    samples: int = 16
    # the interaction model's weights: None the shipped model, else a folder holding
    # interaction.safetensors (a training run's output, to try it before `--install`)
    interaction_weights: str | None = None
    dro: bool = True  # D(R,O) point targets in the program (False: wrist + anchors)
    # the D(R,O) weights: None the shipped network, else a file or a name in learned/weights/
    # ("dro_no_anchors": the ablation trained without the anchors' contact map)
    dro_weights: str | None = None
    # how learned proposals become configurations: "drake" (the grasp program: collision,
    # coupling and joint-limit constraints) or "fit" (D(R,O) Grasp's way, the ablation
    # without Drake: every hand point's D(R,O) target, joints fitted to them by least squares
    # within the limits, no collision constraints; learned.joint_fit)
    solver: str = "drake"
    seed: int = 0  # the samples' seed: the same seed, the same proposals
    guidance: float | None = None  # classifier-free guidance; None: the model's own
    sample_steps: int | None = None  # DDIM steps per sample; None: the model's own
    # model-based proposals (planner.model_proposer) on the region the samples' anchors point
    # at (planner.learned_proposer.pointed_region), solved after the samples: at most this
    # many (0: none). The samples alone hold on the part within 8 validations no more often
    # than any of them holds (92/90/82% on the test pairs); where none does, the geometric
    # proposer often finds a grasp on the same region. Solved by the grasp program, so not
    # with solver "fit" (the ablation without Drake).
    region_proposals: int = 8
    # m; 0: off. On an object without the instruction's part labelled, a grasp that holds
    # counts for the instruction only where its fingertips vote (planner.labels) for the points
    # within this distance of the majority's anchors (pointed_region, one sample enough); one
    # that holds elsewhere is returned only when none does. On the 150 validation pairs held on
    # the instructed part within 8 validations 92/80/86% at 2 cm and at 1 cm against 90/80/84%
    # off (one pair each for Allegro and Shadow; docs/learned_log.md): off until it does more.
    region_vote: float = 0.0
    # Use and Handover on an object without labels: the cloud's parts found by asking the
    # interaction model for each part of the understood category (planner.model_labels), so
    # candidates meeting the intent are preferred and the region proposals are the
    # model-based proposer's on the labelled part, shaped by the intent (keep-outs included).
    # On the 150 test pairs (three seeds): Use met 43/56/59% -> 83/86/86% of the grasps held on
    # the part, Handover 34/29/23% -> 57/46/53%, first samples the same, within 8 -3/0/-1
    # points, a Use or Handover plan 1-4 s longer (docs/learned_log.md)
    model_labels: bool = True
    # with model_labels: Hold (an intent measured on its part's own points) on the labelled
    # part too, in place of the region the samples point at (kept where there are no labels),
    # and its later proposals the model-based proposer's on that part. On the validation
    # split's Hold pairs (three seeds): meets Hold 70/65/68% -> 79/80/66% of the grasps held,
    # within 8 92/94/94% -> 92/97/97%, 2.7/3.3/4.4 s a pair against 3.4/4.1/4.8 s
    labels_over_region: bool = True
    # with model_labels: samples drawn to seed each part other than the instructed one, and
    # (m) how far from the points its samples point at the instructed part's label reaches, the
    # rest going to the nearest other part (planner.model_labels trim_held; 0: as the walk
    # spreads it). 16 and 3 cm against 8 and 0, on the validation split's Use, Handover and
    # Hold pairs (three seeds): meeting the intent 67/71/69% -> 72/76/71% of the grasps held
    # on the part, within 8 92/93/95% -> 93/91/96%, time per pair within 10%
    label_samples: int = 16
    held_reach: float = 0.03
    # m; 0: off. With model_labels, once a grasp has held missing the intent, a later one
    # meeting it is returned in its place only where its fingertips vote (planner.labels) for
    # the instructed part kept within this distance of the points its samples point at
    # (ModelLabels.near_seed): the labelled part reaches across its border (a pan's handle
    # onto the body beside it), where grasps meeting the intent held another part, and a
    # grasp on the wrong part is worse than one missing the intent. 15 mm against off, three
    # seeds: validation Use/Handover/Hold pairs 2 gained and 1 lost within 8 (of 333 plans),
    # test pairs 5 gained, none lost (within 8 95/93/95% -> 97/95/95% over all intents),
    # meeting the intent 73/76/74% -> 73/74/74% (docs/learned_log.md)
    switch_reach: float = 0.015
    # with model_labels: the samples too are solved with the intent's keep-outs. Off: on the
    # validation pairs it moved first samples by -23 to +16 points per hand and intent for no
    # clear intent gain (docs/learned_log.md)
    sample_keep_outs: bool = False

    def __post_init__(self) -> None:
        if self.solver not in LEARNED_SOLVERS:
            raise PlanningError(
                f"unknown learned.solver {self.solver!r}; use one of {LEARNED_SOLVERS}"
            )
        if self.solver == "fit" and not self.dro:
            raise PlanningError(
                'learned.solver="fit" fits the joints to D(R,O)\'s point targets; it needs '
                "learned.dro=True"
            )
        for name in ("held_reach", "switch_reach"):
            if not getattr(self, name) >= 0:
                raise PlanningError(f"learned.{name} must be >= 0 m, got {getattr(self, name)}")
        if self.label_samples < 1:
            raise PlanningError(
                f"learned.label_samples must be at least 1, got {self.label_samples}"
            )


@dataclass(frozen=True)
class PlannerSettings:
    """Every knob of FunctionalPlanner: the proposer, the validation protocol and the groups."""

    # Where proposals come from: "model" (the geometric proposer of this module: needs part
    # labels and a "[Intent] a [Object] by [Part]" instruction), "learned" (interaction
    # diffusion -> D(R,O), planner.learned_proposer: any cloud, any sentence) or "auto": model
    # where the object has part labels and the instruction parses, learned otherwise. The
    # model-based proposer stays the default for labelled input until the learned one beats it
    # in `python -m eval.benchmark` (README, "Learned stages"). "direct" is the ablation of
    # direct diffusion: wrist and joints drawn by one model (weights "direct"), no anchors, no
    # D(R,O) and no solver, validated as drawn (the paper's Scene-Diffuser comparison).
    proposer: str = "auto"
    protocol: str = "paper"
    # A single-view cloud (an object with a `viewpoint`) is planned on with its hidden half
    # guessed by mirror symmetry (models.objects.completion): without it fingers are planned
    # through the unseen back of the object. The grasp is in the input's frame either way.
    complete_views: bool = True
    # A grasp planned on a bare cloud must also hold on this many other sets of collision
    # pieces, each from a random 70% of the cloud's points (ObjectModel.piece_variants): the
    # pieces follow the surface only to about the points' spacing, and grasps that hold on one
    # such guess but not on others are most of those that slip on the real object
    # (docs/planner_log.md, "Cloud checks"). 0: no check. Meshes have exact pieces: no effect.
    cloud_checks: int = 2
    schedule: ScheduleSettings = field(default_factory=ScheduleSettings)
    proposals: ProposalSettings = field(default_factory=ProposalSettings)
    intent: IntentSettings = field(default_factory=IntentSettings)
    learned: LearnedSettings = field(default_factory=LearnedSettings)
    program: ProgramSettings = field(default_factory=ProgramSettings)

    def __post_init__(self) -> None:
        if self.proposer not in PROPOSERS:
            raise PlanningError(f"unknown proposer {self.proposer!r}; use one of {PROPOSERS}")


RANKINGS = ("task", "epsilon")
PROPOSERS = ("auto", "model", "learned", "direct")
LEARNED_SOLVERS = ("drake", "fit")
PROPOSAL_ORDERS = ("anchors", "clearance")
HANDOVER_END_ON = ("both", "only", "off")
# the groups of PlannerSettings: field name -> settings class
GROUPS: dict[str, type] = {
    "schedule": ScheduleSettings,
    "proposals": ProposalSettings,
    "intent": IntentSettings,
    "learned": LearnedSettings,
    "program": ProgramSettings,
}


def setting_keys() -> list[str]:
    """Every key `with_overrides` takes: top-level fields, then `group.field` per group."""
    keys = []
    for f in dataclasses.fields(PlannerSettings):
        group = GROUPS.get(f.name)
        if group is None:
            keys.append(f.name)
        else:
            keys += [f"{f.name}.{g.name}" for g in dataclasses.fields(group)]
    return keys


def with_overrides(settings: PlannerSettings, overrides: Mapping[str, object]) -> PlannerSettings:
    """`settings` with `overrides` set: dotted keys for a group's field (`schedule.solve_batch`,
    `intent.aware`, `program.major_iterations`), plain ones for the top level (`protocol`,
    `proposer`). Each group is replaced once with all of its changes, so that fields checked
    together (`learned.solver` "fit" with `learned.dro`) can change together. An unknown key
    raises a PlanningError that lists the valid ones."""
    keys = setting_keys()
    top: dict[str, object] = {}
    grouped: dict[str, dict[str, object]] = {}
    for key, value in overrides.items():
        if key not in keys:
            like = [k for k in keys if k.rpartition(".")[2] == key or k.replace(".", "_") == key]
            like = like or difflib.get_close_matches(key, keys, n=1)  # a typo, a renamed key
            hint = f" (did you mean {like[0]!r}?)" if len(like) == 1 and key not in GROUPS else ""
            raise PlanningError(
                f"unknown planner setting {key!r}{hint}; the settings are: {', '.join(keys)}"
            )
        group, dot, name = key.partition(".")
        if dot:
            grouped.setdefault(group, {})[name] = value
        else:
            top[key] = value
    for group, changes in grouped.items():
        top[group] = dataclasses.replace(getattr(settings, group), **changes)
    return dataclasses.replace(settings, **top) if top else settings
