"""Validator on each built-in hand: a box grasp that holds passes, the same grasp moved 5 cm
away fails, and squeeze = grasp (light contact) fails."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from models.grasp import Grasp
from models.objects.loading import from_mesh
from planner.functional import FunctionalPlanner
from planner.validation import validate


@pytest.fixture(scope="module")
def box():
    mesh = trimesh.creation.box(extents=[0.05, 0.05, 0.1])
    return from_mesh(mesh, "box", face_labels=np.zeros(len(mesh.faces), int), part_names=("body",))


def test_box_grasp_holds_and_fails_when_moved_or_not_squeezed(hand_name, box):
    result = FunctionalPlanner(hand_name).plan(box, "Hold a box by body")
    assert result.success, [c.summary() for c in result.candidates]
    grasp, pieces = result.grasp, box.collision_pieces()
    assert validate(grasp, pieces, hand_name, "paper").success
    assert not validate(grasp.moved([0.05, 0.0, 0.0]), pieces, hand_name, "paper").success
    light = Grasp.from_dict({**grasp.to_dict(), "squeeze": grasp.grasp.tolist()})
    assert not validate(light, pieces, hand_name, "paper").success
