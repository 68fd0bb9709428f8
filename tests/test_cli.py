"""The command line as a user meets it: start-up without the heavy libraries, exit codes 0 / 1 /
2, outputs checked before the work, Meshcat on localhost, and pages with a caption."""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

from planner import cli

REPO = Path(__file__).resolve().parents[1]
HEAVY = ("torch", "pydrake", "mujoco", "trimesh", "manifold3d", "coacd", "scipy")


def _drograsp(*argv: str, timeout: float = 600) -> subprocess.CompletedProcess:
    code = "import sys; from planner import cli; sys.exit(cli.main(sys.argv[1:]))"
    return subprocess.run(
        [sys.executable, "-c", code, *argv],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=timeout,
    )


@pytest.mark.parametrize(
    "argv",
    [
        ["--help"],
        ["plan", "--help"],
        ["plan", "--object", "unicorn", "--text", "x"],
        ["plan", "--object", "mug", "--text", "Use a mug by handle", "--candidates", "0"],
        ["validate", "--help"],
        ["batch", "x.jsonl", "out", "--workers", "0"],
        ["objects", "export", "mug", "m.obj", "--seed", "-1"],
        ["export", "--help"],
        ["hands", "--help"],
        ["hands", "--json", "--nosuch"],
        ["nosuch"],
    ],
)
def test_help_and_argument_errors_import_nothing_heavy(argv):
    """`drograsp --help` took 9 s: torch, Drake and MuJoCo loaded before argparse ran. Now only
    the chosen command's module loads, and commands import their libraries when they run
    (`drograsp hands --help` took 4 s: it imported the hand models to register)."""
    probe = (
        "import sys, contextlib, io\n"
        "from planner import cli\n"
        "with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):\n"
        "    try:\n"
        f"        cli.main({argv!r})\n"
        "    except SystemExit:\n"
        "        pass\n"
        f"print(sorted(m for m in {HEAVY!r} if m in sys.modules))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", probe], cwd=REPO, capture_output=True, text=True, timeout=120
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]", f"drograsp {' '.join(argv)} imported {out.stdout}"


def test_the_command_list_matches_the_commands():
    """cli.COMMANDS (shown by --help without importing the commands) says what each
    command's own parser says."""
    parser = cli.build_parser()  # every command, fully
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    helps = {action.dest: action.help for action in sub._choices_actions}
    assert helps == cli.COMMANDS
    from planner.batch.runner import SHARD_SIZE
    from planner.commands import batch
    from planner.commands.args import PRESET_NAMES
    from planner.validation.protocol import PRESETS

    assert batch.SHARD_SIZE == SHARD_SIZE and set(PRESET_NAMES) == set(PRESETS)


def _labelled_box(folder: Path, extents, name: str) -> tuple[Path, Path]:
    mesh = trimesh.creation.box(extents=extents)
    path = folder / f"{name}.obj"
    mesh.export(path)
    labels = folder / f"{name}.labels.json"
    labels.write_text(json.dumps({"part_names": ["body"], "face_labels": [0] * len(mesh.faces)}))
    return path, labels


@pytest.mark.slow  # three CLI processes, each loading the planner (10 s)
def test_exit_codes_success_no_grasp_and_bad_input(tmp_path):
    """0: a grasp holds (and --out is written into a folder made for it); 1: the planner ran and
    nothing held; 2: bad input, reported without a traceback."""
    out = tmp_path / "new" / "folder" / "g.json"
    ok = _drograsp(
        "plan", "--object", "bottle", "--seed", "1", "--text", "Hold a bottle by body",
        "--hand", "allegro", "--out", str(out),
    )  # fmt: skip
    assert ok.returncode == 0, ok.stderr
    assert json.loads(out.read_text())["metrics"]["object"] == {"category": "bottle", "seed": 1}
    big, labels = _labelled_box(tmp_path, [0.5, 0.5, 0.5], "crate")
    none = _drograsp(
        "plan", "--mesh", str(big), "--part-labels", str(labels), "--text",
        "Hold a crate by body", "--hand", "allegro", "--candidates", "1",
    )  # fmt: skip
    assert none.returncode == 1, none.stderr
    assert "no grasp found" in none.stderr and "Traceback" not in none.stderr
    bad = _drograsp("plan", "--object", "mug", "--text", "Use a mug by lid", "--hand", "allegro")
    assert bad.returncode == 2 and "lid" in bad.stderr and "Traceback" not in bad.stderr


