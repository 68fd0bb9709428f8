"""What a depth camera sees (models.objects.views) and objects turned in space."""

from __future__ import annotations

import sys

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

from models.errors import ObjectError
from models.objects import load_object, make_object
from models.objects.completion import complete_view
from models.objects.views import (
    Camera,
    random_turn,
    sampled_cloud_object,
    single_view,
    single_view_object,
    turned,
)


@pytest.mark.usefixtures("needs_open3d")
def test_a_single_view_is_the_near_side_of_the_surface_with_depth_noise():
    mug = make_object("mug", 3)
    points, labels, eye = single_view(mug, Camera(depth_noise=0.001), seed=0)
    assert 1000 < len(points) < 320 * 240 and labels is not None and len(labels) == len(points)
    _, distance, _ = trimesh.proximity.closest_point(mug.mesh, points)
    assert np.median(distance) < 0.0015 and distance.max() < 0.006  # 1 mm noise along rays
    # the camera sees the side facing it: the points lie nearer the camera than the far side
    centre = mug.mesh.bounds.mean(axis=0)
    toward = (eye - centre) / np.linalg.norm(eye - centre)
    assert np.mean((points - centre) @ toward > -0.01) > 0.8
    view = single_view_object(mug, seed=0, labelled=True)
    assert view.labelled and view.part_names == mug.part_names
    assert not single_view_object(mug, seed=0).labelled


@pytest.mark.usefixtures("needs_open3d")
def test_a_view_needs_a_mesh_and_enough_points():
    cloud = load_object(make_object("mug", 3).sample_cloud(2048).points)
    with pytest.raises(ObjectError, match="from a mesh"):
        single_view(cloud)
    with pytest.raises(ObjectError, match="closer"):
        single_view(make_object("mug", 3), Camera(distance=20.0))


def test_a_turned_object_keeps_its_shape_and_labels():
    mug = make_object("mug", 3)
    rot = random_turn(5)
    assert np.allclose(rot @ rot.T, np.eye(3)) and np.linalg.det(rot) == pytest.approx(1.0)
    # at most 30 degrees of tilt: the object's up axis stays within 30 degrees of vertical
    assert rot[2, 2] >= np.cos(np.radians(30)) - 1e-9
    t = turned(mug, rot)
    assert t.labelled and t.part_names == mug.part_names and t.seed is None
    assert np.allclose(t.mesh.vertices, mug.mesh.vertices @ rot.T)
    assert np.allclose(t.construction_pieces[0], np.asarray(mug.construction_pieces[0]) @ rot.T)
    with pytest.raises(ObjectError, match="rotation"):
        turned(mug, np.eye(3) * 2)


@pytest.mark.usefixtures("needs_open3d")
@pytest.mark.parametrize("category", ["bottle", "wine_glass", "hammer", "knife"])
def test_a_completed_view_covers_the_hidden_side_where_the_object_is(category):
    obj = make_object(category, 3)
    view = single_view_object(obj, seed=3)
    done = complete_view(view)
    assert done.viewpoint is None and len(done.points) > 1.5 * len(view.points)
    assert done.completed_by in ("swept", "mirrored", "swept+mirrored")

    def covered(points: np.ndarray) -> float:
        return float((cKDTree(points).query(obj.points)[0] < 0.005).mean())

    # the mirrored half lies near the real surface (the plane may sit a few mm toward the
    # camera: a bottle's back comes out up to 8 mm too near), and covers much of what was hidden
    error = cKDTree(obj.points).query(done.points)[0]
    assert np.percentile(error, 90) < 0.01
    assert covered(done.points) > covered(view.points) + 0.15


@pytest.mark.usefixtures("needs_open3d")
def test_upright_round_objects_are_swept_about_their_axis_and_others_are_not():
    from models.objects.completion import find_revolution

    def covered(obj, points: np.ndarray) -> float:
        return float((cKDTree(points).query(obj.points)[0] < 0.005).mean())

    bottle = make_object("bottle", 3)
    view = single_view_object(bottle, seed=3)
    turn = find_revolution(view.points, np.asarray(view.viewpoint))
    assert turn is not None and turn.swept.mean() > 0.9
    # the axis: the bottle's own (the procedural objects stand on z about x = y = 0)
    axis = bottle.points[:, :2].mean(axis=0)
    assert np.linalg.norm(turn.centre - axis) < 0.005
    done = complete_view(view)
    assert covered(bottle, done.points) > 0.85
    assert np.percentile(cKDTree(bottle.points).query(done.points)[0], 90) < 0.003
    # its underside, which the camera above never sees, is closed by a disc at its lowest point
    underside = bottle.points[bottle.points[:, 2] < bottle.points[:, 2].min() + 0.001]
    assert len(underside) > 20
    assert (cKDTree(done.points).query(underside)[0] < 0.005).mean() > 0.95
    assert (cKDTree(view.points).query(underside)[0] < 0.005).mean() < 0.5
    # a mug's handle is no surface of revolution: its points are mirrored, not swept
    mug = make_object("mug", 3)
    view = single_view_object(mug, seed=3, labelled=True)
    turn = find_revolution(view.points, np.asarray(view.viewpoint))
    handle = view.point_labels == mug.part_names.index("handle")
    assert turn is not None and handle.any()
    assert turn.swept[handle].mean() < 0.5 < turn.swept[~handle].mean()
    # a knife lying down has no vertical axis to sweep about
    knife = single_view_object(make_object("knife", 3), seed=3)
    assert find_revolution(knife.points, np.asarray(knife.viewpoint)) is None


