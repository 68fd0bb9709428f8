"""Plans do not depend on the last bits of their inputs (models.reproducible)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from models.hands import load_hand
from models.objects import make_object
from models.objects.model import Samples
from models.reproducible import DECIMALS, rounded, rounded_within
from planner.functional import FunctionalPlanner
from planner.grasp_program import GraspTargets, grasp_program


def _jittered(values: np.ndarray, seed: int) -> np.ndarray:
    """`values` moved by a few units in their last place, as another machine's BLAS might."""
    rng = np.random.default_rng(seed)
    return values * (1 + rng.integers(-4, 5, size=values.shape) * np.finfo(float).eps)


def test_rounded_is_a_nanometre_grid():
    x = np.array([0.1234567891234, -2.0000000004])
    assert np.all(np.abs(rounded(x) - x) <= 0.5 * 10.0**-DECIMALS)
    assert rounded(x)[1] == -2.0  # 0.4 nm off the grid lands on it
    assert rounded(0.1 + 2e-17) == rounded(0.1) and isinstance(rounded(0.1), float)
    assert np.array_equal(rounded(_jittered(x, 0)), rounded(x))
    # joint values stay within limits that have more decimals than the grid
    limit = np.pi / 2
    assert rounded_within([limit], -limit, limit)[0] == limit and rounded([limit])[0] > limit


def test_proposals_ignore_last_bit_differences_in_the_object(hand_name):
    obj = make_object("mug", 3)
    planner = FunctionalPlanner(hand_name)
    moved = dataclasses.replace(obj, _derived={})
    moved._derived["surface"] = Samples(
        _jittered(obj.points, 1), obj.normals, obj.point_labels, np.arange(len(obj.points))
    )
    assert not np.array_equal(moved.points, obj.points)
    for a, b in zip(planner.propose(obj, "handle"), planner.propose(moved, "handle"), strict=True):
        # equal_nan: a pinch's free finger has a NaN anchor row
        assert np.array_equal(a.wrist, b.wrist)
        assert np.array_equal(a.anchors, b.anchors, equal_nan=True)
        assert a.anchor_quality == b.anchor_quality


def test_solve_ignores_last_bit_differences_in_its_targets(hand_name):
    obj = make_object("bottle", 6)
    planner = FunctionalPlanner(hand_name)
    program = grasp_program(planner.hand, obj.collision_pieces(), planner.settings.program)
    p = planner.propose(obj, "body")[0]
    exact = GraspTargets(p.wrist, p.q, p.anchors, p.normals, palm_target=p.palm_target)
    jittered = GraspTargets(
        _jittered(p.wrist, 2),
        p.q,
        _jittered(p.anchors, 3),
        _jittered(p.normals, 4),
        palm_target=p.palm_target,
    )
    a, b = program.solve(exact), program.solve(jittered)
    assert np.array_equal(a.wrist, b.wrist) and np.array_equal(a.q, b.q)


@pytest.fixture
def two_threads():
    """Torch at two threads for the test (a machine's default is a thread per core)."""
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    yield
    torch.set_num_threads(before)


def test_a_text_s_embedding_is_its_own_whatever_was_encoded_with_it(two_threads):
    from learned import text

    text.clear_cache()
    alone = text.encode(["Use a mug by handle"])[0]
    text.clear_cache()
    longer = "Would you kindly hoist this mug? Grasp it at the handle, please, thank you."
    batched = text.encode([longer, "Use a mug by handle"])[1]
    text.clear_cache()
    assert np.array_equal(alone, batched)  # batched with padding it moved by 1e-7
    text.clear_cache()
    same_length = text.encode(["Use a cup by body", "Use a mug by handle"])[1]
    text.clear_cache()
    assert np.array_equal(alone, same_length)  # in one unpadded batch: the same bits
    assert torch.get_num_threads() == 2  # the process's own count is given back


def test_the_learned_stages_give_the_same_bits_on_one_thread_and_on_two(hand_name, two_threads):
    from learned import text
    from planner.learned_proposer import dro_targets, learned_proposals

    hand = load_hand(hand_name)
    obj = dataclasses.replace(make_object("mug", 3), face_labels=None, part_names=(), _derived={})
    sentence = "Use a mug by handle"
    runs = []
    for threads in (1, 2):
        torch.set_num_threads(threads)
        text.clear_cache()  # each run encodes the sentence on its own thread count
        drawn = learned_proposals(obj, sentence, hand, 2, seed=0)
        wrist, anchors = drawn.wrists[0], drawn.anchors[0]
        targets = dro_targets(obj, sentence, hand, wrist, anchors, (0, 0)).targets
        runs.append((drawn.wrists, drawn.anchors, targets))
    for a, b in zip(*runs, strict=True):
        assert np.array_equal(a, b)
