"""The model-based planner reads the instruction's intent: proposals shaped by each intent's
definition (models/objects/intents.py) and candidates meeting it validated first."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from models.errors import PlanningError
from models.hands import load_hand
from models.objects import make_object
from models.objects.intents import RULES, definition
from planner.functional import CandidateResult, FunctionalPlanner, PlannerSettings
from planner.intent import Criterion, IntentCheck, region_points
from planner.settings import IntentSettings, ProposalSettings, ScheduleSettings


@pytest.fixture(scope="module")
def knife():
    return make_object("knife", 0)


@pytest.fixture(scope="module")
def mug():
    return make_object("mug", 0)


def anchored(proposal) -> np.ndarray:
    return proposal.anchors[np.isfinite(proposal.anchors).all(axis=1)]


def tip_radius(hand_name: str) -> float:
    hand = load_hand(hand_name)
    return float(np.mean([hand.meta.fingertip(n).radius for n in hand.meta.anchor_fingers]))


def test_liftup_proposals_face_down(hand_name, mug):
    hand = load_hand(hand_name)
    settings = PlannerSettings()
    meaning = definition("mug", "Liftup", "handle")
    proposals = FunctionalPlanner(hand_name, settings).propose(mug, "handle", meaning)
    assert len(proposals) >= settings.proposals.max_proposals
    normal = np.asarray(hand.meta.palm.normal, dtype=float)
    half = settings.proposals.max_proposals // 2
    # from above and by part alone in turn, in case those from above all slip
    plain = FunctionalPlanner(hand_name, settings).propose(mug, "handle")
    assert [p.wrist.tolist() for p in proposals[1 : 2 * half : 2]] == [
        p.wrist.tolist() for p in plain[:half]
    ]
    for p in proposals[: 2 * half : 2]:
        world = Rotation.from_quat(p.wrist[3:], scalar_first=True).apply(normal)
        tilt = np.degrees(np.arccos(np.clip(-world[2] / np.linalg.norm(world), -1, 1)))
        assert tilt <= settings.intent.liftup_tilt_deg + 1.0
    # by part alone the palm faces the handle from every side
    sideways = FunctionalPlanner(hand_name, settings).propose(mug, "handle")
    tilts = [Rotation.from_quat(p.wrist[3:], scalar_first=True).apply(normal)[2] for p in sideways]
    assert max(tilts) > -0.5


def test_handover_anchors_keep_clear_of_the_other_parts(hand_name, knife):
    blade = knife.point_labels == knife.part_names.index("blade")
    others = cKDTree(knife.points[~blade])
    farthest = others.query(knife.points[blade])[0].max()
    needed = min(RULES.handover.other_part_clearance + tip_radius(hand_name), farthest - 0.01)
    meaning = definition("knife", "Handover", "blade")
    half = PlannerSettings().proposals.max_proposals // 2
    shaped = FunctionalPlanner(hand_name).propose(knife, "blade", meaning)[: 2 * half : 2]
    plain = FunctionalPlanner(hand_name).propose(knife, "blade")
    gaps = np.concatenate([others.query(anchored(p))[0] for p in shaped])
    assert gaps.min() >= needed - 1e-9
    # without the intent, anchors come nearer the handle
    assert np.concatenate([others.query(anchored(p))[0] for p in plain]).min() < needed


def palm_directions(hand_name: str, proposals) -> np.ndarray:
    normal = np.asarray(load_hand(hand_name).meta.palm.normal, dtype=float)
    normal /= np.linalg.norm(normal)
    return np.array(
        [Rotation.from_quat(p.wrist[3:], scalar_first=True).apply(normal) for p in proposals]
    )


def test_handover_adds_end_on_frames_where_the_part_fits_the_hand(hand_name):
    """A pen handed over by its cap gets proposals with the palm beyond the cap's end facing
    the barrel (the whole hand on the cap's side); a pan's body, wider than any hand's span,
    gets none; nor does the pen with the end-on frames off."""
    settings = PlannerSettings()
    near = np.cos(np.radians(settings.intent.liftup_tilt_deg + 1.0))

    def facing(cat: str, part: str, end_on: str) -> np.ndarray:
        obj = make_object(cat, 0)
        held = obj.point_labels == obj.part_names.index(part)
        toward = obj.points[~held].mean(axis=0) - obj.points[held].mean(axis=0)
        toward /= np.linalg.norm(toward)
        planner = FunctionalPlanner(
            hand_name, PlannerSettings(intent=IntentSettings(handover_end_on=end_on))
        )
        shaped = planner.propose(obj, part, definition(cat, "Handover", part))
        shaped = [p for p in shaped if p.shaped]
        return palm_directions(hand_name, shaped) @ toward

    assert (facing("pen", "cap", "both") >= near).any()
    assert (facing("pen", "cap", "only") >= near).all()
    assert not (facing("pen", "cap", "off") >= near).any()
    assert not (facing("pan", "body", "both") >= near).any()
    with pytest.raises(PlanningError, match="handover_end_on"):
        IntentSettings(handover_end_on="sideways")
    with pytest.raises(PlanningError, match="handover_keep_out_outside"):
        IntentSettings(handover_keep_out_outside=0.0)


def test_use_anchors_keep_clear_of_the_working_parts(hand_name, knife):
    meaning = definition("knife", "Use", "handle")
    blade = cKDTree(np.vstack([region_points(knife, r) for r in meaning.working]))
    proposals = FunctionalPlanner(hand_name).propose(knife, "handle", meaning)
    gaps = np.concatenate([blade.query(anchored(p))[0] for p in proposals])
    assert gaps.min() >= RULES.use.working_clearance + tip_radius(hand_name) - 1e-9


def test_hold_proposes_power_grasps_in_turn_with_regular_ones(hand_name, mug):
    settings = PlannerSettings()
    proposals = FunctionalPlanner(hand_name, settings).propose(
        mug, "body", definition("mug", "Hold", "body")
    )
    half = settings.proposals.max_proposals // 2
    assert [p.kind for p in proposals[: 2 * half]] == ["palm", "row"] * half
    assert all(p.palm_target is not None for p in proposals[: 2 * half : 2])


def test_without_intent_awareness_proposals_are_by_part(hand_name, mug):
    meaning = definition("mug", "Liftup", "handle")
    off = PlannerSettings(intent=IntentSettings(aware=False))
    a = FunctionalPlanner(hand_name, off).propose(mug, "handle", meaning)
    b = FunctionalPlanner(hand_name, off).propose(mug, "handle")
    assert [p.wrist.tolist() for p in a] == [p.wrist.tolist() for p in b]


def _check(ok: bool) -> IntentCheck:
    crit = Criterion("palm_down", ok, 0.0, "<= 30 deg")
    return IntentCheck("Liftup", ok, (crit,), "ok" if ok else "palm_down: tilted")


def _fake(monkeypatch, intent_ok, holds) -> None:
    """Every proposal solves; rank r meets its intent when intent_ok(r) and holds on the
    instructed part when holds(r); better task metric for lower ranks."""
    from planner import functional
    from planner.grasp_program import SolveResult

    solving = []  # the ranks solved, in order: their intent checks follow in the same order

    def fake_solve(self, program, obj, rank, proposal, table_top=None):
        solving.append(rank)
        solved = SolveResult(proposal.wrist, proposal.q, True, 0.001, 0.0, True, "fake", 0.0)
        return CandidateResult(rank, proposal, solved, quality=0.5, task_quality=1 - rank / 100)

    def fake_validate(self, program, obj, instruction, cand):
        cand.grasp, cand.success, cand.part = object(), holds(cand.rank), instruction.part

    monkeypatch.setattr(FunctionalPlanner, "_solve", fake_solve)
    monkeypatch.setattr(FunctionalPlanner, "_validate", fake_validate)
    monkeypatch.setattr(
        functional, "check_configuration", lambda *args, **kwargs: _check(intent_ok(solving.pop(0)))
    )
    monkeypatch.setattr(functional, "processes", lambda setting: 1)  # the fakes count here


def test_candidates_meeting_the_intent_are_validated_first_where_asked(monkeypatch, mug):
    _fake(monkeypatch, intent_ok=lambda r: r >= 2, holds=lambda r: True)
    settings = PlannerSettings(
        schedule=ScheduleSettings(solve_batch=4, sweep_after=None, intent_first=4),
        proposals=ProposalSettings(max_proposals=8),
    )
    result = FunctionalPlanner("allegro", settings).plan(mug, "Liftup a mug by handle")
    assert result.success and result.intent_ok
    assert result.best.rank == 2 and result.best.order == 0


def test_by_default_the_best_goes_first_and_a_hold_off_intent_keeps_the_search(monkeypatch, mug):
    """intent_first 0: the best candidate is validated first whatever its intent; once it holds
    without meeting the intent only candidates meeting it are validated, and one that holds
    is returned."""
    _fake(monkeypatch, intent_ok=lambda r: r >= 2, holds=lambda r: True)
    settings = PlannerSettings(proposals=ProposalSettings(max_proposals=8))
    result = FunctionalPlanner("allegro", settings).plan(mug, "Liftup a mug by handle")
    validated = sorted((c for c in result.candidates if c.order is not None), key=lambda c: c.order)
    assert [c.rank for c in validated] == [0, 2]
    assert result.success and result.intent_ok and result.best.rank == 2


def test_an_off_intent_grasp_is_returned_with_a_note_when_nothing_else_holds(monkeypatch, mug):
    # only rank 0 holds, and it misses the intent; the intent-meeting ones slip
    _fake(monkeypatch, intent_ok=lambda r: r != 0, holds=lambda r: r == 0)
    settings = PlannerSettings(
        schedule=ScheduleSettings(
            solve_batch=4, max_candidates=8, sweep_after=None, intent_first=2
        ),
        proposals=ProposalSettings(max_proposals=8),
    )
    result = FunctionalPlanner("allegro", settings).plan(mug, "Liftup a mug by handle")
    assert result.success and result.best.rank == 0 and result.intent_ok is False
    assert any("Liftup definition" in n for n in result.notes)
    # after the first two intent-meeting failures, rank 0 (best quality) is validated, then
    # only candidates meeting the intent
    validated = sorted((c for c in result.candidates if c.order is not None), key=lambda c: c.order)
    order = [c.rank for c in validated]
    assert order[:3] == [1, 2, 0] and 0 not in order[3:]


def test_liftup_plans_the_shaped_proposals_above_a_table(knife):
    from planner.intent_pieces import TABLE_GAP, table_under

    slab = table_under(knife)
    bottom = knife.mesh.vertices[:, 2].min()
    assert np.isclose(slab[:, 2].max(), bottom + TABLE_GAP)
    assert slab[:, 0].min() < knife.mesh.vertices[:, 0].min()
    assert slab[:, 0].max() > knife.mesh.vertices[:, 0].max()
    proposals = FunctionalPlanner("allegro").propose(
        knife, "handle", definition("knife", "Liftup", "handle")
    )
    shaped = [p.shaped for p in proposals]
    assert any(shaped) and not all(shaped)


def test_liftup_anchors_climb_toward_the_palm_as_set(hand_name, knife):
    """`intent.liftup_toward_palm`: 0 puts the anchors at the handle's widest points (squeezed
    straight across), higher values pull them up toward the palm above."""
    meaning = definition("knife", "Liftup", "handle")

    def heights(toward: float) -> np.ndarray:
        settings = PlannerSettings(intent=IntentSettings(liftup_toward_palm=toward))
        proposals = FunctionalPlanner(hand_name, settings).propose(knife, "handle", meaning)
        shaped = [p for p in proposals if p.shaped]
        return np.concatenate([anchored(p)[:, 2] for p in shaped])

    across, up = heights(0.0), heights(1.0)
    assert up.mean() > across.mean() + 0.001
    with pytest.raises(PlanningError, match="liftup_toward_palm"):
        IntentSettings(liftup_toward_palm=2.0)


def test_use_keep_out_covers_each_working_part_with_the_clearance(knife):
    """The keep-out of a knife's blade holds every blade point at least most of the working
    clearance inside its hull (26 growth directions: 0.8 of it at worst), and ends short of
    the handle's far end."""
    from scipy.spatial import ConvexHull

    from planner.intent_pieces import keep_out

    meaning = definition("knife", "Use", "handle")
    (piece,) = keep_out(knife, meaning)
    blade = region_points(knife, meaning.working[0])
    hull = ConvexHull(piece)
    inside = -(blade @ hull.equations[:, :3].T + hull.equations[:, 3]).max(axis=1)
    assert inside.min() >= 0.8 * RULES.use.working_clearance
    handle = knife.points[knife.point_labels == knife.part_names.index("handle")]
    depth = -(handle @ hull.equations[:, :3].T + hull.equations[:, 3]).max(axis=1)
    assert (depth < 0).mean() > 0.5  # most of the handle is outside the keep-out


