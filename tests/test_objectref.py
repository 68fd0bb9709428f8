"""A grasp record names its object well enough to view it again, from the Python API as from the
CLI: library objects by (category, seed), files with their labels file and scale, objects made
from arrays with their geometry and labels."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from models.errors import ObjectError
from models.grasp import Grasp
from models.objects import load_object, make_object
from models.objects.loading import from_mesh
from planner.objectref import load_labelled, object_ref, resolve_object


def _same_object(a, b) -> None:
    assert a.part_names == b.part_names
    if a.mesh is not None:
        np.testing.assert_allclose(a.mesh.vertices, b.mesh.vertices, atol=1e-6)
        np.testing.assert_array_equal(a.mesh.faces, b.mesh.faces)
        np.testing.assert_array_equal(a.face_labels, b.face_labels)
    else:
        np.testing.assert_allclose(a.cloud, b.cloud, atol=1e-6)
        np.testing.assert_array_equal(a.cloud_labels, b.cloud_labels)


def test_references_rebuild_every_kind_of_object(tmp_path):
    mug = make_object("mug", 3)
    assert object_ref(mug) == {"category": "mug", "seed": 3}
    # a file with a labels file beside it elsewhere, loaded in millimetres
    mesh = trimesh.Trimesh(mug.mesh.vertices * 1000, mug.mesh.faces, process=False)
    path = tmp_path / "mug_mm.obj"
    mesh.export(path)
    labels = tmp_path / "labels.json"
    labels.write_text(
        json.dumps({"part_names": ["body", "handle"], "face_labels": mug.face_labels.tolist()})
    )
    scanned = load_object(path, scale=0.001)
    from models.objects.loading import with_labels_file

    scanned = with_labels_file(scanned, labels)
    ref = json.loads(json.dumps(object_ref(scanned)))  # what a grasp file holds
    assert ref["scale"] == 0.001 and ref["part_labels"] == str(labels.resolve())
    _same_object(resolve_object(ref), scanned)
    assert object_ref(load_labelled(path, labels, scale=0.001)) == ref
    # a labelled cloud from arrays: inline points and labels
    samples = mug.sample_cloud(3000, seed=1)
    cloud = load_object(samples.points, labels=samples.labels, part_names=mug.part_names)
    ref = json.loads(json.dumps(object_ref(cloud)))
    assert len(ref["cloud"]) == 3000 and ref["part_names"] == ["body", "handle"]
    _same_object(resolve_object(ref), cloud)
    # a mesh from arrays, labelled, with its pieces method
    arrays = from_mesh(mug.mesh, "mine", face_labels=mug.face_labels, part_names=mug.part_names)
    arrays.pieces = "surface"
    ref = json.loads(json.dumps(object_ref(arrays)))
    back = resolve_object(ref)
    _same_object(back, arrays)
    assert back.pieces == "surface"


def test_a_scanned_file_keeps_its_camera(tmp_path):
    """A single-view scan loaded from a file in millimetres with its camera: the grasp's
    reference brings the camera back, so the object is completed again as it was planned."""
    pts = make_object("bottle", 1).sample_cloud(2000, seed=1).points
    seen = pts[pts[:, 0] > 0]
    path = tmp_path / "scan_mm.npy"
    np.save(path, 1000 * seen)
    camera = np.array([0.5, 0.0, 0.2])
    scan = load_labelled(path, scale=0.001, viewpoint=1000 * camera)
    np.testing.assert_allclose(scan.viewpoint, camera)
    ref = json.loads(json.dumps(object_ref(scan)))
    back = resolve_object(ref)
    np.testing.assert_allclose(back.viewpoint, camera)
    np.testing.assert_allclose(back.normals, scan.normals, atol=1e-9)


@pytest.mark.parametrize(
    ("ref", "message"),
    [
        ({}, "names its object only as"),
        ([1], "names its object only as"),
        ({"category": "mug", "seed": "x"}, "seed must be a non-negative integer"),
        ({"category": 5}, "category must be a name"),
        ({"path": 5}, "must be a path"),
        ({"colour": "red"}, "neither category, path, cloud nor vertices"),
        ({"cloud": [[0, 0], [1]]}, "not a rectangular array"),
        ({"category": "mug", "seed": 1, "pieces": "magic"}, "pieces must be one of"),
    ],
)
def test_bad_references_are_named(ref, message):
    with pytest.raises(ObjectError, match=message):
        resolve_object(ref)


def test_a_grasp_planned_from_the_api_can_be_viewed_again(tmp_path, capsys):
    """`plan_grasp` on arrays: the saved grasp carries its object ("the grasp names its object
    only as {}" before), labels included, and `drograsp view` shows it."""
    from planner import plan_grasp
    from planner.cli import main

    bottle = make_object("bottle", 1)
    samples = bottle.sample_cloud(6000, seed=0)
    cloud = load_object(
        samples.points, normals=samples.normals, labels=samples.labels, part_names=bottle.part_names
    )
    result = plan_grasp(cloud, "Hold a bottle by body", "allegro")
    assert result.grasp is not None
    saved = result.grasp.save(tmp_path / "api" / "g.json")  # the folder is made
    ref = Grasp.load(saved).metrics["object"]
    assert ref["part_names"] == ["body", "neck", "cap"] and len(ref["cloud"]) == 6000
    page = tmp_path / "g.html"
    assert main(["view", str(saved), "--html", str(page)]) == 0, capsys.readouterr().err
    assert page.stat().st_size > 10_000
