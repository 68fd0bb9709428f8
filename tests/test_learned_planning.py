"""Planning on the learned stages: any cloud, any sentence (planner.learned_proposer)."""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial import cKDTree

from learned.understand import named_intents, repaired, understand
from models.errors import InstructionError, PlanningError
from models.hands import load_hand
from models.objects import load_object, make_object, parse_instruction
from planner import plan_grasp
from planner.functional import FunctionalPlanner, PlannerSettings
from planner.learned_proposer import pointed_region, sample_start
from planner.settings import IntentSettings, LearnedSettings, ScheduleSettings
from tests.tiny_models import TINY_INTERACTION


def test_a_parsed_instruction_is_kept_and_a_free_sentence_is_read_by_meaning():
    kept = understand("Use a mug by handle")
    assert kept.parsed and kept.instruction.text == "Use a mug by handle"
    read = understand("Would you kindly employ this spray bottle? Grasp it at the trigger.")
    assert not read.parsed and read.instruction.text == "Use a spray bottle by trigger"
    assert read.similarity > read.runner_up_similarity
    # the verb decides the intent where the embedding would not
    assert named_intents("pick up the bottle from the top") == ["Liftup"]
    assert understand("pick up the bottle from the top").instruction.intent == "Liftup"
    with pytest.raises(InstructionError, match="empty"):
        understand("   ")


def test_the_request_s_own_verb_decides_over_how_the_part_is_held():
    """The first verb names the intent; a later one says how the part is held ("Grasp it at
    the handle"), and a verb's word after a determiner is a noun ("your hand")."""
    text = "Would you kindly hoist this mug? Grasp it at the handle."
    assert named_intents(text) == ["Liftup", "Hold"]
    assert understand(text).instruction.text == "Liftup a mug by handle"
    assert named_intents("Could you hand me the knife? Hold it by the blade.")[0] == "Handover"
    assert named_intents("with your hand on the handle, use the knife") == ["Use"]
    assert understand("with your hand on the handle, use the knife").instruction.intent == "Use"


@pytest.mark.parametrize(
    "text, read",
    [
        ("pick up the mug and hold it by the handle", "Liftup a mug by handle"),
        ("hold the wine glass by the stem and lift it", "Hold a wine glass by stem"),
        ("lift up the bottles by their necks", "Liftup a bottle by neck"),
        ("Use a coffee mug by handle", "Use a mug by handle"),
        ("Use a widget by knob", "Use a widget by knob"),  # a user's own words stand
    ],
)
def test_a_parse_that_caught_a_clause_is_mended(text, read):
    assert understand(text).instruction.text == read
    assert repaired(parse_instruction("Use a spray bottle and more by trigger")).category == (
        "spray_bottle"
    )
    assert repaired(parse_instruction("Hold a mug by handle or body")) is None  # by meaning


def test_auto_takes_the_model_for_labelled_parsed_input_and_learned_otherwise():
    mug = make_object("mug", 3)
    cloud = load_object(mug.sample_cloud(2048).points)
    planner = FunctionalPlanner("allegro")
    assert planner.proposer_for(mug, "Use a mug by handle") == "model"
    assert planner.proposer_for(mug, "grab the mug by its handle") == "learned"
    assert planner.proposer_for(cloud, "Use a mug by handle") == "learned"
    with pytest.raises(PlanningError, match="proposer"):
        PlannerSettings(proposer="dreamed")


@pytest.mark.parametrize("hand_name", ["allegro", "leap", "shadow"])
def test_an_unlabelled_cloud_and_a_sentence_are_planned(hand_name):
    cloud = make_object("mug", 3).sample_cloud(4096).points
    settings = PlannerSettings(
        schedule=ScheduleSettings(max_candidates=2), learned=LearnedSettings(samples=4)
    )
    result = plan_grasp(cloud, "hold the mug around its body", hand_name, settings)
    assert result.proposer == "learned"
    assert result.understood["understood_as"] == "Hold a mug by body"
    assert 1 <= len(result.candidates)
    samples = [c for c in result.candidates if c.proposal.kind == "learned"]
    # the samples first, then (where they are used up) proposals on the region they point at
    assert result.candidates[: len(samples)] == samples
    qualities = [c.proposal.anchor_quality for c in samples]
    assert qualities == sorted(qualities, reverse=True)
    # the fingers start where the hand's files say samples start
    start = sample_start(load_hand(hand_name))
    assert all(np.array_equal(c.proposal.q, start) for c in samples)
    # D(R,O)'s point targets reach the program, with weights from its predicted closeness
    p = result.candidates[0].proposal
    assert len(p.point_index) == len(p.point_targets) == len(p.point_weights) > 0
    assert np.all((p.point_weights > 0) & (p.point_weights <= 1))
    validated = [c for c in result.candidates if c.order is not None]
    assert validated and all(c.part is None for c in validated)  # no labels: no part vote
    assert "interaction" in result.stage_times() and "dro" in result.stage_times()


