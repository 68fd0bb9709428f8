"""eval.real_objects: meshes found with their categories, and a scan planned and judged on
its own mesh."""

from __future__ import annotations

import pytest
import trimesh

from eval.real_objects import (
    Record,
    Task,
    categories,
    handle_labels,
    run_task,
    sentences,
    summarise_verdicts,
)
from models.objects import make_object


def test_meshes_get_their_manifest_category_and_the_rest_their_stem(tmp_path):
    (tmp_path / "ycb").mkdir()
    box = trimesh.creation.box((0.05, 0.05, 0.1))
    box.export(tmp_path / "ycb" / "003_cracker_box.obj")
    box.export(tmp_path / "drill.stl")
    (tmp_path / "notes.txt").write_text("not a mesh")
    (tmp_path / "manifest.csv").write_text("file,category\nycb/003_cracker_box.obj,box\n")
    found = {p.name: c for p, c in categories(tmp_path).items()}
    assert found == {"003_cracker_box.obj": "box", "drill.stl": "drill"}


def test_every_category_has_free_sentences_and_others_get_generic_ones():
    assert sentences("mug") == ("grab the mug by its handle", "pick up the mug")
    assert sentences("power_tool") == ("pick up the power tool", "hold the power tool")


@pytest.mark.parametrize("seed", [0, 3, 9])
def test_a_mugs_handle_is_found_where_its_labels_put_it(seed):
    """The handle found on a mesh by its distance from the body's axis (no labels), checked
    on library mugs, whose labels are known."""
    obj = make_object("mug", seed)
    found = handle_labels(obj).point_labels == 1
    truth = obj.point_labels == obj.part_names.index("handle")
    assert (found & truth).sum() >= 0.8 * truth.sum()  # most of the handle
    assert (found & truth).sum() >= 0.95 * found.sum()  # and hardly anything else


def test_verdicts_are_summed_per_completion_of_the_view():
    def rec(completion: str, verdicts: list[list[bool]] | None) -> Record:
        r = Record("m", "mug", "pick up the mug", "allegro", "single", 0, completion=completion)
        r.verdicts = verdicts
        return r

    records = [
        rec("mirrored", [[True, True], [True, False], [False, False]]),
        rec("mirrored", [[False, True]]),
        rec("swept+mirrored", [[True, True]]),
        rec("as seen", None),  # planned without --verdicts: not counted
    ]
    rows = {r["completion"]: r for r in summarise_verdicts(records)}
    assert set(rows) == {"mirrored", "swept+mirrored", "all"}
    assert rows["mirrored"] == {
        "completion": "mirrored",
        "plans": 2,
        "candidates": 4,
        "held": 2,
        "held_on_mesh": 1,
        "slipped": 2,
        "slipped_held_on_mesh": 1,
    }
    assert rows["all"]["plans"] == 3 and rows["all"]["held_on_mesh"] == 2


@pytest.mark.slow  # one learned plan per hand on a mesh (about 10 s each)
def test_a_mesh_is_planned_and_judged_on_its_own_pieces(tmp_path, hand_name):
    path = tmp_path / "mug.obj"
    make_object("mug", 3).mesh.export(path)
    pages = tmp_path / "pages"
    text = "pick up the mug by its handle"
    rec = run_task(Task(str(path), "mug", text, hand_name, "mesh", 0, str(pages), verdicts=True))
    assert rec.error == ""
    # every validated candidate judged again on the mesh: on the mesh view, the same verdicts
    assert rec.completion == "" and rec.verdicts
    assert all(view == mesh for view, mesh in rec.verdicts)
    assert any(view for view, _ in rec.verdicts) == rec.planned
    assert rec.understood.startswith("Liftup")
    # on the mesh view the planner validated on the same pieces: its verdict is the mesh's
    assert rec.held == rec.planned
    assert rec.status == ("holds" if rec.planned else "none")
    # Liftup needs no labels: checked wherever a grasp held
    assert (rec.intent_ok is not None) == rec.held
    # the sentence names the handle: the part a held grasp touches is scored on the mesh
    assert rec.part_touched in (("body", "handle") if rec.held else (None,))
    # a page of the returned grasp on the mesh, where one was returned
    written = list(pages.glob("mug_mesh_*_pick_up_the_mug_by_its_handle_s0.html"))
    assert len(written) == (1 if rec.status != "none" else 0)
