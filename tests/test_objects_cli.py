"""`drograsp objects`: listing, export, contact sheet."""

from __future__ import annotations

import argparse
import json

import numpy as np
import pytest

from models.objects import categories, load_object, make_object
from planner.commands import objects as cmd


def _run(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="drograsp")
    sub = parser.add_subparsers(dest="command")
    cmd.register(sub)
    args = parser.parse_args(argv)
    return args.func(args)


def test_listing_json(capsys):
    assert _run(["objects", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert [r["category"] for r in rows] == list(categories())
    mug = rows[0]
    assert mug["parts"] == ["body", "handle"] and "Use a mug by handle" in mug["instructions"]
    assert sum(r["heldout"] for r in rows) >= 2


def test_listing_text(capsys):
    assert _run(["objects"]) == 0
    out = capsys.readouterr().out
    assert "knife: parts blade, handle" in out and "Handover a knife by blade" in out


def test_export_writes_mesh_and_labels(tmp_path, capsys):
    out = tmp_path / "mug3.obj"
    assert _run(["objects", "export", "mug", "--seed", "3", str(out)]) == 0
    parts = json.loads(out.with_suffix(".parts.json").read_text())
    assert parts["part_names"] == ["body", "handle"] and parts["seed"] == 3
    back = load_object(out)
    assert back.mesh.is_watertight
    np.testing.assert_array_equal(back.face_labels, make_object("mug", 3).face_labels)
    assert "wrote" in capsys.readouterr().out


@pytest.mark.slow
def test_sheet_writes_a_png(tmp_path):
    out = tmp_path / "sheet.png"
    assert _run(["objects", "sheet", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 50_000


def test_output_piped_into_head_ends_without_a_traceback():
    import subprocess
    import sys
    from pathlib import Path

    code = "import sys; from planner import cli; sys.exit(cli.main(sys.argv[1:]))"
    listing = subprocess.Popen(
        [sys.executable, "-c", code, "objects"],
        cwd=Path(__file__).resolve().parents[1],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    listing.stdout.readline()
    listing.stdout.close()  # what `| head -1` does
    _, err = listing.communicate(timeout=120)
    assert b"Traceback" not in err, err.decode()