@pytest.mark.parametrize("hand_name", ["allegro", "leap", "shadow"])
def test_samples_start_closed_by_the_hands_own_fraction(hand_name):
    hand = load_hand(hand_name)
    assert np.array_equal(hand.closed_pose(0.0), hand.open_pose)
    closed = hand.closed_pose(0.35)
    assert np.all((closed >= hand.lower) & (closed <= hand.upper))
    moved = closed - hand.open_pose
    fixed = hand.closing_direction == 0
    assert np.all(moved[fixed] == 0)  # joints with no closing direction stay open
    # the others move toward their closing limit, 0.35 of the range or up to the limit
    toward = np.sign(moved[~fixed]) == hand.closing_direction[~fixed]
    at_limit = np.isclose(closed, hand.lower) | np.isclose(closed, hand.upper)
    assert np.all(toward | (moved[~fixed] == 0) & at_limit[~fixed])
    start = sample_start(hand)
    fraction = hand.meta.learned_start_closure
    assert np.allclose(start, hand.closed_pose(fraction), atol=1e-9)
    if fraction == 0:
        assert np.array_equal(start, hand.open_pose)


def test_the_region_follows_the_anchors_of_most_samples():
    """Eleven samples on one end of a bar and three on the other: the region is the first end."""
    points = np.column_stack([np.linspace(0, 0.3, 301), np.zeros(301), np.zeros(301)])
    rng = np.random.default_rng(0)
    majority = (0.05 + rng.normal(0, 0.004, (11, 4, 1))) * [1, 0, 0]
    minority = (0.25 + rng.normal(0, 0.004, (3, 4, 1))) * [1, 0, 0]
    minority[0, 3] = np.nan  # a pinch leaves its fourth finger free
    region = pointed_region(points, np.concatenate([minority, majority]))
    x = points[region, 0]
    assert region.sum() > 10 and x.min() > 0.02 and x.max() < 0.09


@pytest.mark.parametrize("hand_name", ["allegro", "leap", "shadow"])
def test_after_the_samples_come_model_proposals_on_the_region_they_point_at(hand_name):
    cloud = load_object(make_object("mug", 3).sample_cloud(4096).points)
    settings = PlannerSettings(
        schedule=ScheduleSettings(max_candidates=20),
        learned=LearnedSettings(samples=4, region_proposals=3, dro=False),
    )
    planner = FunctionalPlanner(hand_name, settings)
    # nothing holds: every proposal is solved, in order
    planner._validate = lambda program, obj, instruction, cand: None
    result = planner.plan(cloud, "grab the mug by its handle")
    kinds = [c.proposal.kind for c in sorted(result.candidates, key=lambda c: c.rank)]
    assert kinds[:4] == ["learned"] * 4 and len(kinds) == 7
    assert set(kinds[4:]) <= {"row", "pinch", "palm"}
    samples = np.concatenate([c.proposal.anchors for c in result.candidates[:4]])
    region = pointed_region(cloud.points, samples.reshape(4, 4, 3))
    inside = cKDTree(cloud.points[region])
    for c in result.candidates[4:]:
        used = np.all(np.isfinite(c.proposal.anchors), axis=1)
        assert inside.query(c.proposal.anchors[used])[0].max() < 1e-9
    assert "region" in result.stage_times()


