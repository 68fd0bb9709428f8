"""Validator on each built-in hand: a box grasp that holds passes, the same grasp moved 5 cm
away fails, and squeeze = grasp (light contact) fails.

The holding grasp comes from the model-based planner; it is not equally good on every box size
for every hand, so the first of a few boxes that it grasps is used (the checks are about the
validator's verdicts, the planner has its own benchmark)."""

from __future__ import annotations

import numpy as np
import trimesh

from models.grasp import Grasp
from models.objects.loading import from_mesh
from planner.functional import FunctionalPlanner
from planner.validation import validate

BOXES = ([0.05, 0.05, 0.1], [0.04, 0.04, 0.1], [0.06, 0.04, 0.1], [0.035, 0.035, 0.1])


def _box(extents):
    mesh = trimesh.creation.box(extents=extents)
    return from_mesh(mesh, "box", face_labels=np.zeros(len(mesh.faces), int), part_names=("body",))


def test_box_grasp_holds_and_fails_when_moved_or_not_squeezed(hand_name):
    planner = FunctionalPlanner(hand_name)
    for extents in BOXES:
        box = _box(extents)
        result = planner.plan(box, "Hold a box by body")
        if result.success:
            break
    assert result.success, f"no holding grasp on any of {BOXES}"
    grasp, pieces = result.grasp, box.collision_pieces()
    assert validate(grasp, pieces, hand_name, "paper").success
    assert not validate(grasp.moved([0.05, 0.0, 0.0]), pieces, hand_name, "paper").success
    light = Grasp.from_dict({**grasp.to_dict(), "squeeze": grasp.grasp.tolist()})
    assert not validate(light, pieces, hand_name, "paper").success


def test_mujoco_warnings_go_into_the_result_not_to_stderr(monkeypatch, capfd):
    """An unstable simulation's warning is recorded with the verdict; MuJoCo's own handler (a
    line on stderr and MUJOCO_LOG.TXT in the working folder) is back in place afterwards."""
    import mujoco

    from planner.validation import validator

    def unstable(*args):
        model = mujoco.MjModel.from_xml_string(
            '<mujoco><worldbody><body><freejoint/><geom size=".01"/></body></worldbody></mujoco>'
        )
        data = mujoco.MjData(model)
        data.xfrc_applied[1, 0] = np.inf
        mujoco.mj_step(model, data)
        mujoco.mj_step(model, data)  # the same warning twice is kept once
        return validator.ValidationResult(success=False, reason="slipped")

    monkeypatch.setattr(validator, "_validate", unstable)
    z = np.zeros(16)
    result = validator.validate(Grasp("allegro", [0, 0, 0], [1, 0, 0, 0], z, z, z), None, None)
    assert result.warnings == [
        "Nan, Inf or huge value in QACC at DOF 0. The simulation is unstable."
    ]
    assert "QACC" not in capfd.readouterr().err
    assert mujoco.get_mju_user_warning() is None


def test_a_reset_or_non_finite_simulation_is_never_held():
    """MuJoCo resets the state on NaN, inf or huge values (a wrist 1e12 m away, a force of
    1e20 N): the object then sits where it started, which must not read as held."""
    from planner.validation import get_protocol

    box = _box(BOXES[0])
    pieces = box.collision_pieces()
    result = FunctionalPlanner("allegro").plan(box, "Hold a box by body")
    assert result.success
    grasp = result.grasp
    far = validate(grasp.moved([1e12, 0.0, 0.0]), pieces, "allegro", "paper")
    assert not far.success and far.reason == "unstable"
    assert any("unstable" in w for w in far.warnings)
    pushed = validate(grasp, pieces, "allegro", get_protocol("paper", force_scale=1e20))
    assert not pushed.success and pushed.reason == "unstable"
    assert pushed.directions and pushed.directions[-1].unstable
    huge = grasp.to_dict() | {"wrist_pos": [1e300, 0.0, 0.0]}
    assert not validate(Grasp.from_dict(huge), pieces, "allegro", "paper").success


def test_the_scene_reserves_room_for_many_contacts(hand_name):
    """A closing hand on a cloud's many pieces can make hundreds of contacts: MuJoCo's default
    arena (sized from the model) aborted such a validation with "mj_stackAlloc: out of memory"
    (LEAP on a single view of a YCB soup can: 422 contacts); the scene reserves ARENA_BYTES."""
    from models.hands import load_hand
    from planner.validation.hands import as_hand
    from planner.validation.objects import as_collision_object
    from planner.validation.protocol import get_protocol
    from planner.validation.scene import ARENA_BYTES, get_scene

    box = as_collision_object([trimesh.creation.box((0.05, 0.05, 0.05))])
    scene = get_scene(as_hand(load_hand(hand_name)), box, get_protocol("paper"))
    assert scene.model.narena >= ARENA_BYTES