def test_use_grasps_keep_the_whole_hand_clear_of_the_working_parts(hand_name):
    """With the keep-out every shaped Use candidate that solves has each hand point at least
    the working clearance (less 1 mm of geometry difference) from a wine glass's bowl, which
    the anchors alone do not ensure; without it some come closer."""
    glass = make_object("wine_glass", 4)
    gaps = {}
    for keep in (True, False):
        settings = PlannerSettings(
            schedule=ScheduleSettings(max_candidates=1),
            proposals=ProposalSettings(max_proposals=4),
            intent=IntentSettings(use_keep_out=keep),
        )
        result = FunctionalPlanner(hand_name, settings).plan(glass, "Use a wine glass by stem")
        gaps[keep] = [
            c.intent["working_parts_clear"].value
            for c in result.candidates
            if c.solve.ok and c.proposal.shaped
        ]
    assert gaps[True] and min(gaps[True]) >= RULES.use.working_clearance - 0.001
    assert gaps[False] and min(gaps[False]) < RULES.use.working_clearance


def test_handover_keep_out_grows_the_other_parts_where_the_held_part_stays_outside(knife):
    """A knife handed over by its blade gets its handle grown by 2 cm as a keep-out, holding
    every handle point that deep inside and leaving most of the blade out; a cup's body grown
    by 2 cm would swallow its rim, so a cup handed over by the rim gets none."""
    from scipy.spatial import ConvexHull

    from planner.intent_pieces import inside_hull, keep_out

    (piece,) = keep_out(knife, definition("knife", "Handover", "blade"))
    handle = knife.points[knife.point_labels == knife.part_names.index("handle")]
    blade = knife.points[knife.point_labels == knife.part_names.index("blade")]
    eq = ConvexHull(piece).equations
    depth = -(handle @ eq[:, :3].T + eq[:, 3]).max(axis=1)
    assert depth.min() >= 0.8 * RULES.handover.other_part_clearance
    assert inside_hull(piece, blade).mean() < 0.5
    assert keep_out(make_object("cup", 0), definition("cup", "Handover", "rim")) == []
    # a bottle's body and cap, each grown by 2 cm, cover most of its neck between them
    assert keep_out(make_object("bottle", 0), definition("bottle", "Handover", "neck")) == []
    assert (
        keep_out(
            knife, definition("knife", "Handover", "blade"), IntentSettings(handover_keep_out=False)
        )
        == []
    )
    # a pen's cap lies within 2 cm of its barrel for just over half its length: the barrel's
    # keep-out where 30% of the held part outside is enough (the default), none where half is
    # asked (the tip's, at the pen's other end, either way)
    pen, cap = make_object("pen", 0), definition("pen", "Handover", "cap")
    assert len(keep_out(pen, cap)) == 2
    assert len(keep_out(pen, cap, IntentSettings(handover_keep_out_outside=0.5))) == 1


