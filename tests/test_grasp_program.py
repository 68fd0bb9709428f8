"""The Drake grasp program: feasible answers, clear failures, cached diagrams."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
import torch
import trimesh

from models.errors import PlanningError
from models.hands import load_hand
from models.objects import make_object
from planner import functional
from planner.functional import FunctionalPlanner, PlannerSettings
from planner.grasp_program import PREGRASP_SCALES, GraspTargets, ProgramSettings, grasp_program
from planner.settings import ProposalSettings

# the grasp program as it solved before SNOPT's wrist variables were scaled
UNSCALED = ProgramSettings(wrist_position_scale=1.0, wrist_quaternion_scale=1.0)


def _check_feasible(hand, program, result) -> None:
    """Joints within limits and the distance re-checked; an accepted answer does not penetrate
    beyond the bound, and a rejected one says why."""
    settings = program.settings
    if result.ok:
        assert result.min_distance >= settings.min_distance - settings.penetration_tolerance
    else:
        assert result.message
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
    assert result.ok, result.message
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


def test_grasp_pregrasp_and_squeeze_keep_the_couplings(hand_name):
    """What one tendon drives (ShadowHand's J1/J2) stays in its plan ratio in every phase the
    validator executes, even from an initial guess that breaks it."""
    hand = load_hand(hand_name)
    obj = make_object("mug", 3)
    program = grasp_program(hand, obj.collision_pieces())
    p = FunctionalPlanner(hand).propose(obj, "handle")[0]
    guess = np.random.default_rng(1).uniform(hand.lower, hand.upper)
    r = program.solve(GraspTargets(p.wrist, guess, p.anchors, p.normals, palm_target=p.palm_target))
    nearest = [int(np.argmin(np.linalg.norm(obj.points - a, axis=1))) for a in p.anchors]
    pre = program.pregrasp(r.wrist, r.q, obj.normals[nearest])
    for q in (r.q, pre, program.squeeze(r.q, pre), program.squeeze(r.q, pre, 2.0)):
        assert hand.coupling_violation(q) < 1e-9


def test_hand_hand_pairs_are_a_constraint_of_their_own(hand_name):
    """The main context sees only hand-object pairs, the second only hand-hand pairs, and the
    answers keep the fingers out of each other as well as out of the object."""
    hand = load_hand(hand_name)
    obj = make_object("mug", 3)
    program = grasp_program(hand, obj.collision_pieces())
    hand_geoms = program._hand_geoms
    for context, want_hand_hand in ((program.plant_context, False), (program._self_context, True)):
        query = program.plant.get_geometry_query_input_port().Eval(context)
        pairs = query.ComputeSignedDistancePairwiseClosestPoints(1.0)
        kinds = {(p.id_A in hand_geoms) and (p.id_B in hand_geoms) for p in pairs}
        assert kinds == {want_hand_hand}
    bound = program.settings.min_distance - program.settings.penetration_tolerance
    solved = [
        program.solve(GraspTargets(p.wrist, p.q, p.anchors, p.normals, palm_target=p.palm_target))
        for p in FunctionalPlanner(hand).propose(obj, "handle")[:3]
    ]
    assert any(r.ok for r in solved)
    for r in solved:
        if r.ok:
            assert program.hand_hand_distance(r.wrist, r.q) >= bound
    shared = grasp_program(hand, obj.collision_pieces(), ProgramSettings(separate_hand_hand=False))
    r = solved[0]
    assert shared.hand_hand_distance(r.wrist, r.q) == pytest.approx(
        program.hand_hand_distance(r.wrist, r.q), abs=1e-9
    )


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


def _squeeze_forces(program, wrist, q, squeeze) -> np.ndarray:
    """The forces (per unit kp) the squeeze's joint offsets make the anchor fingertips push
    with: least squares of J^T f = squeeze - grasp over each finger's joints."""
    from pydrake.multibody.tree import JacobianWrtVariable

    program.set_configuration(wrist, q)
    plant, world = program.plant, program.plant.world_frame()
    joints = program.handle.joint_velocity_index
    forces = []
    for tip, frame in zip(program.tips, program.tip_frames, strict=True):
        jac = plant.CalcJacobianTranslationalVelocity(
            program.plant_context, JacobianWrtVariable.kV, frame, tip.point, world, world
        )[:, joints]
        cols = np.flatnonzero(np.abs(jac).sum(axis=0) > 1e-9)
        forces.append(np.linalg.lstsq(jac[:, cols].T, (squeeze - q)[cols], rcond=None)[0])
    return np.array(forces)


def test_balanced_pregrasp_backs_off_and_balances_the_squeeze(hand_name):
    hand = load_hand(hand_name)
    obj = make_object("bottle", 1)
    proposal = FunctionalPlanner(hand).propose(obj, "body")[0]
    targets = GraspTargets(proposal.wrist, proposal.q, proposal.anchors, proposal.normals)
    nets = {}
    for rule in ("normal", "balanced"):
        program = grasp_program(hand, obj.collision_pieces(), ProgramSettings(pregrasp_rule=rule))
        solved = program.solve(targets)
        assert solved.ok, solved.message
        centres = program.tip_centres(solved.wrist, solved.q)
        nearest = np.argmin(np.linalg.norm(obj.points[None] - centres[:, None], axis=2), axis=1)
        normals = obj.normals[nearest]
        pre = program.pregrasp(solved.wrist, solved.q, normals)
        squeeze = program.squeeze(solved.q, pre)
        pre_centres = program.tip_centres(solved.wrist, pre)
        backoff = np.einsum("ij,ij->i", pre_centres - centres, normals)
        # about the hand's clearance on average (the promise; hand.json, 5 mm or 1 cm), and no
        # fingertip pushed into the surface: under the balanced rule one may move a fraction of
        # a millimetre inward
        clearance = program.pregrasp_clearance
        assert clearance == hand.meta.pregrasp_clearance
        assert 0.5 * clearance < backoff.mean() < 1.5 * clearance, backoff
        assert np.all(backoff > -0.0005), backoff
        # the squeeze target lies about depth x clearance past the contacts (the hand's
        # squeeze_depth; 1 cm for every built-in hand), along the normals into the object
        reach = np.einsum("ij,ij->i", centres - program.tip_centres(solved.wrist, squeeze), normals)
        past = program.squeeze_depth * clearance
        assert 0.5 * past < reach.mean() < 1.5 * past, reach
        forces = _squeeze_forces(program, solved.wrist, solved.q, squeeze)
        radii = np.array([t.radius for t in program.tips])
        points = centres - radii[:, None] * normals
        net = np.concatenate(
            [forces.sum(axis=0), np.cross(points - points.mean(axis=0), forces).sum(axis=0) / 0.03]
        )
        nets[rule] = np.linalg.norm(net) / np.linalg.norm(forces, axis=1).sum()
    assert nets["balanced"] < nets["normal"], nets


def test_scaled_wrist_variables_let_snopt_converge(hand_name):
    """Unscaled (1 m, 1), SNOPT runs the bottle-body solve to its iteration cap; with the
    wrist's position and quaternion scaled (the defaults) it ends at an optimum, and the answer
    moves: the settings reach SNOPT (docs/planner_log.md, "Scaled wrist variables")."""
    hand = load_hand(hand_name)
    obj = make_object("bottle", 1)
    proposal = FunctionalPlanner(hand).propose(obj, "body")[0]
    targets = GraspTargets(proposal.wrist, proposal.q, proposal.anchors, proposal.normals)
    before = grasp_program(hand, obj.collision_pieces(), UNSCALED).solve(targets)
    scaled = grasp_program(hand, obj.collision_pieces()).solve(targets)
    assert before.solver_status == "kIterationLimit"
    assert scaled.solver_status == "kSolutionFound"
    assert scaled.ok and not np.allclose(scaled.wrist, before.wrist, atol=1e-3)


def test_pregrasp_offsets_shrink_until_clear_of_the_object(hand_name):
    hand = load_hand(hand_name)
    obj = make_object("bottle", 1)
    proposal = FunctionalPlanner(hand).propose(obj, "body")[0]
    program = grasp_program(hand, obj.collision_pieces())
    solved = program.solve(
        GraspTargets(proposal.wrist, proposal.q, proposal.anchors, proposal.normals)
    )
    assert solved.ok, solved.message
    wrist, q = solved.wrist, solved.q
    anchor_joints = np.ones(hand.dof, dtype=bool)
    # an offset that closes every joint a little further drives the fingers a few mm into the bottle
    inward = 0.015 * hand.closing_direction * (hand.upper - hand.lower)
    assert program.hand_object_distance(wrist, np.clip(q + inward, hand.lower, hand.upper)) < -0.002
    pre = program.clear_of_object(wrist, q, inward, anchor_joints)
    bound = min(-program.settings.pregrasp_penetration, program.hand_object_distance(wrist, q))
    assert program.hand_object_distance(wrist, pre) >= bound
    scales = [a for a, _ in PREGRASP_SCALES]
    assert any(np.allclose(pre, np.clip(q + a * inward, hand.lower, hand.upper)) for a in scales)
    # the scale it settled on, for the squeeze
    same, scale = program._clear_of_object(wrist, q, inward, anchor_joints)
    assert np.array_equal(same, pre) and scale < 1
    assert np.allclose(pre, np.clip(q + scale * inward, hand.lower, hand.upper))
    assert not np.allclose(pre, np.clip(q + inward, hand.lower, hand.upper))
    # an offset that opens the hand leaves the object alone and is kept as it is
    outward = -0.5 * inward
    kept = program.clear_of_object(wrist, q, outward, anchor_joints)
    assert np.allclose(kept, np.clip(q + outward, hand.lower, hand.upper))


def test_the_closing_path_from_the_pregrasp_stays_clear_of_the_object():
    """The validator closes along the straight joint path from the pregrasp to the grasp: a
    finger clear of the part at both ends can sweep through it between them (ShadowHand on a
    knife handle, 10 mm deep midway when only the pregrasp is checked)."""
    hand = load_hand("shadow")
    obj = make_object("knife", 13)
    proposal = FunctionalPlanner(hand).propose(obj, "handle")[1]
    # the grasp the case was found with, solved unscaled: scaled, none of 80 knife-handle
    # solves (seeds 10-29, first 4 proposals) nor of about 150 on pan, hammer, mug and knife
    # handles had a closing path more than 3.4 mm inside
    solved = grasp_program(hand, obj.collision_pieces(), UNSCALED).solve(
        GraspTargets(
            proposal.wrist,
            proposal.q,
            proposal.anchors,
            proposal.normals,
            palm_target=proposal.palm_target,
        )
    )
    assert solved.ok, solved.message
    wrist, q = solved.wrist, solved.q
    tips = hand.fingertip_positions(
        torch.tensor(wrist[None]), torch.tensor(q[None]), list(hand.meta.anchor_fingers)
    )[0].numpy()
    normals = obj.normals[np.argmin(np.linalg.norm(obj.points[None] - tips[:, None], axis=2), 1)]
    deepest, closing, squeeze = {}, {}, {}
    for checks in (0, 3):
        program = grasp_program(
            hand, obj.collision_pieces(), ProgramSettings(pregrasp_path_checks=checks)
        )
        pre, scale = closing[checks] = program.closing(wrist, q, normals)
        assert np.array_equal(pre, program.pregrasp(wrist, q, normals))
        bound = min(-program.settings.pregrasp_penetration, program.hand_object_distance(wrist, q))
        assert program.hand_object_distance(wrist, pre) >= bound
        deepest[checks] = min(
            program.hand_object_distance(wrist, pre + a * (q - pre)) for a in np.linspace(0, 1, 9)
        )
        squeeze[checks] = program.squeeze(q, pre, scale=scale)
    assert deepest[0] < -0.005  # the pregrasp alone was clear, its path 5+ mm inside
    assert deepest[3] >= bound - 1e-4, deepest
    # whatever shrank to clear the path (here the little finger's opening), the anchor
    # fingers' squeeze did not
    assert closing[3][1] <= closing[0][1]
    anchor = closing[3][0] != q
    assert anchor.any()
    assert np.allclose(squeeze[3][anchor], squeeze[0][anchor], atol=1e-6)


def test_a_shrunk_pregrasp_is_squeezed_as_deep_as_unshrunk():
    hand = load_hand("allegro")
    obj = make_object("bottle", 1)
    program = grasp_program(hand, obj.collision_pieces())
    q = (hand.lower + hand.upper) / 2
    pre = q - 0.01 * hand.closing_direction
    depth = program.squeeze_depth
    assert np.allclose(program.squeeze(q, pre), q + depth * (q - pre))  # BODex's rule
    assert np.allclose(program.squeeze(q, pre, scale=0.5), q + 2 * depth * (q - pre))
    assert np.allclose(program.squeeze(q, pre, 3.0, 0.25), q + 12 * (q - pre))
    before = grasp_program(hand, obj.collision_pieces(), ProgramSettings(full_squeeze=False))
    assert np.allclose(before.squeeze(q, pre, scale=0.5), q + depth * (q - pre))


def test_unknown_pregrasp_rule_is_a_clear_error():
    with pytest.raises(PlanningError, match="pregrasp_rule"):
        ProgramSettings(pregrasp_rule="tight")


def test_settings_override_the_hands_closing(hand_name):
    """ProgramSettings' squeeze depth and pregrasp clearance, where given, replace hand.json's."""
    hand = load_hand(hand_name)
    obj = make_object("bottle", 1)
    own = grasp_program(hand, obj.collision_pieces())
    assert (own.squeeze_depth, own.pregrasp_clearance) == (
        hand.meta.squeeze_depth,
        hand.meta.pregrasp_clearance,
    )
    settings = ProgramSettings(squeeze_depth=3.0, pregrasp_clearance=0.002)
    given = grasp_program(hand, obj.collision_pieces(), settings)
    assert (given.squeeze_depth, given.pregrasp_clearance) == (3.0, 0.002)
    assert own.retry_squeeze_depths == hand.meta.retry_squeeze_depths
    retry = ProgramSettings(retry_squeeze_depths=(5.0, 0.5, 5.0))
    assert grasp_program(hand, obj.collision_pieces(), retry).retry_squeeze_depths == (5.0, 0.5)
    none = grasp_program(hand, obj.collision_pieces(), ProgramSettings(retry_squeeze_depths=()))
    assert none.retry_squeeze_depths == ()
    # a squeeze set to one of the hand's retry depths is not retried at that depth again
    for depth in hand.meta.retry_squeeze_depths:
        same = grasp_program(hand, obj.collision_pieces(), ProgramSettings(squeeze_depth=depth))
        assert depth not in same.retry_squeeze_depths
    for bad in (0.5, (0.0,), (float("nan"),), (True,), ("1",)):
        with pytest.raises(PlanningError, match="retry_squeeze_depths must be a tuple"):
            ProgramSettings(retry_squeeze_depths=bad)


def test_a_row_of_nan_anchors_leaves_that_finger_free(hand_name):
    """A pinch's free finger has no anchor: no position cost, and no part in the error."""
    hand = load_hand(hand_name)
    obj = make_object("lotion_pump", 13)
    program = grasp_program(hand, obj.collision_pieces())
    planner = FunctionalPlanner(
        hand, PlannerSettings(proposals=ProposalSettings(max_proposals=0, pinch_proposals=1))
    )
    (pinch,) = planner.propose(obj, "pump")
    result = program.solve(
        GraspTargets(pinch.wrist, pinch.q, pinch.anchors, pinch.normals, pinch.palm_target)
    )
    _check_feasible(hand, program, result)
    assert np.isfinite(result.anchor_error)
    # the error counts the anchored fingers only, however far the free one is from anything
    centres = program.tip_centres(result.wrist, result.q)
    radii = np.array([t.radius for t in program.tips])
    direction = np.array([0.0, 0.0, 1.0])
    exact = centres - radii[:, None] * direction  # each anchor on its fingertip's surface
    exact[3:] = np.nan
    assert program.anchor_error(result.wrist, result.q, exact) == pytest.approx(0.0, abs=1e-9)
    far = exact.copy()
    far[3:] = centres[3:] + 0.5
    assert program.anchor_error(result.wrist, result.q, far) > 0.4


@dataclass
class _Verdict:
    """A ValidationResult's fields that finish_grasp reads and sets."""

    success: bool
    reason: str = ""

    def to_dict(self) -> dict:
        return {"success": self.success, "reason": self.reason}


def test_a_slipping_grasp_is_validated_again_with_other_closings(hand_name, monkeypatch):
    """finish_grasp validates the retries' closings only after a slip, in turn (the other
    squeeze depths, then a pregrasp by the retry rule), and records the closing that held;
    without retries one validation decides."""
    hand = load_hand(hand_name)
    obj = make_object("bottle", 1)
    (proposal,) = FunctionalPlanner(
        hand, PlannerSettings(proposals=ProposalSettings(max_proposals=1, pinch_proposals=0))
    ).propose(obj, "body")
    targets = GraspTargets(proposal.wrist, proposal.q, proposal.anchors, proposal.normals)
    tried: list = []

    def fake_validate(grasp, *args):  # holds only with the third closing
        tried.append(grasp)
        return _Verdict(len(tried) == 3)

    monkeypatch.setattr(functional, "validate", fake_validate)
    settings = ProgramSettings(retry_squeeze_depths=(3.0, 0.5, 4.0))
    program = grasp_program(hand, obj.collision_pieces(), settings)
    assert program.retry_closings() == [
        (3.0, "balanced"),
        (0.5, "balanced"),
        (4.0, "balanced"),
        (program.squeeze_depth, "normal"),
    ]
    solved = program.solve(targets)
    done = functional.finish_grasp(program, obj, solved, "Hold a bottle by body", "paper")
    pre = done.grasp.pregrasp
    squeezes = [program.squeeze(solved.q, pre, d) for d in (program.squeeze_depth, 3.0, 0.5)]
    assert not np.allclose(squeezes[0], squeezes[1]) and not np.allclose(squeezes[0], squeezes[2])
    assert len(tried) == 3  # the one that held ends the retries: 4.0 is never validated
    assert all(np.array_equal(g.squeeze, b) for g, b in zip(tried, squeezes, strict=True))
    assert all(np.array_equal(g.pregrasp, pre) for g in tried)
    assert done.success and np.array_equal(done.grasp.squeeze, squeezes[2])
    assert done.grasp.metrics["squeeze_depth"] == 0.5 and "retry" in done.times
    assert done.grasp.metrics["pregrasp_rule"] == "balanced"

    tried.clear()
    monkeypatch.setattr(
        functional, "validate", lambda g, *a: _Verdict(tried.append(g) or len(tried) == 5)
    )
    done = functional.finish_grasp(program, obj, solved, "Hold a bottle by body", "paper")
    assert len(tried) == 5 and done.success  # the last: the normal rule's own pregrasp
    wrist_t, q_t = torch.tensor(solved.wrist[None]), torch.tensor(solved.q[None])
    tips = hand.fingertip_positions(wrist_t, q_t, list(hand.meta.anchor_fingers))[0].numpy()
    nearest = np.argmin(np.linalg.norm(obj.points[None] - tips[:, None], axis=2), axis=1)
    normal, _ = program.closing(solved.wrist, solved.q, obj.normals[nearest], rule="normal")
    assert np.array_equal(done.grasp.pregrasp, normal) and not np.allclose(normal, pre)
    assert np.array_equal(done.grasp.squeeze, tried[-1].squeeze)
    assert done.grasp.metrics["pregrasp_rule"] == "normal"
    assert done.grasp.metrics["squeeze_depth"] == program.squeeze_depth

    tried.clear()
    monkeypatch.setattr(functional, "validate", lambda g, *a: tried.append(g) or _Verdict(False))
    done = functional.finish_grasp(program, obj, solved, "Hold a bottle by body", "paper")
    assert len(tried) == 5 and not done.success  # all slip: the first closing is kept
    assert np.array_equal(done.grasp.squeeze, squeezes[0])
    assert np.array_equal(done.grasp.pregrasp, pre)
    assert done.grasp.metrics["squeeze_depth"] == program.squeeze_depth

    tried.clear()
    none = ProgramSettings(retry_squeeze_depths=(), retry_pregrasp_rule="none")
    once = grasp_program(hand, obj.collision_pieces(), none)
    assert once.retry_closings() == []
    done = functional.finish_grasp(once, obj, once.solve(targets), "Hold a bottle", "paper")
    assert len(tried) == 1 and "retry" not in done.times
    with pytest.raises(PlanningError, match="unknown retry_pregrasp_rule"):
        ProgramSettings(retry_pregrasp_rule="sideways")


def test_a_grasp_on_a_cloud_must_also_hold_on_its_piece_variants(hand_name, monkeypatch):
    """finish_grasp's cloud checks: a grasp that held on a bare cloud's pieces is validated on
    `cloud_checks` piece variants and counts as slipped unless it holds on all; a grasp that
    slipped is not checked, and a mesh's exact pieces get no checks."""
    from models.objects import load_object

    hand = load_hand(hand_name)
    bottle = make_object("bottle", 1)
    cloud = load_object(bottle.sample_cloud(4096, seed=1).points)
    (proposal,) = FunctionalPlanner(
        hand, PlannerSettings(proposals=ProposalSettings(max_proposals=1, pinch_proposals=0))
    ).propose(bottle, "body")
    targets = GraspTargets(proposal.wrist, proposal.q, proposal.anchors, proposal.normals)
    none = ProgramSettings(retry_squeeze_depths=(), retry_pregrasp_rule="none")
    program = grasp_program(hand, cloud.collision_pieces(), none)
    solved = program.solve(targets)
    variants = cloud.piece_variants(2)
    seen: list = []

    def holds_except(*failing):
        def fake(grasp, pieces, *args):
            seen.append(pieces)
            return _Verdict(not any(pieces is variants[i] for i in failing))

        return fake

    def finish(obj=cloud, checks=2):
        return functional.finish_grasp(program, obj, solved, "Hold a bottle", "paper", checks)

    monkeypatch.setattr(functional, "validate", holds_except())
    done = finish()
    assert done.success and done.validation["cloud_checks"] == {"held": 2, "of": 2}
    assert seen == [cloud.collision_pieces(), *variants] and "cloud_checks" in done.times

    seen.clear()
    monkeypatch.setattr(functional, "validate", holds_except(1))
    done = finish()
    assert not done.success and not done.grasp.metrics["success"]
    assert done.validation["cloud_checks"] == {"held": 1, "of": 2}
    assert done.validation["reason"] == "slipped on other pieces of the cloud"

    seen.clear()
    monkeypatch.setattr(functional, "validate", lambda g, p, *a: seen.append(p) or _Verdict(False))
    done = finish()
    assert not done.success and len(seen) == 1 and "cloud_checks" not in done.validation

    for obj, checks in ((cloud, 0), (bottle, 2)):
        seen.clear()
        monkeypatch.setattr(functional, "validate", holds_except())
        done = finish(obj, checks)
        assert done.success and len(seen) == 1 and "cloud_checks" not in done.validation
