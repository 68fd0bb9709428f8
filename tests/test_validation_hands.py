"""The validator with the project's built-in hands (models.hands): one code path with MJCF hands."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from models.errors import GraspError, ObjectError
from models.grasp import Grasp
from planner.validation import as_collision_object, get_protocol, project_hand, validate
from planner.validation.scene import get_scene

hands_module = pytest.importorskip("models.hands")
HANDS = ("shadow", "allegro", "leap")
SHORT = get_protocol("dexgraspbench", hold_time=0.4)
CUBE = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float) * 0.02


def open_grasp(name: str, offset=(0.0, 0.0, 0.0)) -> Grasp:
    hand = hands_module.load_hand(name)
    q = np.asarray(hand.open_pose, dtype=float)
    return Grasp.with_bodex_squeeze(name, offset, [1, 0, 0, 0], q, q, joint_names=hand.joint_names)


@pytest.mark.parametrize("name", HANDS)
def test_scene_follows_the_hand_contract(name):
    adapter = project_hand(name)
    scene = get_scene(adapter, as_collision_object([CUBE], name="cube"), SHORT)
    m = scene.model
    assert adapter.dof == hands_module.load_hand(name).dof == len(scene.joint_qpos)
    # one actuator per joint or per coupling (ShadowHand's J1/J2 tendons)
    assert m.nu == len(hands_module.load_hand(name).actuators()) and m.nmocap == 1
    assert m.opt.timestep == SHORT.timestep and m.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC
    assert scene.object_mass == pytest.approx(SHORT.object_mass, rel=1e-6)
    assert scene.hand_body.sum() >= adapter.dof // 4  # the hand's links, not the object


@pytest.mark.parametrize("name", HANDS)
def test_grasp_far_from_the_object_fails(name):
    far = open_grasp(name, offset=(0.3, 0.3, 0.3))
    result = validate(far, [CUBE], project_hand(name), SHORT)
    assert not result.success and result.reason == "slipped"
    assert result.contact_count == 0 and result.directions[0].translation > SHORT.max_translation


@pytest.mark.parametrize("name", HANDS)
def test_bad_joint_vectors_and_objects_give_clear_errors(name):
    adapter = project_hand(name)
    grasp = open_grasp(name)
    with pytest.raises(GraspError, match="NaN"):
        Grasp.from_dict(grasp.to_dict() | {"grasp": [np.nan] * grasp.dof})
    short = {k: grasp.joints(k)[:-1].tolist() for k in ("pregrasp", "grasp", "squeeze")}
    wrong = Grasp.from_dict(grasp.to_dict() | short | {"joint_names": None})
    with pytest.raises(GraspError, match=f"{grasp.dof - 1} joint values but hand"):
        validate(wrong, [CUBE], adapter, SHORT)
    with pytest.raises(ObjectError, match="no collision pieces"):
        validate(grasp, [], adapter, SHORT)
    with pytest.raises(ObjectError, match="no convex_pieces"):
        validate(grasp, "/nonexistent/objects/teapot", adapter, SHORT)