@pytest.mark.usefixtures("needs_open3d")
def test_a_mugs_handle_is_mirrored_through_the_plane_through_its_axis():
    from models.objects.completion import find_completion, smooth

    mug = make_object("mug", 19)
    view = single_view_object(mug, seed=19, labelled=True)
    plan = find_completion(smooth(view.points), np.asarray(view.viewpoint))
    assert plan.axial and plan.revolution is not None
    # the handle stands out along x from the body's axis: the plane through both is y = 0
    assert abs(plan.mirror.normal[1]) > 0.99
    done = complete_view(view)
    handle = mug.points[mug.point_labels == mug.part_names.index("handle")]
    assert (cKDTree(done.points).query(handle)[0] < 0.005).mean() > 0.9
    # no phantom handle: the view's own plane (facing the camera) put a copy 15-35 mm away
    assert np.percentile(cKDTree(mug.points).query(done.points)[0], 99) < 0.005


def test_a_completion_says_what_it_added():
    from models.objects.completion import Completion, Mirror, Revolution

    mirror = Mirror(np.array([1.0, 0.0, 0.0]), 0.0, 0.01)
    turn = Revolution(np.zeros(2), np.ones(3, dtype=bool), np.ones((3, 15), dtype=bool), 0.01)
    assert Completion(None, None).kind == "as seen"
    assert Completion(None, mirror).kind == "mirrored"
    assert Completion(turn, None).kind == "swept"
    assert Completion(turn, mirror, axial=True).kind == "swept+mirrored"


def test_completion_leaves_meshes_and_clouds_without_a_camera_alone():
    mug = make_object("mug", 3)
    assert complete_view(mug) is mug
    cloud = load_object(mug.sample_cloud(2048).points)
    assert complete_view(cloud) is cloud


@pytest.mark.usefixtures("needs_open3d")
@pytest.mark.parametrize("complete", [True, False])
def test_the_planner_plans_on_the_completed_view_unless_told_not_to(complete, monkeypatch):
    from planner.functional import FunctionalPlanner
    from planner.settings import PlannerSettings

    view = single_view_object(make_object("bottle", 3), seed=3)
    planner = FunctionalPlanner("allegro", PlannerSettings(complete_views=complete))
    seen = []

    def stop(obj, instruction):
        seen.append(obj)
        raise RuntimeError("stop here")

    monkeypatch.setattr(planner, "proposer_for", stop)
    with pytest.raises(RuntimeError, match="stop here"):
        planner.plan(view, "hold the bottle")
    assert (len(seen[0].points) > len(view.points)) == complete
    assert seen[0].completed_by == ("swept+mirrored" if complete else None)


@pytest.mark.usefixtures("needs_open3d")
def test_a_grasp_on_a_completed_view_says_its_verdict_rests_on_the_guess(monkeypatch):
    from models.objects import parse_instruction
    from planner.functional import FunctionalPlanner
    from planner.results import PlanResult

    planner = FunctionalPlanner("allegro")
    instruction = parse_instruction("Hold a bottle by body")

    def planned(grasp):
        def fake(obj, instruction_):
            return PlanResult(instruction, "allegro", grasp, [], ["another note"])

        return fake

    view = single_view_object(make_object("bottle", 3), seed=3)
    monkeypatch.setattr(planner, "_plan", planned(object()))
    result = planner.plan(view, "hold the bottle")
    notes = result.notes
    assert result.completed_by == "swept+mirrored" == result.summary()["completed_by"]
    assert notes[0] == "another note" and "completed by sweeping it" in notes[1]
    assert len(planner.plan(make_object("bottle", 3), "hold the bottle").notes) == 1  # a mesh
    # no grasp returned: nothing to say of one
    monkeypatch.setattr(planner, "_plan", planned(None))
    assert planner.plan(view, "hold the bottle").notes == ["another note"]
    # a view no sweep or plane completes is planned as seen, its back open
    monkeypatch.setattr("planner.functional.complete_view", _as_seen)
    monkeypatch.setattr(planner, "_plan", planned(object()))
    assert "hidden back is open" in planner.plan(view, "hold the bottle").notes[1]


def _as_seen(obj):
    done = load_object(obj.points, normals=obj.normals)
    done.completed_by = "as seen"
    return done


@pytest.mark.usefixtures("needs_open3d")
def test_eval_completion_reports_what_the_completion_added():
    from eval.completion import measure, table

    row = measure("hammer", 5)
    assert row.completed_coverage > row.view_coverage and row.plane == "below"
    assert row.swept == 0.0  # a hammer lying down is no surface of revolution
    cup = measure("cup", 1)
    assert cup.swept > 0.9 and cup.completed_coverage > 0.85
    assert "| hammer | 1 |" in table([row]) and "| all | 2 | " in table([row, cup])
    assert "| 1 (" in table([cup])


def test_a_view_without_open3d_says_which_library_is_missing(monkeypatch):
    monkeypatch.setitem(sys.modules, "open3d", None)  # the import fails as on a slim machine
    with pytest.raises(ObjectError, match="rendering a single view needs Open3D.*libusb"):
        single_view(make_object("mug", 3))


def test_a_sampled_cloud_is_the_whole_surface_without_its_mesh():
    mug = make_object("mug", 3)
    cloud = sampled_cloud_object(mug, 2000, seed=1)
    assert cloud.mesh is None and cloud.viewpoint is None and not cloud.labelled
    assert len(cloud.points) == 2000
    near = cKDTree(mug.sample_cloud(20000, seed=2).points).query(cloud.points)[0]
    assert near.max() < 0.005  # on the surface
    labelled = sampled_cloud_object(mug, 2000, seed=1, labelled=True)
    assert labelled.labelled and labelled.part_names == mug.part_names
    assert np.allclose(labelled.points, cloud.points)