def test_outputs_are_checked_before_the_work(tmp_path, capsys):
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    plan = ["plan", "--object", "bottle", "--seed", "1", "--text", "Hold a bottle by body"]
    plan += ["--hand", "allegro"]
    assert cli.main([*plan, "--out", str(blocker / "g.json")]) == 2
    err = capsys.readouterr().err
    assert "a_file" in err and "in the way" in err and "planning" not in err
    assert cli.main([*plan, "--out", str(tmp_path / "g.txt")]) == 2
    assert "must end in .json or .npz" in capsys.readouterr().err
    rows = tmp_path / "rows.npz"
    np.savez(rows, grasp_qpos=np.zeros((1, 23)))
    argv = ["validate", str(rows), "--hand", "allegro", "--objects", str(tmp_path)]
    assert cli.main([*argv, "--out", str(tmp_path / "results.npz")]) == 2
    assert "results.npz must end in .json" in capsys.readouterr().err
    for argv in (
        ["objects", "export", "mug", str(tmp_path / "m.stl")],
        ["objects", "sheet", str(tmp_path / "s.xyz")],
        ["view", str(tmp_path / "g.json"), "--html", str(tmp_path / "v.png")],
        ["jobs", "make", str(blocker / "j.jsonl"), "--hands", "leap"],
        ["batch", str(tmp_path / "none.jsonl"), str(tmp_path / "b")],
        ["demo", "--out", str(blocker / "demo")],
    ):
        assert cli.main(argv) == 2, argv
        assert "Traceback" not in capsys.readouterr().err


def test_open_mesh_with_labels_plans_instead_of_aborting(tmp_path):
    """`drograsp plan --mesh SCAN --part-labels ...` aborted (exit 134) in CoACD, which was fed
    a mesh it cannot take; an open mesh now gets surface pieces and the plan runs."""
    tube = trimesh.creation.cylinder(radius=0.03, height=0.1, sections=32)
    keep = np.abs(tube.face_normals[:, 2]) < 0.5  # the side wall only: open at both ends
    tube.update_faces(keep)
    tube.remove_unreferenced_vertices()
    path = tmp_path / "tube.obj"
    tube.export(path)
    labels = tmp_path / "tube.json"
    labels.write_text(json.dumps({"part_names": ["body"], "face_labels": [0] * len(tube.faces)}))
    run = _drograsp(
        "plan", "--mesh", str(path), "--part-labels", str(labels), "--text",
        "Hold a tube by body", "--hand", "allegro", "--candidates", "2",
    )  # fmt: skip
    assert run.returncode in (0, 1), run.stderr
    assert "open (not watertight)" in run.stderr


def test_meshcat_listens_on_localhost_and_pages_have_a_caption(tmp_path):
    from models.grasp import Grasp
    from models.hands import load_hand
    from models.objects import make_object
    from planner.viewer import new_meshcat, write_html

    meshcat = new_meshcat()
    assert meshcat.web_url().startswith("http://localhost:")
    z = np.zeros(16)
    grasp = Grasp(
        "allegro", [0, 0, 0.2], [1, 0, 0, 0], z, z, z, instruction="Use a mug by handle",
        metrics={"success": True, "part": "handle", "squeeze_depth": 2.0},
    )  # fmt: skip
    page = write_html(grasp, make_object("mug", 3), load_hand("allegro"), tmp_path / "p.html")
    text = page.read_text()
    assert "allegro · Use a mug by handle · holds · part touched: handle" in text
    assert "pregrasp &rarr; grasp &rarr; squeeze" in text


@pytest.mark.usefixtures("needs_open3d")
def test_a_scanned_cloud_takes_its_camera_position(tmp_path, capsys):
    """`--viewpoint` marks --mesh as a single-view scan (normals face the camera; the planner
    completes the hidden side); it is refused for a library object or a mesh."""
    from models.objects import make_object
    from models.objects.views import single_view
    from planner.commands.plan import check_object_arguments, object_from_args

    points, _, eye = single_view(make_object("bottle", 1), seed=1)
    scan = tmp_path / "scan.npy"
    np.save(scan, points)
    args = argparse.Namespace(
        object=None, mesh=str(scan), part_labels=None, viewpoint=list(eye), pieces="auto"
    )
    check_object_arguments("plan", args)
    obj = object_from_args(args)
    assert np.allclose(obj.viewpoint, eye) and obj.mesh is None
    plan = ["plan", "--text", "hold the bottle", "--hand", "allegro", "--viewpoint", "1", "0", "0"]
    assert cli.main([*plan, "--object", "bottle"]) == 2
    assert "--viewpoint places the camera" in capsys.readouterr().err
    mesh = tmp_path / "box.obj"
    trimesh.creation.box([0.05, 0.05, 0.05]).export(mesh)
    assert cli.main([*plan, "--mesh", str(mesh)]) == 2
    err = capsys.readouterr().err
    assert "single-view point cloud" in err and "Traceback" not in err