def test_an_intent_the_part_cannot_meet_stops_at_the_first_hold(monkeypatch):
    """Handover by a cup's rim (planner.intent.unmeetable): the first grasp that holds on the
    rim is returned, the reason first among the notes, with no search for one meeting it; on a
    part where the intent may be met the search goes on."""
    _fake(monkeypatch, intent_ok=lambda r: False, holds=lambda r: True)
    settings = PlannerSettings(
        schedule=ScheduleSettings(solve_batch=4, sweep_after=None),
        proposals=ProposalSettings(max_proposals=12),
    )
    planner = FunctionalPlanner("allegro", settings)
    result = planner.plan(make_object("cup", 0), "Handover a cup by rim")
    assert result.success and result.intent_ok is False and result.best.rank == 0
    assert result.unmeetable and result.notes[0] == result.unmeetable
    assert len(result.candidates) == 4  # one batch
    searched = planner.plan(make_object("mug", 0), "Handover a mug by body")
    assert searched.unmeetable is None and len(searched.candidates) > 4


@pytest.mark.parametrize("text", ["Liftup a mug by handle", "Handover a mug by body"])
def test_the_search_for_the_intent_passes_over_proposals_that_will_miss_it(monkeypatch, mug, text):
    """Once a grasp has held without meeting the intent, proposals whose drawn wrist fails
    what it decides (Liftup's palm down; Handover's palm away from the free end), or whose
    anchors lie beside a part kept clear, are passed over unsolved, each with its reason; the
    rest are solved (planner.intent.proposal_misses, with the real proposals)."""
    _fake(monkeypatch, intent_ok=lambda r: False, holds=lambda r: r == 0)
    hand = "leap"  # its pinches leave a finger's anchor NaN
    result = FunctionalPlanner(hand, PlannerSettings()).plan(mug, text)
    assert result.success and result.best.rank == 0 and result.intent_ok is False
    assert result.passed, "no proposal was passed over"
    assert all(
        why.startswith(("the drawn wrist fails", "an anchor lies"))
        for why in result.passed.values()
    )
    solved = {c.rank for c in result.candidates}
    assert not solved & set(result.passed)
    assert solved | set(result.passed) == set(range(len(solved) + len(result.passed)))
    # not passed over: with the setting off every proposal is solved
    off = PlannerSettings(schedule=ScheduleSettings(pass_over_misses=False))
    everything = FunctionalPlanner(hand, off).plan(mug, text)
    assert not everything.passed
    assert len(everything.candidates) == len(solved) + len(result.passed)
