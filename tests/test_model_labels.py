"""Part labels asked of the interaction model, and Use / Handover checked with them on clouds."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from eval.model_labels import covered
from learned.interaction import load_model
from models.errors import PlanningError
from models.hands import load_hand
from models.objects import load_object, make_object, parse_instruction
from planner.functional import FunctionalPlanner, PlannerSettings
from planner.intent_pieces import grown_hull, inside_hull
from planner.model_labels import (
    model_labels,
    nearest_seed,
    part_seeds,
    part_texts,
    spread_labels,
    trim_held,
)
from planner.settings import LearnedSettings, ScheduleSettings


def test_each_part_is_asked_for_with_a_table_instruction_of_the_same_intent_where_there_is_one():
    texts = part_texts(parse_instruction("Use a knife by handle"))
    assert texts == {"blade": "Handover a knife by blade", "handle": "Use a knife by handle"}
    pen = part_texts(parse_instruction("Handover a pen by cap"))
    assert pen["tip"] is None and pen["cap"] == "Handover a pen by cap"


def _labels(hand_name: str, category: str, text: str, seed: int = 3):
    obj = make_object(category, seed)
    cloud = load_object(obj.sample_cloud(4096, seed=1).points)
    hand = load_hand(hand_name)
    _, anchors = load_model(None).sample(cloud.points, text, hand, 16, seed=0)
    found = model_labels(cloud, parse_instruction(text), hand, anchors)
    true = obj.point_labels[cKDTree(obj.points).query(cloud.points)[1]]
    return obj, cloud, found, true


@pytest.mark.parametrize("hand_name", ["allegro", "leap", "shadow"])
def test_a_bare_knife_cloud_is_labelled_as_its_parts(hand_name):
    """The shipped interaction model finds a knife's blade and handle on a bare cloud: most
    points get their true part, and the definition measured on them is the knife's."""
    obj, cloud, found, true = _labels(hand_name, "knife", "Use a knife by handle")
    assert found is not None
    assert found.obj.part_names == obj.part_names
    assert (found.obj.point_labels == true).mean() > 0.8
    assert [r.part for r in found.meaning.working] == ["blade"]
    assert found.seeds["blade"] > 0 and found.seeds["handle"] > 0


def test_near_its_seed_the_held_part_is_where_the_samples_point():
    obj, cloud, found, true = _labels("allegro", "knife", "Use a knife by handle")
    handle = found.obj.part_names.index("handle")
    sure = found.near_seed(0.01)
    held, kept = found.obj.point_labels == handle, sure.point_labels == handle
    assert kept.sum() < held.sum() and not (kept & ~held).any()  # a part of the handle label
    near = cKDTree(cloud.points[found.held_seed]).query(cloud.points[kept])[0]
    assert near.max() <= 0.01
    assert (true[kept] == handle).mean() >= (true[held] == handle).mean()  # surer of its points


def test_no_labels_where_a_measured_part_is_named_by_no_instruction():
    """A pen's Use keeps its tip clear, and no instruction asks for the tip: no labels (the
    plan goes on without the Use check) rather than a definition on a part never found."""
    *_, found, _ = _labels("allegro", "pen", "Use a pen by barrel")
    assert found is None


def test_more_samples_per_part_seed_more_of_it():
    obj = make_object("bowl", 3)
    cloud = load_object(obj.sample_cloud(4096, seed=1).points)
    hand, instruction = load_hand("allegro"), parse_instruction("Use a bowl by body")
    few = part_seeds(cloud, instruction, hand, None, samples=2)
    many = part_seeds(cloud, instruction, hand, None, samples=16)
    assert set(many) == {"body", "rim"}
    assert all(many[p].sum() > (few[p].sum() if p in few else 0) for p in many)


def test_the_held_part_is_kept_near_its_seed_and_the_rest_goes_to_its_neighbours():
    points = np.c_[np.linspace(0.0, 0.1, 11), np.zeros(11), np.zeros(11)]
    labels = np.array([1] * 2 + [0] * 9)  # the walk carried held (0) over most of the line
    seed = np.zeros(11, bool)
    seed[[9, 10]] = True  # the model pointed at the far end only
    trimmed = trim_held(points, labels, seed, held=0, reach=0.025)
    assert trimmed.tolist() == [1] * 7 + [0] * 4  # 7 cm and on: within 2.5 cm of 9 cm
    assert trim_held(points, np.zeros(11, int), seed, 0, 0.025).tolist() == [0] * 11


def test_label_samples_must_be_positive():
    with pytest.raises(PlanningError, match="label_samples"):
        LearnedSettings(label_samples=0)
    with pytest.raises(PlanningError, match="held_reach"):
        LearnedSettings(held_reach=float("nan"))
    with pytest.raises(PlanningError, match="switch_reach"):
        LearnedSettings(switch_reach=-0.01)


