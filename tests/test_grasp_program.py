"""The Drake grasp program: feasible answers, clear failures, cached diagrams."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from models.hands import load_hand
from models.objects import make_object
from planner.functional import FunctionalPlanner
from planner.grasp_program import GraspTargets, ProgramSettings, grasp_program


def _check_feasible(hand, program, result) -> None:
    settings = program.settings
    assert result.min_distance >= settings.min_distance - settings.penetration_tolerance
    assert np.all(result.q >= hand.lower - 1e-9) and np.all(result.q <= hand.upper + 1e-9)
    # checked independently of the solver's own report
    assert program.hand_object_distance(result.wrist, result.q) == pytest.approx(
        result.min_distance, abs=1e-6
    )


def test_box_solve_has_no_penetration_and_respects_limits(hand_name):
    hand = load_hand(hand_name)
    box = trimesh.creation.box(extents=[0.05, 0.05, 0.08])
    program = grasp_program(hand, [box.vertices])
    planner = FunctionalPlanner(hand)
    obj = make_object("bottle", 1)  # any labelled object gives a proposal; re-aim it at the box
    proposal = planner.propose(obj, "body")[0]
    result = program.solve(GraspTargets(proposal.wrist, proposal.q))
    _check_feasible(hand, program, result)


def test_mug_handle_solve_reaches_anchors_without_penetration(hand_name):
    hand = load_hand(hand_name)
    obj = make_object("mug", 3)
    program = grasp_program(hand, obj.collision_pieces())
    proposals = FunctionalPlanner(hand).propose(obj, "handle")
    results = [
        program.solve(GraspTargets(p.wrist, p.q, p.anchors, p.normals, palm_target=p.palm_target))
        for p in proposals[:3]
    ]
    for r in results:
        _check_feasible(hand, program, r)
    assert any(r.ok for r in results), [r.message for r in results]


def test_unreachable_anchors_fail_clearly():
    hand = load_hand("allegro")
    obj = make_object("mug", 3)
    program = grasp_program(hand, obj.collision_pieces())
    proposal = FunctionalPlanner(hand).propose(obj, "handle")[0]
    far = proposal.anchors + np.array([[0, 0, 0], [0.5, 0, 0], [0, 0.5, 0], [0, 0, 0.5]])
    result = program.solve(GraspTargets(proposal.wrist, proposal.q, far, proposal.normals))
    assert not result.ok
    assert "anchor error" in result.message


def test_repeated_solves_reuse_the_cached_program():
    hand = load_hand("leap")
    obj = make_object("knife", 2)
    first = grasp_program(hand, obj.collision_pieces())
    again = grasp_program(hand, make_object("knife", 2).collision_pieces())
    assert first is again
    assert (
        grasp_program(hand, obj.collision_pieces(), ProgramSettings(min_distance=0.002))
        is not first
    )


def test_squeeze_follows_bodex_rule():
    hand = load_hand("shadow")
    program = grasp_program(hand, [trimesh.creation.box(extents=[0.04] * 3).vertices])
    q = (hand.lower + hand.upper) / 2
    pre = q - 0.1
    np.testing.assert_allclose(
        program.squeeze(q, pre), np.clip(2 * q - pre, hand.lower, hand.upper)
    )