def test_with_a_region_vote_a_grasp_off_the_region_is_passed_over(monkeypatch):
    """Every grasp holds; the first one's fingertips vote off the region the samples point
    at, so the search goes on and the next one, on the region, is returned."""
    from planner import functional
    from planner.learned_proposer import REGION_PART

    cloud = load_object(make_object("mug", 3).sample_cloud(4096).points)
    settings = PlannerSettings(
        schedule=ScheduleSettings(max_candidates=4, solve_batch=1),
        learned=LearnedSettings(samples=6, region_proposals=0, dro=False, region_vote=0.02),
    )
    planner = FunctionalPlanner("allegro", settings)

    def holds(program, obj, instruction, cand):
        cand.grasp, cand.success, cand.part = object(), True, None

    voted = []

    def vote(hand, wrist, q, obj):
        assert set(obj.part_names) == {REGION_PART, "rest"}
        voted.append(REGION_PART if voted else "rest")
        return voted[-1]

    planner._validate = holds
    monkeypatch.setattr(functional, "grasp_part", vote)
    result = planner.plan(cloud, "hold the mug by its handle")
    validated = sorted((c for c in result.candidates if c.order is not None), key=lambda c: c.order)
    assert voted == ["rest", REGION_PART] and len(validated) == 2
    assert result.best is validated[1]
    assert all(c.part is None for c in result.candidates)  # no labels: no part reported
    assert not any("region" in n for n in result.notes)


@pytest.mark.parametrize("hand_name", ["allegro", "leap", "shadow"])
def test_the_direct_ablation_validates_its_samples_as_drawn(hand_name, monkeypatch):
    """proposer="direct": wrist and joints from one diffusion model (here an untrained small
    one, standing in for learned/weights/direct), nothing solved, each sample validated."""
    import learned.interaction as interaction

    config = replace(TINY_INTERACTION, diffusion_steps=20, sample_steps=3, target="joints")
    stand_in = interaction.InteractionModel.new(config, seed=0)
    monkeypatch.setitem(interaction._loaded, f"None:{interaction.DIRECT_NAME}", stand_in)
    cloud = make_object("mug", 3).sample_cloud(2048).points
    settings = PlannerSettings(
        proposer="direct",
        schedule=ScheduleSettings(max_candidates=2),
        learned=LearnedSettings(samples=3),
    )
    result = plan_grasp(cloud, "Use a mug by handle", hand_name, settings)
    assert result.proposer == "direct" and len(result.candidates) == 3
    hand = FunctionalPlanner(hand_name).hand
    for c in result.candidates:
        assert c.proposal.kind == "direct" and c.solve.solver_status == "as drawn"
        assert c.proposal.point_targets is None  # no D(R,O)
        np.testing.assert_array_equal(c.solve.q, c.proposal.q)  # nothing solved
        assert (c.solve.q >= hand.lower).all() and (c.solve.q <= hand.upper).all()
    assert sum(c.order is not None for c in result.candidates) >= 1
    assert "direct" in result.stage_times() and "dro" not in result.stage_times()


@pytest.mark.slow
def test_learned_proposals_hold_a_mug_by_its_body():
    """The shipped weights' grasps hold: on the labelled mug the part is voted too."""
    mug = make_object("mug", 3)
    result = plan_grasp(mug, "Hold a mug by body", "allegro", PlannerSettings(proposer="learned"))
    assert result.proposer == "learned" and result.success
    assert result.part_touched == "body"


@pytest.mark.slow
@pytest.mark.parametrize("hand_name", ["allegro", "leap", "shadow"])
def test_liftup_is_checked_on_a_bare_cloud_and_samples_facing_down_go_first(hand_name):
    """Liftup needs no part labels: on a bare cloud every solved sample is checked, and the
    samples drawn palm down above the centre of mass are solved first, above a table."""
    from planner.intent import faces_intent

    cloud = load_object(make_object("pan", 3).sample_cloud(4096).points)
    planner = FunctionalPlanner(
        hand_name,
        PlannerSettings(
            schedule=ScheduleSettings(max_candidates=1), learned=LearnedSettings(samples=8)
        ),
    )
    # only solve: proposals and their order are what is tested here
    planner._validate = lambda program, obj, instruction, cand: None
    result = planner.plan(cloud, "lift up the pan by its handle")
    assert result.instruction.intent == "Liftup"
    shaped = [c.proposal.shaped for c in sorted(result.candidates, key=lambda c: c.rank)]
    assert any(shaped) and shaped == sorted(shaped, reverse=True)
    for c in result.candidates:
        wrist = c.proposal.wrist
        assert c.proposal.shaped == faces_intent(wrist, cloud, planner.hand, result.instruction)
        if c.solve.ok:
            assert c.intent is not None and c.intent.intent == "Liftup"
            if c.proposal.shaped:  # solved above the table
                assert c.intent["above_table"].value >= -1e-3


