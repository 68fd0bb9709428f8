"""DexGraspBench's second pregrasp check: more than 1 cm of hand-hand (self) penetration at the
pregrasp fails the grasp before the force test, with reason "pregrasp_self_penetration"."""

from __future__ import annotations

import copy
import dataclasses
from pathlib import Path

import mujoco
import numpy as np
import pytest

from models.grasp import Grasp
from planner.validation import as_collision_object, get_protocol, mjcf_hand, project_hand, validate
from planner.validation.batch import validate_many
from planner.validation.hands import mjcf_joint_names
from planner.validation.layout import read_rows, row_case
from planner.validation.scene import get_scene
from planner.validation.validator import IDENTITY_POSE, _self_penetration, _set_configuration

hands_module = pytest.importorskip("models.hands")
BENCH = Path(__file__).resolve().parents[1].parent / "shared" / "reference" / "dexgraspbench"
SHORT = get_protocol("dexgraspbench", hold_time=0.4)
CUBE = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float) * 0.02
FAR = (0.3, 0.3, 0.3)  # wrist offset that keeps the hand clear of the cube
CUBE_AWAY = np.array([1.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0])  # object pose clear of the hand

# Joint values (the rest at the hand's open pose) that push two neighbouring fingers into each
# other, found by a grid search over the index and middle fingers' abduction joints (and, for
# Allegro, whose straight fingers stay clear, their proximal flexion) at 5 x 5 (x 4 x 4) values
# within the joint limits, measuring the deepest hand-hand contact after mj_forward. Penetration
# measured with MuJoCo 4.0.0: shadow 1.80 cm (rh_ffmiddle / rh_mfmiddle), allegro 2.80 cm
# (ff_medial / mf_medial), leap 2.48 cm (if_md / mf_md).
COLLIDING = {
    "shadow": {"rh_FFJ4": 0.349},
    "allegro": {"ffj0": -0.47, "mfj0": 0.47, "ffj1": 0.8, "mfj1": 0.8},
    "leap": {"if_rot": 0.524, "mf_rot": -0.524},
}


def _open(name: str) -> np.ndarray:
    return np.array(hands_module.load_hand(name).open_pose, dtype=float)  # a copy


def _grasp(name: str, pregrasp: np.ndarray, grasp: np.ndarray | None = None) -> Grasp:
    hand = hands_module.load_hand(name)
    g = pregrasp if grasp is None else grasp
    return Grasp.with_bodex_squeeze(
        name, FAR, [1, 0, 0, 0], g, pregrasp, joint_names=hand.joint_names
    )


def _colliding(name: str) -> np.ndarray:
    hand = hands_module.load_hand(name)
    q = _open(name)
    for joint, value in COLLIDING[name].items():
        q[hand.joint_names.index(joint)] = value
    return q


@pytest.mark.parametrize("name", sorted(COLLIDING))
def test_fingers_driven_into_each_other_fail_before_the_force_test(name):
    result = validate(
        _grasp(name, _colliding(name), _open(name)), [CUBE], project_hand(name), SHORT
    )
    assert not result.success and result.reason == "pregrasp_self_penetration"
    assert result.pregrasp_self_penetration > SHORT.max_pregrasp_self_penetration
    assert result.pregrasp_penetration == 0.0 and result.directions == []  # no force test ran
    assert result.to_dict()["pregrasp_self_penetration"] == result.pregrasp_self_penetration


@pytest.mark.parametrize("name", sorted(COLLIDING))
def test_the_limit_is_a_protocol_setting(name):
    loose = SHORT.replace(max_pregrasp_self_penetration=0.05)
    result = validate(
        _grasp(name, _colliding(name), _open(name)), [CUBE], project_hand(name), loose
    )
    assert result.reason == "slipped" and result.directions  # tested, and the far cube falls
    assert 0.01 < result.pregrasp_self_penetration < 0.05


@pytest.mark.parametrize("name", sorted(COLLIDING))
def test_an_open_pregrasp_passes_the_check(name):
    result = validate(_grasp(name, _open(name)), [CUBE], project_hand(name), SHORT)
    assert result.reason == "slipped" and result.directions  # went on to the force test
    assert result.pregrasp_self_penetration < SHORT.max_pregrasp_self_penetration


@pytest.mark.parametrize("name", ["shadow", "allegro"])
def test_only_contacts_mujoco_generates_count(name):
    """At the open pose, parent-child links (ShadowHand) and the hand's excluded pairs
    (Allegro's palm and finger bases) overlap by more than 1 cm; MuJoCo filters those pairs,
    and so does the check."""
    scene = get_scene(project_hand(name), as_collision_object([CUBE], name="cube"), SHORT)
    unfiltered = copy.deepcopy(scene.model)
    unfiltered.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_FILTERPARENT)
    unfiltered.exclude_signature[:] = -1  # matches no body pair: no exclusions
    depths = []
    for model in (scene.model, unfiltered):
        data = mujoco.MjData(model)
        probe = dataclasses.replace(scene, model=model)
        _set_configuration(probe, data, IDENTITY_POSE, _open(name), CUBE_AWAY)
        mujoco.mj_forward(model, data)
        depths.append(_self_penetration(probe, data))
    assert depths[0] < 0.001 and depths[1] > 0.01


def test_reference_pregrasps_are_within_the_limit():
    """None of the 200 DexGraspBench reference grasps comes near the limit (their verdicts
    stay): the deepest self-contact at their pregrasps is under 1 mm."""
    hand_xml = BENCH / "hand" / "shadow_right_hand.xml"
    if not (BENCH / "grasps.npz").is_file() or not hand_xml.is_file():
        pytest.skip(f"DexGraspBench reference data not found under {BENCH}")
    rows = read_rows(BENCH / "grasps.npz")
    hand = mjcf_hand(hand_xml)
    xml = mjcf_joint_names(str(hand_xml.resolve()))
    cases = [row_case(rows, i, hand, xml, BENCH / "objects") for i in range(len(rows["object"]))]
    # A hand-object limit below zero stops every grasp right after the two pregrasp measurements.
    measure_only = get_protocol("dexgraspbench", max_pregrasp_penetration=-1.0)
    results = validate_many(
        [g for g, _ in cases],
        [o for _, o in cases],
        hand,
        measure_only,
        object_poses=list(rows["obj_pose"]),
    )
    depths = np.array([r.pregrasp_self_penetration for r in results])
    assert len(depths) == 200 and depths.max() < 0.001