def test_other_parts_covered_counts_their_points_near_their_label():
    points = np.c_[np.linspace(0.0, 0.1, 11), np.zeros(11), np.zeros(11)]
    true = np.array([0] * 5 + [1] * 6)
    assert covered(points, true, true, held=0) == 1.0
    found = true.copy()
    found[5:8] = 0  # 3 of the other part's points labelled held; the nearest 1 is 1 cm off
    assert covered(points, found, true, held=0) == pytest.approx(3 / 6)
    assert covered(points, found, np.zeros(11, int), held=0) is None


def test_no_labels_outside_the_library():
    cloud = load_object(make_object("mug", 3).sample_cloud(2048).points)
    hand = load_hand("allegro")
    instruction = parse_instruction("Use a widget by handle")
    assert model_labels(cloud, instruction, hand, np.zeros((4, 4, 3))) is None


@pytest.mark.slow
def test_use_on_a_bare_cloud_is_checked_and_kept_out_on_the_models_labels():
    """On a bare knife cloud "Use a knife by handle" is checked on every solved candidate with
    the model's labels, and the samples solved with the keep-outs (`sample_keep_outs`) keep
    every solved hand clear of the blade as labelled; with `model_labels` off nothing is
    checked."""
    cloud = load_object(make_object("knife", 3).sample_cloud(4096, seed=1).points)

    def planned(labels: bool, keep_outs: bool):
        settings = PlannerSettings(
            schedule=ScheduleSettings(max_candidates=1),
            learned=LearnedSettings(samples=4, model_labels=labels, sample_keep_outs=keep_outs),
        )
        planner = FunctionalPlanner("allegro", settings)
        planner._validate = lambda program, obj, instruction, cand: None  # solves only
        return planner, planner.plan(cloud, "Use a knife by handle")

    planner, result = planned(True, True)
    assert set(result.understood["model_labels"]) == {"blade", "handle"}
    solved = [c for c in result.candidates if c.solve.ok]
    assert solved and all(c.proposal.shaped for c in result.candidates)
    for c in solved:
        assert c.intent is not None and c.intent.intent == "Use"
        assert [x.name for x in c.intent.criteria] == ["working_parts_clear"]
    _, plain = planned(False, False)
    assert "model_labels" not in plain.understood
    assert all(c.intent is None for c in plain.candidates)


def test_the_keep_out_comes_from_the_models_labels():
    """The shaped program's extra piece is the labelled blade grown by the clearance: it holds
    most of the true blade, and of the true handle not much more than the true blade's grown
    hull does (the handle's end beside the blade is within the clearance)."""
    obj, cloud, found, true = _labels("allegro", "knife", "Use a knife by handle")
    planner = FunctionalPlanner("allegro", PlannerSettings())
    program, own = planner._intent_program(cloud, found.meaning, found.obj)
    assert own == len(cloud.collision_pieces())
    assert len(set(program._piece_index.values())) == own + 1  # one keep-out: the blade
    blade = obj.part_names.index("blade")
    corners = found.obj.points[found.obj.point_labels == blade]
    hull = grown_hull(corners, 0.01)
    truth = grown_hull(cloud.points[true == blade], 0.01)
    handle = cloud.points[true != blade]
    assert inside_hull(hull, cloud.points[true == blade]).mean() > 0.9
    assert inside_hull(hull, handle).mean() < inside_hull(truth, handle).mean() + 0.15


def test_the_walk_puts_the_border_in_the_crease_not_halfway_between_the_seeds():
    """A pan seeded only at the far side of its body and along its handle (where samples'
    fingers go): the nearest seed splits it halfway between them, well inside the body; the
    random walk stops at the crease where the handle meets the body."""
    pan = make_object("pan", 0)
    points, labels = pan.points, pan.point_labels
    body, handle = pan.part_names.index("body"), pan.part_names.index("handle")
    x = points[:, 0]
    span = np.ptp(x)
    seeds = {
        body: (labels == body) & (x < x.min() + 0.1 * span),
        handle: (labels == handle) & (x > x.max() - 0.4 * span),
    }
    walked = spread_labels(points, pan.normals, seeds)
    nearest = nearest_seed(points, seeds)
    assert (walked == labels).mean() > 0.95
    assert (nearest == labels).mean() < (walked == labels).mean() - 0.05


@pytest.mark.parametrize("hand_name", ["allegro", "leap", "shadow"])
def test_no_labels_where_the_model_does_not_tell_two_parts_apart(hand_name):
    """A screwdriver's shaft is a part word no training category has: asked for it, the model
    points at the handle, the two seeds overlap, and no labels are made (a keep-out around a
    "shaft" on the handle would leave nothing to hold)."""
    *_, found, _ = _labels(hand_name, "screwdriver", "Use a screwdriver by handle")
    assert found is None