@pytest.mark.slow
@pytest.mark.parametrize("over_region", [True, False])
def test_hold_is_checked_on_a_bare_cloud_on_the_model_labels_or_the_pointed_region(over_region):
    """Hold's palm contact needs a part: on a bare cloud the part as the interaction model
    labels it (learned.labels_over_region), or else the region the samples point at, is that
    part, so every solved candidate is checked (and the held ones meeting it preferred); with
    intent awareness off nothing is checked."""
    cloud = load_object(make_object("mug", 3).sample_cloud(4096).points)

    def planned(aware: bool):
        settings = PlannerSettings(
            schedule=ScheduleSettings(max_candidates=1),
            learned=LearnedSettings(samples=8, labels_over_region=over_region),
            intent=IntentSettings(aware=aware),
        )
        planner = FunctionalPlanner("allegro", settings)
        planner._validate = lambda program, obj, instruction, cand: None  # solves only
        return planner.plan(cloud, "Hold a mug by body")

    result = planned(True)
    assert result.instruction.intent == "Hold"
    assert ("model_labels" in result.understood) == over_region
    if over_region:
        assert result.understood["model_labels"]["body"] > 0
    solved = [c for c in result.candidates if c.solve.ok]
    assert solved
    for c in solved:
        assert c.intent is not None and c.intent.intent == "Hold"
        assert [x.name for x in c.intent.criteria] == ["palm_contact", "force_closure"]
    assert all(c.intent is None for c in planned(False).candidates)


@pytest.mark.slow
def test_without_dro_the_program_gets_wrist_and_anchors_only():
    cloud = make_object("mug", 3).sample_cloud(4096).points
    settings = PlannerSettings(
        schedule=ScheduleSettings(max_candidates=1), learned=LearnedSettings(samples=2, dro=False)
    )
    result = plan_grasp(cloud, "hold the mug around its body", "allegro", settings)
    assert all(c.proposal.point_index is None for c in result.candidates)
    assert "dro" not in result.stage_times()


@pytest.mark.slow
def test_without_drake_the_joints_are_fitted_to_dro_targets():
    """The ablation without Drake: every candidate comes from the joint fit, unconstrained,
    and goes to validation however deep it is in the object."""
    cloud = make_object("mug", 3).sample_cloud(4096).points
    settings = PlannerSettings(
        schedule=ScheduleSettings(max_candidates=1),
        learned=LearnedSettings(samples=2, solver="fit"),
    )
    result = plan_grasp(cloud, "hold the mug around its body", "allegro", settings)
    assert result.candidates
    for cand in result.candidates:
        assert cand.solve.solver_status == "joint fit" and cand.solve.ok
        assert cand.proposal.point_index is not None
    assert any(c.validation for c in result.candidates)


@pytest.mark.slow
def test_cli_plans_a_cloud_file_from_a_sentence(tmp_path):
    cloud = tmp_path / "mug.npy"
    np.save(cloud, make_object("mug", 3).sample_cloud(4096).points)
    run = subprocess.run(
        [
            sys.executable, "-m", "planner.cli", "plan", "--mesh", str(cloud), "--text",
            "hold the mug around its body", "--hand", "allegro", "--samples", "4",
            "--candidates", "2", "--json",
        ],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert run.returncode in (0, 1), run.stderr
    summary = json.loads(run.stdout)
    assert summary["proposer"] == "learned"
    assert summary["understood"]["understood_as"] == "Hold a mug by body"
    model = subprocess.run(
        [
            sys.executable, "-m", "planner.cli", "plan", "--mesh", str(cloud), "--text",
            "Use a mug by handle", "--proposer", "model",
        ],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert model.returncode == 2 and "--proposer learned" in model.stderr


def test_a_training_runs_interaction_weights_are_used_where_given(tmp_path):
    """learned.interaction_weights: a folder of interaction weights (a run's output, tried
    before --install) draws the samples instead of the shipped model."""
    from learned.interaction import InteractionModel
    from models.hands import load_hand
    from planner.learned_proposer import learned_proposals

    config = replace(TINY_INTERACTION, diffusion_steps=20, sample_steps=3)
    InteractionModel.new(config, seed=0).save(str(tmp_path))
    mug, hand = make_object("mug", 3), load_hand("allegro")
    mine = learned_proposals(mug, "Use a mug by handle", hand, 2, weights=str(tmp_path))
    again = InteractionModel.load(str(tmp_path)).sample(
        mug.points, "Use a mug by handle", hand, 2, None, seed=0
    )
    np.testing.assert_allclose(mine.wrists, again[0])
    shipped = learned_proposals(mug, "Use a mug by handle", hand, 2)
    assert not np.allclose(shipped.wrists, mine.wrists)
