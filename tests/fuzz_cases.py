"""Seeded fuzz of every entry point a user's data goes through (issue 28's rule).

Every case is a clean `DrograspError` (bad input) or a correct result (good input): never
another exception, never a hang, never a crash of the process, never bad input accepted. Cases
run in a worker subprocess, one after the other; the parent gives each a time limit, and a case
that hangs or kills its worker (an abort, a segfault) is recorded and the worker restarted.

    python -m tests.fuzz_cases [--seed 0] [--scale 1] [--groups objects,cli] [--timeout 30]

prints the figures (cases, clean errors, correct results, other exceptions by signature, hangs,
crashes, bad input accepted, CLI tracebacks); `tests/test_fuzz.py` asserts them.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import select
import subprocess
import sys
import time
import traceback
import zipfile
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
GROUPS = (
    "objects", "files", "library", "text", "grasps", "validate", "plan", "jobs", "cli", "hands",
)  # fmt: skip


@dataclass
class Case:
    name: str
    group: str
    fn: Callable[[], Any]
    expect: str  # "error": a DrograspError; "ok": a result that passes `check`; "either"
    check: Callable[[Any], str | None] | None = None  # problem with a result, or None
    match: str | None = None  # an error's message must contain this (e.g. the file it names)


@dataclass
class Outcome:
    name: str
    group: str
    kind: str  # clean_error, ok, other_exception, accepted_bad, wrong_result, hang, crash
    detail: str = ""
    seconds: float = 0.0


# ---------------------------------------------------------------------- inputs
def _ball(rng: np.random.Generator, n: int, radius: float) -> np.ndarray:
    v = rng.normal(size=(n, 3))
    return radius * v / np.linalg.norm(v, axis=1, keepdims=True)


def _box_obj(path: Path, size: float = 0.05, extra: str = "") -> Path:
    s = size / 2
    corners = [(x, y, z) for x in (-s, s) for y in (-s, s) for z in (-s, s)]
    faces = [
        (1, 3, 4), (1, 4, 2), (5, 6, 8), (5, 8, 7), (1, 2, 6), (1, 6, 5),
        (3, 7, 8), (3, 8, 4), (1, 5, 7), (1, 7, 3), (2, 4, 8), (2, 8, 6),
    ]  # fmt: skip
    text = "".join(f"v {x} {y} {z}\n" for x, y, z in corners)
    text += "".join(f"f {a} {b} {c}\n" for a, b, c in faces) + extra
    path.write_text(text)
    return path


def _open_cylinder(path: Path, n: int = 48, rows: int = 12) -> Path:
    """A tube without caps: an open mesh, like a scan that misses a side."""
    lines = []
    for r in range(rows):
        z = 0.1 * r / (rows - 1) - 0.05
        for k in range(n):
            a = 2 * np.pi * k / n
            lines.append(f"v {0.03 * np.cos(a):.6f} {0.03 * np.sin(a):.6f} {z:.6f}")
    for r in range(rows - 1):
        for k in range(n):
            a, b = r * n + k + 1, r * n + (k + 1) % n + 1
            c, d = a + n, b + n
            lines += [f"f {a} {b} {d}", f"f {a} {d} {c}"]
    path.write_text("\n".join(lines) + "\n")
    return path


def _files(tmp: Path) -> dict[str, Path]:
    """Files the cases read, written once per worker (same bytes for the same seed)."""
    rng = np.random.default_rng(1234)
    f: dict[str, Path] = {}
    tmp.mkdir(parents=True, exist_ok=True)
    f["box"] = _box_obj(tmp / "box.obj")
    f["box_mm"] = _box_obj(tmp / "box_mm.obj", size=50.0)
    f["box_badface"] = _box_obj(tmp / "box_badface.obj", extra="f 1 2 99\n")
    f["box_nan"] = tmp / "box_nan.obj"
    f["box_nan"].write_text(f["box"].read_text().replace("v -0.025 -0.025 -0.025", "v nan 0 0"))
    f["open"] = _open_cylinder(tmp / "open_tube.obj")
    f["open_labels"] = tmp / "open_tube_labels.json"
    f["open_labels"].write_text(json.dumps({"part_names": ["body"], "face_labels": [0] * 1056}))
    ply = tmp / "badface.ply"
    verts = _ball(rng, 8, 0.03)
    header = (
        "ply\nformat ascii 1.0\nelement vertex 8\nproperty float x\nproperty float y\n"
        "property float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n"
    )
    body = "".join(f"{x:.5f} {y:.5f} {z:.5f}\n" for x, y, z in verts) + "3 0 1 2\n3 0 1 40\n"
    ply.write_text(header + body)
    f["ply_badface"] = ply
    for suffix in (".obj", ".stl", ".ply", ".glb", ".npy", ".xyz", ".pcd", ".off"):
        empty = tmp / f"empty{suffix}"
        empty.write_bytes(b"")
        f[f"empty{suffix}"] = empty
        junk = tmp / f"junk{suffix}"
        junk.write_bytes(bytes(rng.integers(0, 256, 300, dtype=np.uint8)))
        f[f"junk{suffix}"] = junk
    np.save(tmp / "cloud.npy", _ball(rng, 500, 0.04))
    f["cloud.npy"] = tmp / "cloud.npy"
    np.save(tmp / "objects.npy", np.array([{"a": 1}, None], dtype=object), allow_pickle=True)
    f["pickle.npy"] = tmp / "objects.npy"
    np.save(tmp / "flat.npy", np.zeros((100, 2)))
    f["flat.npy"] = tmp / "flat.npy"
    (tmp / "text.xyz").write_text("a b c\n1 2 3\n")
    f["text.xyz"] = tmp / "text.xyz"
    (tmp / "short.xyz").write_text("1 2\n3 4\n")
    f["short.xyz"] = tmp / "short.xyz"
    f["unknown"] = tmp / "thing.xyzw"
    f["unknown"].write_text("1 2 3\n")
    # a labelled mesh with sidecars of every broken kind
    for kind, text in {
        "json": "{not json",
        "utf8": b"\xff\xfe\x00bad".decode("latin-1"),
        "types": '{"face_labels": "abc", "part_names": 5}',
        "negative": '{"face_labels": [-1,0,0,0,0,0,0,0,0,0,0,0], "part_names": ["a"]}',
        "count": '{"face_labels": [0, 0], "part_names": ["a"]}',
        "list": "[1, 2, 3]",
        "names": '{"face_labels": [0,0,0,0,0,0,0,0,0,0,0,0], "part_names": "body"}',
        "float": '{"face_labels": [0.5,0,0,0,0,0,0,0,0,0,0,0], "part_names": ["a"]}',
    }.items():
        mesh = _box_obj(tmp / f"side_{kind}.obj")
        side = mesh.with_suffix(".parts.json")
        side.write_bytes(text.encode("latin-1") if kind == "utf8" else text.encode())
        f[f"side_{kind}"] = mesh
    labels = tmp / "labels.json"
    labels.write_text(json.dumps({"part_names": ["body"], "face_labels": [0] * 12}))
    f["labels"] = labels
    for kind, text in {
        "json": "{",
        "utf8": None,
        "empty": "",
        "types": '{"part_names": 5, "face_labels": {}}',
        "bignames": json.dumps({"part_names": ["a"] * 3, "face_labels": [0] * 12}),
        "huge": json.dumps({"part_names": ["a"], "face_labels": [7] * 12}),
        "nolabels": '{"part_names": ["a"]}',
        "strnames": json.dumps({"part_names": "body", "face_labels": [0] * 12}),
    }.items():
        p = tmp / f"labels_{kind}.json"
        p.write_bytes(b"\xff\xfe\xfa" if text is None else text.encode())
        f[f"labels_{kind}"] = p
    # grasp records
    from models.grasp import Grasp

    good = Grasp("allegro", [0, 0, 0.1], [1, 0, 0, 0], np.zeros(16), np.zeros(16), np.zeros(16))
    f["grasp.json"] = good.save(tmp / "grasp.json")
    f["grasp.npz"] = good.save(tmp / "grasp.npz")
    data = f["grasp.npz"].read_bytes()
    (tmp / "trunc.npz").write_bytes(data[: len(data) // 2])
    f["trunc.npz"] = tmp / "trunc.npz"
    (tmp / "trunc.json").write_text(f["grasp.json"].read_text()[:50])
    f["trunc.json"] = tmp / "trunc.json"
    (tmp / "empty.json").write_bytes(b"")
    f["empty.json"] = tmp / "empty.json"
    (tmp / "empty.npz").write_bytes(b"")
    f["empty.npz"] = tmp / "empty.npz"
    (tmp / "utf8.json").write_bytes(b'{"hand": "\xff\xfe"}')
    f["utf8.json"] = tmp / "utf8.json"
    (tmp / "list.json").write_text("[1, 2]")
    f["list.json"] = tmp / "list.json"
    np.savez(tmp / "objarr.npz", hand=np.array([None, {}], dtype=object))
    f["objarr.npz"] = tmp / "objarr.npz"
    np.savez(tmp / "nokeys.npz", x=np.zeros(3))
    f["nokeys.npz"] = tmp / "nokeys.npz"
    np.savez(tmp / "badmetrics.npz", **(good.to_arrays() | {"metrics": np.array("{bad")}))
    f["badmetrics.npz"] = tmp / "badmetrics.npz"
    with zipfile.ZipFile(tmp / "notnpy.npz", "w") as z:
        z.writestr("hand.npy", b"this is not an npy array")
    f["notnpy.npz"] = tmp / "notnpy.npz"
    wrong = good.to_dict() | {"joint_names": 5}
    (tmp / "names5.json").write_text(json.dumps(wrong))
    f["names5.json"] = tmp / "names5.json"
    (tmp / "anchors.json").write_text(json.dumps(good.to_dict() | {"anchors": "abc"}))
    f["anchors.json"] = tmp / "anchors.json"
    (tmp / "nested.json").write_text(json.dumps(good.to_dict() | {"wrist_pos": [[0, 0, 0]]}))
    f["nested.json"] = tmp / "nested.json"
    (tmp / "far.json").write_text(json.dumps(good.to_dict() | {"wrist_pos": [1e300, 0, 0]}))
    f["far.json"] = tmp / "far.json"
    (tmp / "dir.json").mkdir(exist_ok=True)
    f["dir.json"] = tmp / "dir.json"
    (tmp / "a_file").write_text("x")
    f["a_file"] = tmp / "a_file"
    # DexGraspBench-layout grasp files for `drograsp validate`
    (tmp / "objects").mkdir(exist_ok=True)
    np.savez(tmp / "rows_missing.npz", grasp_qpos=np.zeros((1, 23)))
    f["rows_missing.npz"] = tmp / "rows_missing.npz"
    # jobs files
    job = {"object": {"category": "mug", "seed": 0}, "instruction": "Use a mug by handle"}
    job |= {"hand": "allegro"}
    for kind, text in {
        "ok": json.dumps(job) + "\n",
        "trunc": json.dumps(job)[:30] + "\n",
        "list": "[1]\n",
        "field": json.dumps(job | {"colour": 1}) + "\n",
        "variant": json.dumps(job | {"variant": "x"}) + "\n",
        "cands": json.dumps(job | {"max_candidates": 1.5}) + "\n",
        "object": json.dumps(job | {"object": "mug"}) + "\n",
        "hand": json.dumps(job | {"hand": 5}) + "\n",
        "utf8": None,
        "dup": (json.dumps(job) + "\n") * 2,
        "seed": json.dumps(job | {"object": {"category": "mug", "seed": 1.5}}) + "\n",
    }.items():
        p = tmp / f"jobs_{kind}.jsonl"
        p.write_bytes(b"\xff\xfe{}\n" if text is None else text.encode())
        f[f"jobs_{kind}"] = p
    return f


# ---------------------------------------------------------------------- expectations
def _is_cloud(min_points: int = 1):
    def check(obj: Any) -> str | None:
        from models.objects import ObjectModel

        if not isinstance(obj, ObjectModel):
            return f"returned {type(obj).__name__}, not an ObjectModel"
        pts = obj.cloud if obj.cloud is not None else obj.mesh.vertices
        if not np.isfinite(pts).all() or len(pts) < min_points:
            return "non-finite or too few points"
        extent = float(np.ptp(pts, axis=0).max())
        if not 0.01 <= extent <= 1.0:
            return f"extent {extent} outside 1 cm .. 1 m"
        return None

    return check


def _exit(*codes: int) -> Callable[[Any], str | None]:
    def check(code: Any) -> str | None:
        return None if code in codes else f"exit code {code}, expected {codes}"

    return check


def _held(expected: bool) -> Callable[[Any], str | None]:
    def check(result: Any) -> str | None:
        if bool(result.success) != expected:
            return f"success {result.success} (reason {result.reason}), expected {expected}"
        return None

    return check


# ---------------------------------------------------------------------- case families
def object_cases(rng: np.random.Generator, scale: int) -> list[Case]:
    from models.objects import load_object

    cases: list[Case] = []

    def add(name, fn, expect, check=None):
        cases.append(Case(name, "objects", fn, expect, check))

    for _ in range(8 * scale):  # good clouds of random size and density
        n = int(rng.integers(64, 3000))
        radius = float(rng.uniform(0.01, 0.3))
        pts = _ball(rng, n, radius)
        add(f"cloud ok n={n} r={radius:.3f}", lambda p=pts: load_object(p), "ok", _is_cloud())
    bad_arrays: list[tuple[str, Any]] = [
        ("ragged list", [[0.0, 0.0, 0.0], [1.0, 2.0]]),
        ("ragged nested", [[[0.0]], [0.0, 1.0, 2.0]]),
        ("strings", np.array([["a", "b", "c"]] * 100)),
        ("string list", [["0.1", "x", "0.2"]] * 100),
        ("dict", {"points": [1, 2, 3]}),
        ("set", {1, 2, 3}),
        ("None", None),
        ("int", 5),
        ("bytes", b"\x00\x01"),
        ("structured", np.zeros(100, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4")])),
        ("object array", np.array([None] * 300, dtype=object).reshape(100, 3)),
        ("complex", _ball(rng, 100, 0.05).astype(complex) * (1 + 1j)),
        ("bool", np.ones((100, 3), dtype=bool)),
        ("empty", np.zeros((0, 3))),
        ("1-D", np.zeros(300)),
        ("4 columns", np.zeros((100, 4))),
        ("3-D", np.zeros((10, 10, 3))),
        ("scalar array", np.array(3.0)),
        ("too few", _ball(rng, 10, 0.05)),
        ("millimetres", _ball(rng, 500, 40.0)),
        ("centimetres", _ball(rng, 500, 4.0)),
        ("tiny", _ball(rng, 500, 0.001)),
        ("huge values", _ball(rng, 500, 1e300)),
        ("flat", np.c_[rng.uniform(-0.05, 0.05, (200, 2)), np.zeros(200)]),
        ("collinear", np.outer(np.linspace(0, 0.1, 200), [1, 2, 3])),
        ("all same point", np.ones((200, 3))),
    ]
    for name, value in bad_arrays:
        add(f"load_object({name})", lambda v=value: load_object(v), "error")
    for name in ("nan", "inf", "-inf"):
        for _ in range(2 * scale):
            pts = _ball(rng, 300, 0.05)
            pts[rng.integers(0, 300, 3), rng.integers(0, 3, 3)] = float(name)
            add(f"load_object({name} points)", lambda p=pts: load_object(p), "error")
    try:
        import torch

        t = torch.tensor(_ball(rng, 300, 0.05), requires_grad=True)
        add("torch requires_grad", lambda: load_object(t), "ok", _is_cloud())
        add("torch float16", lambda: load_object(t.detach().half()), "ok", _is_cloud())
        add("torch int", lambda: load_object(torch.zeros(100, 3, dtype=torch.int64)), "error")
    except ImportError:
        pass
    pts = _ball(rng, 400, 0.05)
    kwargs: list[tuple[str, dict, str]] = [
        ("scale=-1", {"scale": -1}, "error"),
        ("scale=0", {"scale": 0}, "error"),
        ("scale=nan", {"scale": float("nan")}, "error"),
        ("scale=inf", {"scale": float("inf")}, "error"),
        ("scale='2'", {"scale": "2"}, "error"),
        ("scale=True", {"scale": True}, "error"),
        ("scale=[1,2]", {"scale": [1, 2]}, "error"),
        ("scale=2", {"scale": 2}, "ok"),
        ("scale=np.float32", {"scale": np.float32(0.5)}, "ok"),
        ("name=5", {"name": 5}, "error"),
        ("normals wrong shape", {"normals": np.ones((3, 3))}, "error"),
        ("normals nan", {"normals": np.full((400, 3), np.nan)}, "error"),
        ("normals zero", {"normals": np.zeros((400, 3))}, "error"),
        ("normals strings", {"normals": [["a"] * 3] * 400}, "error"),
        ("normals ok", {"normals": pts / np.linalg.norm(pts, axis=1, keepdims=True)}, "ok"),
        ("labels no names", {"labels": np.zeros(400, int)}, "error"),
        ("labels short", {"labels": np.zeros(3, int), "part_names": ["a"]}, "error"),
        ("labels negative", {"labels": -np.ones(400, int), "part_names": ["a"]}, "error"),
        ("labels float", {"labels": np.full(400, 0.5), "part_names": ["a"]}, "error"),
        ("labels strings", {"labels": ["a"] * 400, "part_names": ["a"]}, "error"),
        ("labels too big", {"labels": np.full(400, 3), "part_names": ["a"]}, "error"),
        ("labels ok", {"labels": np.zeros(400, int), "part_names": ["body"]}, "ok"),
        ("part_names str", {"labels": np.zeros(400, int), "part_names": "body"}, "error"),
        ("part_names ints", {"labels": np.zeros(400, int), "part_names": [1]}, "error"),
        ("part_names dup", {"labels": np.zeros(400, int), "part_names": ["a", "a"]}, "error"),
        ("part_names empty name", {"labels": np.zeros(400, int), "part_names": [""]}, "error"),
        ("part_names no labels", {"part_names": ["body"]}, "error"),
        ("viewpoint str", {"viewpoint": "abc"}, "error"),
        ("viewpoint shape", {"viewpoint": [1, 2]}, "error"),
        ("viewpoint nan", {"viewpoint": [np.nan, 0, 0]}, "error"),
        ("viewpoint ok", {"viewpoint": [0, 0, 1.0]}, "ok"),
    ]
    for name, kw, expect in kwargs:
        check = _is_cloud() if expect == "ok" else None
        add(f"load_object(cloud, {name})", lambda kw=kw: load_object(pts, **kw), expect, check)
    return cases


def file_cases(files: dict[str, Path], tmp: Path) -> list[Case]:
    from models.objects import load_object
    from planner.objectref import load_labelled, resolve_object

    cases: list[Case] = []

    def add(name, fn, expect, check=None):
        cases.append(Case(name, "files", fn, expect, check))

    add("box.obj", lambda: load_object(files["box"]), "ok", _is_cloud())
    add("box.obj as Path str", lambda: load_object(str(files["box"])), "ok", _is_cloud())
    add("npy cloud", lambda: load_object(files["cloud.npy"]), "ok", _is_cloud())
    add("open tube", lambda: load_object(files["open"]), "ok", _is_cloud())
    add("open tube pieces", lambda: load_object(files["open"]).collision_pieces(), "ok")

    def coacd(kind: str) -> Any:
        import inspect

        import trimesh

        from models.objects import coacd_pieces

        box = trimesh.creation.box(extents=[0.05, 0.05, 0.05])
        # (the keywords only where the code has them: the fuzz also measures older code)
        known = inspect.signature(coacd_pieces).parameters
        if kind == "flat":  # CoACD aborts the process (exit 134) on it
            mesh = trimesh.Trimesh(box.vertices * [1, 1, 0], box.faces, process=False)
            return coacd_pieces(mesh, use_cache=False)
        mesh = trimesh.Trimesh(box.vertices, box.faces[:-2], process=False)  # never finishes
        return coacd_pieces(mesh, use_cache=False, **({"timeout": 2} if "timeout" in known else {}))

    add("CoACD on a flat mesh (aborts)", lambda: coacd("flat"), "error")
    add("CoACD on an open box (hangs)", lambda: coacd("open"), "error")
    add("box in mm", lambda: load_object(files["box_mm"]), "error")
    add("box mm scale=0.001", lambda: load_object(files["box_mm"], scale=0.001), "ok", _is_cloud())
    add("obj face index past vertices", lambda: load_object(files["box_badface"]), "error")
    add("obj nan vertex", lambda: load_object(files["box_nan"]), "error")
    add("ply face index past vertices", lambda: load_object(files["ply_badface"]), "error")
    for key in sorted(k for k in files if k.startswith(("empty.", "junk."))):
        add(f"load_object({key})", lambda k=key: load_object(files[k]), "error")
    for key in ("pickle.npy", "flat.npy", "text.xyz", "short.xyz", "unknown"):
        add(f"load_object({key})", lambda k=key: load_object(files[k]), "error")
    paths = [
        ("300-character name", str(tmp / ("x" * 300 + ".obj"))),
        ("300-character folder", str(tmp / ("y" * 300) / "a.obj")),
        ("~nosuchuser", "~nosuchuser_drograsp/mesh.obj"),
        ("missing", str(tmp / "missing.obj")),
        ("folder", str(tmp)),
        ("nul byte", str(tmp / "a\x00b.obj")),
        ("empty string", ""),
        ("under a file", str(files["a_file"] / "mesh.obj")),
    ]
    for name, p in paths:
        add(f"load_object({name})", lambda p=p: load_object(p), "error")
    for key in sorted(k for k in files if k.startswith("side_")):
        add(f"sidecar {key}", lambda k=key: load_object(files[k]), "error")
    add("labels ok", lambda: load_labelled(files["box"], files["labels"]), "ok", _is_cloud())
    for key in sorted(k for k in files if k.startswith("labels_")):
        add(f"part labels {key}", lambda k=key: load_labelled(files["box"], files[k]), "error")
    add("part labels missing file", lambda: load_labelled(files["box"], tmp / "no.json"), "error")
    refs: list[tuple[str, Any, str]] = [
        ("{}", {}, "error"),
        ("list", [1], "error"),
        ("category unknown", {"category": "unicorn"}, "error"),
        ("category int", {"category": 5}, "error"),
        ("seed str", {"category": "mug", "seed": "x"}, "error"),
        ("seed float", {"category": "mug", "seed": 1.5}, "error"),
        ("path int", {"path": 5}, "error"),
        ("path missing", {"path": str(tmp / "nope.obj")}, "error"),
        ("labels bad", {"path": str(files["box"]), "part_labels": str(files["labels_json"])}, "error"),
        ("cloud ragged", {"cloud": [[0, 0], [1]]}, "error"),
        ("ok", {"category": "cup", "seed": 2}, "ok"),
        ("path ok", {"path": str(files["box"])}, "ok"),
    ]  # fmt: skip
    for name, ref, expect in refs:
        check = _is_cloud() if expect == "ok" else None
        add(f"resolve_object({name})", lambda r=ref: resolve_object(r), expect, check)
    return cases


def library_cases(rng: np.random.Generator, scale: int) -> list[Case]:
    from models.objects import categories, make_object

    cases: list[Case] = []

    def add(name, fn, expect, check=None):
        cases.append(Case(name, "library", fn, expect, check))

    names = categories()
    for _ in range(3 * scale):
        cat, seed = names[int(rng.integers(len(names)))], int(rng.integers(0, 500))
        add(
            f"make_object({cat}, {seed})",
            lambda c=cat, s=seed: make_object(c, s),
            "ok",
            _is_cloud(),
        )
    add("make_object(np.int64)", lambda: make_object("cup", np.int64(3)), "ok", _is_cloud())
    add("make_object noun", lambda: make_object("spray bottle", 1), "ok", _is_cloud())
    for name, args in [
        ("seed=1.5", ("mug", 1.5)),
        ("seed=-1", ("mug", -1)),
        ("seed='3'", ("mug", "3")),
        ("seed=None", ("mug", None)),
        ("seed=True", ("mug", True)),
        ("seed=nan", ("mug", float("nan"))),
        ("seed=[1]", ("mug", [1])),
        ("category unicorn", ("unicorn", 0)),
        ("category 5", (5, 0)),
        ("category None", (None, 0)),
        ("category ''", ("", 0)),
    ]:
        add(f"make_object({name})", lambda a=args: make_object(*a), "error")
    return cases


def text_cases(rng: np.random.Generator, scale: int) -> list[Case]:
    from models.objects import parse_instruction

    cases: list[Case] = []

    def add(name, fn, expect, check=None):
        cases.append(Case(name, "text", fn, expect, check))

    for text in (
        "Use a mug by handle",
        "hand over the knife by its blade.",
        "LIFT UP A PAN BY HANDLE",
    ):
        add(f"parse({text!r})", lambda t=text: parse_instruction(t), "ok")
    bad: list[Any] = ["", "   ", None, 5, b"Use a mug by handle", ["Use"], "mug handle"]
    bad += ["Eat a mug by handle", "Use a mug", "by by by", "Use a mug by"]
    bad += ["Use " + "a " * 15000 + "mug by handle", "Use a " + "x" * 30000 + " by handle"]
    bad += ["Use a mug by " + "handle " * 5000, "\x00\x01 by \x02"]
    for _ in range(3 * scale):  # random unicode
        chars = rng.integers(32, 0x2FFF, int(rng.integers(1, 80)))
        bad.append("".join(map(chr, chars)))
    for i, text in enumerate(bad):
        label = repr(text)[:40]
        add(
            f"parse#{i} {label}",
            lambda t=text: parse_instruction(t),
            "either" if i >= 15 else "error",
        )
    add(
        "parse strict unknown part",
        lambda: parse_instruction("Use a mug by lid", strict=True),
        "error",
    )
    return cases


def grasp_cases(files: dict[str, Path], tmp: Path) -> list[Case]:
    from models.grasp import Grasp

    cases: list[Case] = []

    def add(name, fn, expect, check=None):
        cases.append(Case(name, "grasps", fn, expect, check))

    z = np.zeros(16)
    add("load json", lambda: Grasp.load(files["grasp.json"]), "ok")
    add("load npz", lambda: Grasp.load(files["grasp.npz"]), "ok")
    for key in (
        "trunc.npz", "trunc.json", "empty.json", "empty.npz", "utf8.json", "list.json",
        "objarr.npz", "nokeys.npz", "badmetrics.npz", "notnpy.npz", "names5.json",
        "anchors.json", "nested.json", "dir.json", "a_file",
    ):  # fmt: skip
        add(f"Grasp.load({key})", lambda k=key: Grasp.load(files[k]), "error")
    add("Grasp.load(missing)", lambda: Grasp.load(tmp / "none.json"), "error")
    add("Grasp.load(300 chars)", lambda: Grasp.load(tmp / ("g" * 300 + ".json")), "error")
    add("Grasp.load(~nosuchuser)", lambda: Grasp.load("~nosuchuser_drograsp/g.json"), "error")
    add("Grasp.load(5)", lambda: Grasp.load(5), "error")
    g = Grasp.load(files["grasp.json"])
    add("save missing folder", lambda: g.save(tmp / "new" / "deeper" / "g.json"), "ok")
    add("save under a file", lambda: g.save(files["a_file"] / "g.json"), "error")
    add("save .txt", lambda: g.save(tmp / "g.txt"), "error")
    add("save 300 chars", lambda: g.save(tmp / ("s" * 300 + ".json")), "error")
    add("save onto folder", lambda: g.save(files["dir.json"]), "error")
    bad_metrics = Grasp("allegro", [0, 0, 0], [1, 0, 0, 0], z, z, z, metrics={"a": object()})
    add("save unjsonable metrics", lambda: bad_metrics.save(tmp / "m.json"), "error")
    np_metrics = Grasp("allegro", [0, 0, 0], [1, 0, 0, 0], z, z, z, metrics={"a": np.ones(2)})
    add("save numpy metrics", lambda: np_metrics.save(tmp / "m2.json"), "ok")
    fields: list[tuple[str, dict]] = [
        ("hand 5", {"hand": 5}),
        ("hand empty", {"hand": ""}),
        ("wrist str", {"wrist_pos": "abc"}),
        ("wrist (1,3)", {"wrist_pos": [[0, 0, 0]]}),
        ("wrist nan", {"wrist_pos": [np.nan, 0, 0]}),
        ("wrist bool", {"wrist_pos": [True, False, True]}),
        ("quat zero", {"wrist_quat": [0, 0, 0, 0]}),
        ("quat 3", {"wrist_quat": [1, 0, 0]}),
        ("q scalar", {"grasp": 5}),
        ("q bool", {"grasp": np.ones(16, bool)}),
        ("q complex", {"grasp": np.ones(16, complex)}),
        ("q ragged", {"grasp": [[0.0], [1.0, 2.0]]}),
        ("q mismatch", {"pregrasp": np.zeros(15)}),
        ("names 5", {"joint_names": 5}),
        ("names short", {"joint_names": ["a"]}),
        ("anchors str", {"anchors": "abc"}),
        ("anchors shape", {"anchors": np.zeros((4, 2))}),
        ("metrics list", {"metrics": [1]}),
        ("instruction 5", {"instruction": 5}),
    ]
    base = {"hand": "allegro", "wrist_pos": [0, 0, 0], "wrist_quat": [1, 0, 0, 0]}
    base |= {"grasp": z, "pregrasp": z, "squeeze": z}
    for name, change in fields:
        add(f"Grasp({name})", lambda c=change: Grasp(**(base | c)), "error")
    add("from_dict unknown", lambda: Grasp.from_dict(base | {"colour": 1}), "error")
    add("from_dict not dict", lambda: Grasp.from_dict([1, 2]), "error")
    add("from_json 5", lambda: Grasp.from_json(5), "error")
    return cases


def validate_cases(files: dict[str, Path]) -> list[Case]:
    from models.grasp import Grasp
    from models.objects import make_object
    from planner.validation import get_protocol, validate

    cases: list[Case] = []

    def add(name, fn, expect, check=None):
        cases.append(Case(name, "validate", fn, expect, check))

    box = [
        np.array([[x, y, z] for x in (-0.03, 0.03) for y in (-0.03, 0.03) for z in (-0.03, 0.03)])
    ]
    z = np.zeros(16)
    far = Grasp("allegro", [0.0, 0.0, 0.3], [1, 0, 0, 0], z, z, z)
    for name, over in [
        ("waypoints=10**9", {"waypoints": 10**9}),
        ("waypoints=0", {"waypoints": 0}),
        ("waypoints=1.5", {"waypoints": 1.5}),
        ("substeps=10**7", {"substeps": 10**7}),
        ("hold_time=inf", {"hold_time": float("inf")}),
        ("hold_time=nan", {"hold_time": float("nan")}),
        ("hold_time=1e9", {"hold_time": 1e9}),
        ("hold_time='2'", {"hold_time": "2"}),
        ("timestep=1e-12", {"timestep": 1e-12}),
        ("timestep=-1", {"timestep": -1.0}),
        ("directions empty", {"directions": ()}),
        ("direction zero", {"directions": ((0.0, 0.0, 0.0),)}),
        ("direction nan", {"directions": ((np.nan, 0.0, 0.0),)}),
        ("direction short", {"directions": ((1.0, 0.0),)}),
        ("directions str", {"directions": "x"}),
        ("friction nan", {"friction": (np.nan, 0.02)}),
        ("friction 1", {"friction": (0.6,)}),
        ("friction negative", {"friction": (-0.6, 0.02)}),
        ("max_translation=-1", {"max_translation": -1.0}),
        ("max_translation=nan", {"max_translation": float("nan")}),
        ("force_scale=inf", {"force_scale": float("inf")}),
        ("condim=5", {"condim": 5}),
        ("condim=True", {"condim": True}),
        ("unknown key", {"colour": 1}),
        ("rest_speed=-1", {"rest_speed": -1.0}),
        ("noslip=-1", {"noslip_iterations": -1}),
        ("check_interval=1e-9", {"check_interval": 1e-9}),
    ]:
        add(f"get_protocol({name})", lambda o=over: get_protocol("dexgraspbench", **o), "error")
    add("get_protocol(unknown)", lambda: get_protocol("nosuch"), "error")
    add("get_protocol(5)", lambda: get_protocol(5), "error")
    add("get_protocol ok", lambda: get_protocol("paper", hold_time=1.0), "ok")
    for name, kwargs in [
        ("object_pose='abc'", {"object_pose": "abc"}),
        ("object_pose nan", {"object_pose": [np.nan] * 7}),
        ("object_pose 6", {"object_pose": [0] * 6}),
        ("object_pose zero quat", {"object_pose": [0] * 7}),
        ("protocol unknown", {"protocol": "nosuch"}),
        ("protocol 5", {"protocol": 5}),
        ("all_directions str", {"all_directions": "yes"}),
    ]:
        add(f"validate({name})", lambda k=kwargs: validate(far, box, "allegro", **k), "error")
    add("validate(grasp dict)", lambda: validate(far.to_dict(), box, "allegro"), "error")
    add("validate(grasp None)", lambda: validate(None, box, "allegro"), "error")
    add("validate(hand unicorn)", lambda: validate(far, box, "unicorn"), "error")
    add("validate(hand 5)", lambda: validate(far, box, 5), "error")
    add("validate(hand None)", lambda: validate(far, box, None), "error")
    add("validate(hand leap: dof)", lambda: validate(Grasp("leap", [0, 0, 0], [1, 0, 0, 0], z[:3], z[:3], z[:3]), box, "leap"), "error")  # fmt: skip
    add("validate(obj None)", lambda: validate(far, None, "allegro"), "error")
    add("validate(obj [])", lambda: validate(far, [], "allegro"), "error")
    add(
        "validate(obj 'nosuchdir')", lambda: validate(far, "/nonexistent_dir_x", "allegro"), "error"
    )
    add("validate(obj (3,3))", lambda: validate(far, np.zeros((3, 3)), "allegro"), "error")
    add("validate(obj str array)", lambda: validate(far, [np.array([["a"] * 3] * 8)], "allegro"), "error")  # fmt: skip
    add("validate(obj nan piece)", lambda: validate(far, [np.full((8, 3), np.nan)], "allegro"), "error")  # fmt: skip
    add("validate(obj flat piece)", lambda: validate(far, [np.c_[np.eye(3), np.zeros(3)][:, :3].repeat(3, 0) * 0 + np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]] * 3) * 0.05], "allegro"), "either")  # fmt: skip
    # wrist far away: the object is not in the hand, whatever MuJoCo does with the huge value
    for dist in (1e300, 1e30, 1e9, 10.0):
        g = Grasp("allegro", [dist, 0.0, 0.0], [1, 0, 0, 0], z, z, z)
        add(f"validate(wrist {dist:g} m away)", lambda g=g: validate(g, box, "allegro"), "either", lambda r: None if not r.success else f"held ({r.reason})")  # fmt: skip
    add("validate(far.json, wrist 1e300)", lambda: validate(Grasp.load(files["far.json"]), box, "allegro"), "either", lambda r: None if not r.success else "held")  # fmt: skip
    add("validate(no contact)", lambda: validate(far, box, "allegro"), "ok", _held(False))
    add("validate(library object)", lambda: validate(far, make_object("cup", 1), "allegro"), "ok", _held(False))  # fmt: skip
    return cases


def plan_cases() -> list[Case]:
    from models.objects import make_object
    from planner import plan_grasp
    from planner.functional import PlannerSettings
    from planner.settings import GROUPS as SETTINGS_GROUPS

    cases: list[Case] = []

    def add(name, fn, expect, check=None):
        cases.append(Case(name, "plan", fn, expect, check))

    obj = make_object("bottle", 1)
    # (group of PlannerSettings or None for its top level, bad field values)
    settings: list[tuple[str | None, dict]] = [
        ("proposals", {"approach_step_deg": 0}),
        ("proposals", {"approach_step_deg": -45.0}),
        ("proposals", {"approach_step_deg": float("nan")}),
        ("proposals", {"approach_step_deg": 1e-9}),
        ("schedule", {"max_candidates": 0}),
        ("schedule", {"max_candidates": 1.5}),
        ("proposals", {"max_proposals": 0}),
        ("proposals", {"max_proposals": -1}),
        ("schedule", {"solve_batch": 0}),
        (None, {"protocol": "nosuch"}),
        (None, {"protocol": 5}),
        ("proposals", {"span_factor": float("nan")}),
        ("schedule", {"contact_distance": -1.0}),
        ("proposals", {"border_margin": float("inf")}),
        ("schedule", {"gate_solves": -1}),
        ("schedule", {"sweep_after": -1}),
        ("schedule", {"min_quality": float("nan")}),
        ("proposals", {"use_palm": "no"}),
        ("proposals", {"approach_clearance": -1.0}),
    ]

    def nested(group: str | None, kw: dict) -> PlannerSettings:
        return PlannerSettings(**kw) if group is None else PlannerSettings(**{group: SETTINGS_GROUPS[group](**kw)})  # fmt: skip

    for group, kw in settings:
        ((field, value),) = kw.items()
        name = f"{field}={value!r}" if group is None else f"{group}.{field}={value!r}"
        add(f"plan_grasp(settings {name})", lambda group=group, kw=kw: plan_grasp(obj, "Hold a bottle by body", "allegro", nested(group, kw)), "error")  # fmt: skip
    add("plan_grasp(settings dict)", lambda: plan_grasp(obj, "Hold a bottle by body", "allegro", {"a": 1}), "error")  # fmt: skip
    add("plan_grasp(hand unicorn)", lambda: plan_grasp(obj, "Hold a bottle by body", "unicorn"), "error")  # fmt: skip
    add("plan_grasp(hand 5)", lambda: plan_grasp(obj, "Hold a bottle by body", 5), "error")
    add("plan_grasp(text '')", lambda: plan_grasp(obj, "", "allegro"), "error")
    add("plan_grasp(text 5)", lambda: plan_grasp(obj, 5, "allegro"), "error")
    add("plan_grasp(part lid)", lambda: plan_grasp(obj, "Hold a bottle by lid", "allegro"), "error")
    add("plan_grasp(obj ragged)", lambda: plan_grasp([[0, 0], [1]], "Hold a bottle by body", "allegro"), "error")  # fmt: skip
    add("plan_grasp(obj None)", lambda: plan_grasp(None, "Hold a bottle by body", "allegro"), "error")  # fmt: skip
    add("plan_grasp(unlabelled cloud)", lambda: plan_grasp(_ball(np.random.default_rng(0), 500, 0.04), "Hold a bottle by body", "allegro"), "error")  # fmt: skip
    return cases


def jobs_cases(files: dict[str, Path], tmp: Path) -> list[Case]:
    from planner.batch import Job, make_jobs, read_jobs, read_results, run_batch

    cases: list[Case] = []

    def add(name, fn, expect, check=None):
        cases.append(Case(name, "jobs", fn, expect, check))

    add("read_jobs ok", lambda: read_jobs(files["jobs_ok"]), "ok")
    for key in sorted(k for k in files if k.startswith("jobs_") and k != "jobs_ok"):
        add(f"read_jobs({key})", lambda k=key: read_jobs(files[k]), "error")
    add("read_jobs(folder)", lambda: read_jobs(tmp), "error")
    add("make_jobs(hands unicorn)", lambda: make_jobs(hands=["unicorn"], objects_per_category=1), "error")  # fmt: skip
    add("make_jobs(hands str)", lambda: make_jobs(hands="allegro", objects_per_category=1), "error")  # fmt: skip
    add("make_jobs(categories unicorn)", lambda: make_jobs(category_names=["unicorn"]), "error")
    add("make_jobs(objects 0)", lambda: make_jobs(objects_per_category=0), "error")
    add("make_jobs(start -1)", lambda: make_jobs(start_seed=-1, hands=["leap"]), "error")
    add("make_jobs(splits str)", lambda: make_jobs(splits="train", hands=["leap"]), "error")
    add("make_jobs ok", lambda: make_jobs(hands=["leap"], category_names=["mug"], objects_per_category=1, splits=["train"]), "ok")  # fmt: skip
    for name, kw in [
        ("variant str", {"variant": "x"}),
        ("variant bool", {"variant": True}),
        ("candidates 1.5", {"max_candidates": 1.5}),
        ("hand 5", {"hand": 5}),
        ("instruction list", {"instruction": ["x"]}),
        ("protocol 5", {"protocol": 5}),
        ("source list", {"source": [1]}),
        ("id 5", {"id": 5}),
        ("object seed str", {"object": {"category": "mug", "seed": "a"}}),
    ]:
        base = {"object": {"category": "mug", "seed": 0}, "instruction": "Use a mug by handle"}
        base |= {"hand": "allegro"}
        add(f"Job({name})", lambda kw=kw, b=base: Job(**(b | kw)), "error")
    # a damaged batch folder is named, with how to recover
    from tests.batch_fakes import fake_jobs, fake_solve

    jobs = fake_jobs(4)

    def damaged(kind: str):
        out = tmp / f"batch_{kind}"
        run_batch(jobs, out, shard_size=2, job_fn=fake_solve, progress=False)
        if kind == "shard":
            shard = out / "shards" / "shard-000000.jsonl"
            shard.write_text(shard.read_text()[:-40])
        elif kind == "meta":
            meta = out / "batch.json"
            meta.write_text(meta.read_text()[:10])
        elif kind == "meta_list":
            (out / "batch.json").write_text("[1]")
        elif kind == "shard_utf8":
            (out / "shards" / "shard-000001.jsonl").write_bytes(b"\xff\xfe\n")
        return out

    for kind in ("shard", "meta", "meta_list", "shard_utf8"):

        def run(kind=kind):
            out = damaged(kind)
            return run_batch(jobs, out, shard_size=2, job_fn=fake_solve, progress=False)

        def read(kind=kind):
            return list(read_results(damaged(kind)))

        name = "batch.json" if kind.startswith("meta") else "shard-00000"
        cases.append(Case(f"run_batch(damaged {kind})", "jobs", run, "error", match=name))
        if kind.startswith("shard"):
            cases.append(Case(f"read_results(damaged {kind})", "jobs", read, "error", match=name))
    add("run_batch(workers 0)", lambda: run_batch(jobs, tmp / "w0", workers=0, job_fn=fake_solve, progress=False), "error")  # fmt: skip
    add("run_batch(out under a file)", lambda: run_batch(jobs, files["a_file"] / "x", job_fn=fake_solve, progress=False), "error")  # fmt: skip
    return cases


def cli_cases(files: dict[str, Path], tmp: Path) -> list[Case]:
    cases: list[Case] = []

    def add(name, argv, expect_codes):
        cases.append(
            Case(f"drograsp {name}", "cli", lambda a=argv: _cli(a), "ok", _exit(*expect_codes))
        )

    out = tmp / "cli"
    box, grasp = str(files["box"]), str(files["grasp.json"])
    under_file = str(files["a_file"] / "sub" / "g.json")
    plan = ["plan", "--object", "bottle", "--seed", "1", "--text", "Hold a bottle by body"]
    add("(no command)", [], (2,))
    add("--help", ["--help"], (0,))
    add("nosuch", ["nosuch"], (2,))
    add("plan --help", ["plan", "--help"], (0,))
    add("plan (no args)", ["plan"], (2,))
    add("plan --out under a file", plan + ["--hand", "allegro", "--out", under_file], (2,))
    add("plan --out .txt", plan + ["--hand", "allegro", "--out", str(out / "g.txt")], (2,))
    add("plan --out folder", plan + ["--hand", "allegro", "--out", str(tmp)], (2,))
    add("plan --candidates 0", plan + ["--candidates", "0"], (2,))
    add("plan --candidates -3", plan + ["--candidates", "-3"], (2,))
    add("plan --candidates x", plan + ["--candidates", "x"], (2,))
    add("plan --seed -1", ["plan", "--object", "mug", "--seed", "-1", "--text", "Use a mug by handle"], (2,))  # fmt: skip
    add("plan --object unicorn", ["plan", "--object", "unicorn", "--text", "x"], (2,))
    add("plan --hand unicorn", plan + ["--hand", "unicorn"], (2,))
    add("plan --preset nosuch", plan + ["--preset", "nosuch"], (2,))
    add("plan --text ''", ["plan", "--object", "mug", "--text", ""], (2,))
    add("plan --text 30k", ["plan", "--object", "mug", "--text", "Use a " + "x" * 30000 + " by handle"], (2,))  # fmt: skip
    add("plan --text no part", ["plan", "--object", "mug", "--text", "Use a mug by lid"], (2,))
    add("plan --mesh missing", ["plan", "--mesh", str(tmp / "none.obj"), "--text", "Use a mug by handle"], (2,))  # fmt: skip
    add("plan --mesh junk", ["plan", "--mesh", str(files["junk.obj"]), "--text", "Use a x by body"], (2,))  # fmt: skip
    add("plan --mesh unlabelled --proposer model", ["plan", "--mesh", box, "--text", "Use a box by body", "--proposer", "model"], (2,))  # fmt: skip
    add("plan --mesh unlabelled (learned)", ["plan", "--mesh", box, "--text", "hold the box", "--hand", "allegro", "--samples", "2", "--candidates", "1"], (0, 1))  # fmt: skip
    add("plan --samples 0", ["plan", "--mesh", box, "--text", "hold the box", "--samples", "0"], (2,))  # fmt: skip
    add("plan --mesh bad labels", ["plan", "--mesh", box, "--part-labels", str(files["labels_json"]), "--text", "Use a box by body"], (2,))  # fmt: skip
    add("plan --part-labels without --mesh", plan + ["--part-labels", str(files["labels"])], (2,))
    add("plan --mesh open tube with labels", ["plan", "--mesh", str(files["open"]), "--part-labels", str(files["open_labels"]), "--text", "Hold a tube by body", "--hand", "allegro", "--candidates", "1"], (0, 1))  # fmt: skip
    add("plan --mesh 300 chars", ["plan", "--mesh", str(tmp / ("x" * 300 + ".obj")), "--text", "Use a mug by handle"], (2,))  # fmt: skip
    add("view missing", ["view", str(tmp / "none.json")], (2,))
    add("view truncated npz", ["view", str(files["trunc.npz"])], (2,))
    add("view empty", ["view", str(files["empty.json"])], (2,))
    add("view utf8", ["view", str(files["utf8.json"])], (2,))
    add("view no object", ["view", grasp, "--html", str(out / "v.html")], (2,))
    add("view --html .png", ["view", grasp, "--object", "mug", "--html", str(out / "v.png")], (2,))
    add("view --html under a file", ["view", grasp, "--object", "mug", "--html", under_file + ".html"], (2,))  # fmt: skip
    add("view --seconds -1", ["view", grasp, "--object", "mug", "--seconds", "-1"], (2,))
    add("validate missing", ["validate", str(tmp / "none.npz"), "--hand", "allegro", "--objects", str(tmp)], (2,))  # fmt: skip
    add("validate junk", ["validate", str(files["junk.npy"]), "--hand", "allegro", "--objects", str(tmp)], (2,))  # fmt: skip
    add("validate truncated", ["validate", str(files["trunc.npz"]), "--hand", "allegro", "--objects", str(tmp)], (2,))  # fmt: skip
    add("validate missing keys", ["validate", str(files["rows_missing.npz"]), "--hand", "allegro", "--objects", str(tmp)], (2,))  # fmt: skip
    add("validate --out .npz", ["validate", str(files["rows_missing.npz"]), "--hand", "allegro", "--objects", str(tmp), "--out", str(out / "r.npz")], (2,))  # fmt: skip
    add("validate --out under a file", ["validate", str(files["rows_missing.npz"]), "--hand", "allegro", "--objects", str(tmp), "--out", under_file], (2,))  # fmt: skip
    add("validate --set bad", ["validate", str(files["rows_missing.npz"]), "--hand", "allegro", "--objects", str(tmp), "--set", "hold_time=inf"], (2,))  # fmt: skip
    add("validate --set noeq", ["validate", str(files["rows_missing.npz"]), "--hand", "allegro", "--objects", str(tmp), "--set", "hold_time"], (2,))  # fmt: skip
    add("validate --set waypoints", ["validate", str(files["rows_missing.npz"]), "--hand", "allegro", "--objects", str(tmp), "--set", "waypoints=1000000000"], (2,))  # fmt: skip
    add("validate --workers 0", ["validate", str(files["rows_missing.npz"]), "--hand", "allegro", "--objects", str(tmp), "--workers", "0"], (2,))  # fmt: skip
    add("validate --limit -1", ["validate", str(files["rows_missing.npz"]), "--hand", "allegro", "--objects", str(tmp), "--limit", "-1"], (2,))  # fmt: skip
    add("validate --hand-xml missing", ["validate", str(files["rows_missing.npz"]), "--hand-xml", str(tmp / "none.xml"), "--objects", str(tmp)], (2,))  # fmt: skip
    add("validate --hand-xml junk", ["validate", str(files["rows_missing.npz"]), "--hand-xml", str(files["junk.obj"]), "--objects", str(tmp)], (2,))  # fmt: skip
    add("validate --joint-map junk", ["validate", str(files["rows_missing.npz"]), "--hand-xml", str(files["junk.obj"]), "--joint-map", str(files["junk.obj"]), "--objects", str(tmp)], (2,))  # fmt: skip
    add("objects", ["objects"], (0,))
    add("objects export unicorn", ["objects", "export", "unicorn", str(out / "u.obj")], (2,))
    add("objects export under a file", ["objects", "export", "mug", under_file + ".obj"], (2,))
    add("objects export .stl", ["objects", "export", "mug", str(out / "m.stl")], (2,))
    add("objects export --seed -1", ["objects", "export", "mug", str(out / "m.obj"), "--seed", "-1"], (2,))  # fmt: skip
    add("objects sheet .xyz", ["objects", "sheet", str(out / "s.xyz")], (2,))
    add("objects sheet under a file", ["objects", "sheet", under_file + ".png"], (2,))
    add("objects label missing", ["objects", "label", str(tmp / "none.obj"), str(out / "l.json")], (2,))  # fmt: skip
    add("objects label .txt", ["objects", "label", box, str(out / "l.txt")], (2,))
    add("objects label ok", ["objects", "label", box, str(out / "l.json")], (0,))
    add("objects label bad --labels", ["objects", "label", box, str(out / "l2.json"), "--labels", str(files["labels_json"])], (2,))  # fmt: skip
    add("jobs make --hands unicorn", ["jobs", "make", str(out / "j.jsonl"), "--hands", "unicorn"], (2,))  # fmt: skip
    add("jobs make --variants 0", ["jobs", "make", str(out / "j.jsonl"), "--variants", "0"], (2,))
    add("jobs make --objects-per-category -1", ["jobs", "make", str(out / "j.jsonl"), "--objects-per-category", "-1"], (2,))  # fmt: skip
    add("jobs make under a file", ["jobs", "make", under_file + ".jsonl", "--hands", "leap"], (2,))
    add("jobs make .txt", ["jobs", "make", str(out / "j.txt"), "--hands", "leap"], (2,))
    add("jobs transfer missing", ["jobs", "transfer", str(tmp / "nobatch"), str(out / "t.jsonl")], (2,))  # fmt: skip
    add("batch missing jobs", ["batch", str(tmp / "none.jsonl"), str(out / "b")], (2,))
    add("batch truncated jobs", ["batch", str(files["jobs_trunc"]), str(out / "b")], (2,))
    add("batch utf8 jobs", ["batch", str(files["jobs_utf8"]), str(out / "b")], (2,))
    add("batch bad variant", ["batch", str(files["jobs_variant"]), str(out / "b")], (2,))
    add("batch --workers 0", ["batch", str(files["jobs_ok"]), str(out / "b"), "--workers", "0"], (2,))  # fmt: skip
    add("batch --shard-size 0", ["batch", str(files["jobs_ok"]), str(out / "b"), "--shard-size", "0"], (2,))  # fmt: skip
    add("batch --job-fn bad", ["batch", str(files["jobs_ok"]), str(out / "b"), "--job-fn", "nosuch.module:f"], (2,))  # fmt: skip
    add("batch --job-fn noattr", ["batch", str(files["jobs_ok"]), str(out / "b"), "--job-fn", "os"], (2,))  # fmt: skip
    add("batch out under a file", ["batch", str(files["jobs_ok"]), under_file], (2,))
    add("dataset info missing", ["dataset", "info", str(tmp / "nodata")], (2,))
    add("dataset info file", ["dataset", "info", str(files["a_file"])], (2,))
    add("dataset compact missing", ["dataset", "compact", str(tmp / "nobatch"), "--out", str(out / "d")], (2,))  # fmt: skip
    add("dataset refresh missing", ["dataset", "refresh", str(tmp / "nodata"), "--categories", "mug"], (2,))  # fmt: skip
    add("dataset generate --workers 0", ["dataset", "generate", str(out / "g"), "--workers", "0"], (2,))  # fmt: skip
    add("demo --out under a file", ["demo", "--out", under_file], (2,))
    add("demo --hands unicorn", ["demo", "--hands", "unicorn", "--out", str(out / "demo")], (2,))
    add("hands unicorn", ["hands", "unicorn"], (2,))
    add("export missing grasp", ["export", "dexgraspbench", str(out / "e"), str(tmp / "none.json"), "--hand-xml", str(tmp / "none.xml")], (2,))  # fmt: skip
    return cases


def _cli(argv: list[str]) -> int:
    """`drograsp ARGV` in this process: its exit code. An exception escaping `main` is what a
    user sees as a traceback."""
    from planner.cli import main

    sink = io.StringIO()
    with contextlib.redirect_stdout(sink), contextlib.redirect_stderr(sink):
        try:
            return int(main(argv))
        except SystemExit as exc:  # argparse: usage errors and --help
            return int(exc.code or 0) if not isinstance(exc.code, str) else 2


def _hand_variants(meta: dict, urdf: str) -> list[tuple[str, str, Any, Any]]:
    """(name, file the error must name, hand.json, URDF) for malformed hand folders: hand.json
    fields of every wrong kind, URDF elements and attributes, and hands that only MuJoCo or
    Drake would refuse. hand.json as a dict is dumped (NaN included); bytes are written as
    they are."""
    import copy
    import re

    def with_meta(**changes) -> dict:
        return copy.deepcopy(meta) | changes

    def edit(path: tuple, value=None, delete: bool = False) -> dict:
        out = copy.deepcopy(meta)
        node = out
        for key in path[:-1]:
            node = node[key]
        if delete:
            del node[path[-1]]
        else:
            node[path[-1]] = value
        return out

    j0 = meta["joint_order"][0]
    nan, inf = float("nan"), float("inf")
    m: list[tuple[str, Any]] = [
        ("open_pose 5", with_meta(open_pose=5)),
        ("open_pose text value", edit(("open_pose", j0), "0")),
        ("open_pose NaN", edit(("open_pose", j0), nan)),
        ("open_pose lacks a joint", edit(("open_pose", j0), delete=True)),
        ("open_pose outside limits", edit(("open_pose", j0), 5.0)),
        ("urdf null", with_meta(urdf=None)),
        ("urdf 5", with_meta(urdf=5)),
        ("urdf missing file", with_meta(urdf="nope.urdf")),
        ("urdf empty", with_meta(urdf="")),
        ("urdf NUL", with_meta(urdf="hand\x00.urdf")),
        ("name 5", with_meta(name=5)),
        ("utf8", b"\xff\xfe{"),
        ("empty json", ""),
        ("not json", "{name: allegro"),
        ("list json", "[]"),
        ("string json", '"allegro"'),
        ("deep json", "[" * 100000),
        ("fingertip without link", edit(("fingertips", 0, "link"), delete=True)),
        ("fingertips 5", with_meta(fingertips=5)),
        ("fingertips names", with_meta(fingertips=["th", "ff"])),
        ("fingertips empty", with_meta(fingertips=[])),
        ("fingertip point 2", edit(("fingertips", 0, "point"), [0, 0])),
        ("fingertip point NaN", edit(("fingertips", 0, "point"), [0, nan, 0])),
        ("fingertip point text", edit(("fingertips", 0, "point"), "0 0 0")),
        ("fingertip radius -1", edit(("fingertips", 0, "radius"), -1)),
        ("fingertip radius text", edit(("fingertips", 0, "radius"), "0.01")),
        ("fingertip radius NaN", edit(("fingertips", 0, "radius"), nan)),
        ("fingertip link 5", edit(("fingertips", 0, "link"), 5)),
        ("fingertip link unknown", edit(("fingertips", 0, "link"), "nolink")),
        ("fingertip name list", edit(("fingertips", 0, "name"), ["th"])),
        ("fingertip twice", edit(("fingertips", 1, "name"), meta["fingertips"][0]["name"])),
        ("fingertip unknown key", edit(("fingertips", 0, "colour"), "red")),
        ("anchor_fingers 5", with_meta(anchor_fingers=5)),
        ("anchor_fingers text", with_meta(anchor_fingers="thffmfrf")),
        ("anchor_fingers nested", with_meta(anchor_fingers=[["th"], "ff", "mf", "rf"])),
        ("anchor_fingers 3", with_meta(anchor_fingers=meta["anchor_fingers"][:3])),
        ("anchor_fingers repeated", with_meta(anchor_fingers=["th", "th", "ff", "mf"])),
        ("anchor_fingers unknown", with_meta(anchor_fingers=["th", "ff", "mf", "xx"])),
        ("closing_direction 5", with_meta(closing_direction=5)),
        ("closing_direction 2", edit(("closing_direction", j0), 2)),
        ("closing_direction text", edit(("closing_direction", j0), "1")),
        ("closing_direction true", edit(("closing_direction", j0), True)),
        ("closing_direction 0.5", edit(("closing_direction", j0), 0.5)),
        ("closing_direction lacks", edit(("closing_direction", j0), delete=True)),
        ("palm 5", with_meta(palm=5)),
        ("palm list", with_meta(palm=[1, 0, 0])),
        ("palm normal zero", edit(("palm", "normal"), [0, 0, 0])),
        ("palm normal text", edit(("palm", "normal"), "up")),
        ("palm center NaN", edit(("palm", "center"), [nan, 0, 0])),
        ("palm axes parallel", edit(("palm", "finger_axis"), meta["palm"]["normal"])),
        ("palm lacks normal", edit(("palm", "normal"), delete=True)),
        ("palm unknown key", edit(("palm", "up"), [0, 0, 1])),
        ("actuator 5", with_meta(actuator=5)),
        ("actuator kp NaN", edit(("actuator", "kp"), nan)),
        ("actuator kp -1", edit(("actuator", "kp"), -1)),
        ("actuator kp text", edit(("actuator", "kp"), "5")),
        ("actuator kp 0", edit(("actuator", "kp"), 0)),
        ("actuator kv -1", edit(("actuator", "kv"), -1)),
        ("actuator force_range inf", edit(("actuator", "force_range"), inf)),
        ("actuator kd", edit(("actuator", "kd"), 1.0)),
        ("actuator lacks kp", edit(("actuator", "kp"), delete=True)),
        ("joint_order 5", with_meta(joint_order=5)),
        ("joint_order repeated", with_meta(joint_order=[j0] + meta["joint_order"])),
        ("joint_order empty", with_meta(joint_order=[])),
        ("joint_order unknown", with_meta(joint_order=meta["joint_order"][:-1] + ["nojoint"])),
        ("joint_order numbers", with_meta(joint_order=list(range(16)))),
        ("ignore pairs text", with_meta(ignore_collision_pairs="palm")),
        ("ignore pairs single", with_meta(ignore_collision_pairs=[["palm"]])),
        ("ignore pairs numbers", with_meta(ignore_collision_pairs=[[1, 2]])),
        ("ignore pairs unknown", with_meta(ignore_collision_pairs=[["palm", "nolink"]])),
        ("ignore pairs itself", with_meta(ignore_collision_pairs=[["palm", "palm"]])),
        ("joint_dynamics 5", with_meta(joint_dynamics=5)),
        ("joint_dynamics damping -1", edit(("joint_dynamics", "damping"), -1)),
        ("joint_dynamics damping NaN", edit(("joint_dynamics", "damping"), nan)),
        ("joint_dynamics stiffness", edit(("joint_dynamics", "stiffness"), 1.0)),
        ("palm_on_thin_parts text", with_meta(palm_on_thin_parts="false")),
        ("program_hull_links 5", with_meta(program_hull_links=5)),
        ("program_hull_links one box", with_meta(program_hull_links=["ff_distal"])),
        ("source 5", with_meta(source=5)),
        ("unknown field", with_meta(pinch_proposal=3)),
        ("couplings text", with_meta(couplings="x")),
        (
            "couplings name 5",
            with_meta(
                couplings=[{"name": 5, "joints": meta["joint_order"][1:3], "tendon": [1, 1]}]
            ),
        ),
        ("pregrasp_clearance NaN", with_meta(pregrasp_clearance=nan)),
        ("retry_squeeze_depths text", with_meta(retry_squeeze_depths="3")),
        ("pinch_proposals 2.5", with_meta(pinch_proposals=2.5)),
        ("learned_start_closure -0.1", with_meta(learned_start_closure=-0.1)),
    ]
    out = [(name, "hand.json", m_, urdf) for name, m_ in m]

    def first(pattern: str, repl: str) -> str:
        changed, n = re.subn(pattern, repl, urdf, count=1)
        assert n == 1, pattern
        return changed

    def scaled(match: re.Match) -> str:
        values = " ".join(str(float(v) * 1000) for v in match.group(2).split())
        return f'{match.group(1)}="{values}"'

    link = re.search(r"<link name=.*?</link>", urdf, re.S).group(0)
    joint = re.search(r'<joint name=.*?type="revolute".*?</joint>', urdf, re.S).group(0)
    u: list[tuple[str, str]] = [
        ("no axis", first(r"<axis [^>]*/>", "")),
        ("axis without xyz", first(r"<axis xyz=", "<axis xzy=")),
        ("zero axis", first(r'<axis xyz="[^"]*"', '<axis xyz="0 0 0"')),
        ("NaN axis", first(r'<axis xyz="[^"]*"', '<axis xyz="nan 0 1"')),
        ("axis 2 values", first(r'<axis xyz="[^"]*"', '<axis xyz="0 1"')),
        ("no child", first(r"<child ", "<nochild ")),
        ("no parent", first(r"<parent ", "<noparent ")),
        ("child unknown link", first(r'<child link="[^"]*"', '<child link="nolink"')),
        ("limit text", first(r'lower="', 'lower="x')),
        ("upper text", first(r'upper="', 'upper="y')),
        ("lower above upper", first(r'lower="[^"]*" upper="[^"]*"', 'lower="1" upper="-1"')),
        ("no limit", first(r"<limit [^>]*/>", "")),
        ("limit without lower", first(r'lower="[^"]*"', "")),
        ("NaN mass", first(r'<mass value="', '<mass value="nan')),
        ("mass text", first(r'<mass value="[^"]*"', '<mass value="heavy"')),
        ("negative mass", first(r'<mass value="', '<mass value="-')),
        ("zero mass", re.sub(r'<mass value="[^"]*"', '<mass value="0"', urdf)),
        ("no mass", first(r'<mass value="[^"]*"/>', "")),
        ("NaN inertia", first(r'ixx="', 'ixx="nan')),
        ("negative inertia", first(r'ixx="', 'ixx="-')),
        (
            "inertia not physical",
            re.sub(
                r'ixx="[^"]*"(.*?)iyy="[^"]*"(.*?)izz="[^"]*"',
                r'ixx="1e-9"\1iyy="1e-9"\2izz="1"',
                urdf,
                count=2,
            ),
        ),
        ("duplicate link", urdf.replace(link, link + link, 1)),
        (
            "duplicate joint name",
            first(r'<joint name="[^"]*"', f'<joint name="{meta["joint_order"][1]}"'),
        ),
        ("link without name", first(r'<link name="[^"]*"', "<link")),
        ("joint without name", first(r'<joint name="[^"]*"', "<joint")),
        ("joint without type", first(r'type="revolute"', "")),
        ("planar joint", first(r'type="revolute"', 'type="planar"')),
        (
            "mimic",
            urdf.replace(joint, joint.replace("</joint>", '<mimic joint="x"/></joint>'), 1),
        ),
        ("box size NaN", first(r'<box size="', '<box size="nan ')),
        ("box size 2", first(r'<box size="[^"]*"', '<box size="0.01 0.01"')),
        ("box size negative", first(r'<box size="[^"]*"', '<box size="0.01 -0.01 0.01"')),
        ("box size zero", first(r'<box size="[^"]*"', '<box size="0.01 0 0.01"')),
        (
            "collision box NaN",
            first(r'(<collision[^>]*>.*?)<box size="[^"]*"', r'\1<box size="0.01 nan 0.01"'),
        ),
        (
            "collision box negative",
            first(r'(<collision[^>]*>.*?)<box size="[^"]*"', r'\1<box size="-0.01 0.01 0.01"'),
        ),
        (
            "visual mesh scale",
            first(
                r"<visual>",
                '<visual><geometry><mesh filename="x.obj" scale="1 -1 1"/></geometry></visual><visual>',
            ),
        ),
        ("limit effort NaN", first(r'effort="[^"]*"', 'effort="nan"')),
        ("capsule radius text", first(r'<capsule radius="[^"]*"', '<capsule radius="r"')),
        ("capsule no length", first(r'(<capsule radius="[^"]*") length="[^"]*"', r"\1")),
        (
            "sphere NaN",
            first(
                r'<collision([^>]*)>(.*?)<box size="[^"]*"/>',
                r'<collision\1>\2<sphere radius="nan"/>',
            ),
        ),
        (
            "cone geometry",
            first(
                r'<collision([^>]*)>(.*?)<box size="[^"]*"/>', r'<collision\1>\2<cone radius="1"/>'
            ),
        ),
        (
            "collision without geometry",
            first(r"<collision([^>]*)>.*?</collision>", r"<collision\1></collision>"),
        ),
        (
            "no collision geometry",
            re.sub(r"<collision[^>]*>.*?</collision>", "", urdf, flags=re.S),
        ),
        ("origin xyz text", first(r'<origin xyz="[^"]*"', '<origin xyz="a b c"')),
        ("origin rpy 2", first(r'rpy="[^"]*"', 'rpy="0 0"')),
        ("millimetres", re.sub(r'(xyz|size|radius|length)="([^"]*)"', scaled, urdf)),
        (
            "visual mesh missing",
            first(
                r"<visual>",
                '<visual><geometry><mesh filename="missing.obj"/></geometry></visual><visual>',
            ),
        ),
        (
            "collision mesh package",
            first(r'<box size="[^"]*"/>', '<mesh filename="package://hand/x.obj"/>'),
        ),
        ("two roots", urdf.replace(joint, "", 1)),
        ("empty urdf", ""),
        ("not xml", "this is not a URDF"),
        ("root not robot", urdf.replace("<robot", "<robots", 1).replace("</robot>", "</robots>")),
        ("no links", '<robot name="x"/>'),
    ]
    out += [(name, "hand.urdf", meta, text) for name, text in u]
    return out


def hand_cases(tmp: Path) -> list[Case]:
    """Malformed hand folders (every kind of hand.json and URDF fault, hands MuJoCo or Drake
    would refuse), valid user hands, and the hand API's joint vectors and wrists."""
    import torch
    from scipy.spatial.transform import Rotation

    from models.hands import load_hand

    cases: list[Case] = []
    hands = REPO / "models" / "hands"
    src = hands / "allegro"
    meta = json.loads((src / "hand.json").read_text())
    urdf = (src / "hand.urdf").read_text()

    def folder(name: str, meta_value: Any, urdf_text: str | bytes) -> Path:
        d = tmp / "hands" / "".join(c if c.isalnum() else "_" for c in name)
        d.mkdir(parents=True, exist_ok=True)
        if isinstance(meta_value, (dict, list)):
            meta_value = json.dumps(meta_value)
        (d / "hand.json").write_bytes(
            meta_value if isinstance(meta_value, bytes) else meta_value.encode()
        )
        (d / "hand.urdf").write_bytes(
            urdf_text if isinstance(urdf_text, bytes) else urdf_text.encode()
        )
        return d

    def load(d: Path):
        return lambda: load_hand(str(d))

    for name, file, m, u in _hand_variants(meta, urdf):
        d = folder(name, m, u)
        cases.append(Case(f"load_hand({name})", "hands", load(d), "error", match=f"{d.name}/{file}"))  # fmt: skip
    d = folder("urdf utf8", meta, b'<?xml version="1.0"?><robot name="\xff\xfe">')
    cases.append(Case("load_hand(urdf utf8)", "hands", load(d), "error", match=f"{d.name}/hand.urdf"))  # fmt: skip
    d = tmp / "hands" / "json_dir"  # a worker restarted after a crash makes the cases again
    if not (d / "hand.json").is_dir():
        folder("json dir", "{}", urdf)
        (d / "hand.json").unlink()
        (d / "hand.json").mkdir()
    cases.append(Case("load_hand(hand.json a folder)", "hands", load(d), "error", match=f"{d.name}/hand.json"))  # fmt: skip
    d = folder("no json", "{}", urdf)
    (d / "hand.json").unlink(missing_ok=True)
    cases.append(Case("load_hand(no hand.json)", "hands", load(d), "error", match=f"{d.name}/hand.json"))  # fmt: skip
    for bad in ("", "   ", None, 5, ["allegro"], "allegro\x00", "x" * 300, "~nosuchuser/hand"):
        cases.append(Case(f"load_hand({bad!r:.20})", "hands", lambda b=bad: load_hand(b), "error"))

    # valid user hands: copies of the built-in ones, a hand.json with a BOM and a comment, a
    # continuous joint; `drograsp hands FOLDER` on good and bad folders
    import shutil

    def loads_as(dof: int, name: str) -> Callable[[Any], str | None]:
        return lambda h: None if (h.dof, h.name) == (dof, name) else f"{h.name}: {h.dof} DoF"

    for builtin, dof in (("allegro", 16), ("leap", 16), ("shadow", 22)):
        d = tmp / "hands" / f"copy_{builtin}"
        if not d.exists():
            shutil.copytree(hands / builtin, d)
        cases.append(Case(f"load_hand(copy of {builtin})", "hands", load(d), "ok", loads_as(dof, builtin)))  # fmt: skip
    bom = b"\xef\xbb\xbf" + json.dumps(meta | {"_comment": "a user's note"}).encode()
    d = folder("bom and comment", bom, urdf)
    cases.append(Case("load_hand(BOM, comment)", "hands", load(d), "ok", loads_as(16, "allegro")))
    d = folder("continuous joint", meta, urdf.replace('type="revolute"', 'type="continuous"', 1))
    cases.append(Case("load_hand(continuous joint)", "hands", load(d), "ok", loads_as(16, "allegro")))  # fmt: skip
    for name, argv, code in (
        ("hands copy", ["hands", str(tmp / "hands" / "copy_allegro")], 0),
        ("hands open_pose 5", ["hands", str(tmp / "hands" / "open_pose_5")], 2),
        ("hands zero mass", ["hands", str(tmp / "hands" / "zero_mass")], 2),
        ("hands --json utf8", ["hands", "--json", str(tmp / "hands" / "utf8")], 2),
    ):
        cases.append(Case(f"drograsp {name}", "hands", lambda a=argv: _cli(a), "ok", _exit(code)))

    # the hand API: joint vectors and wrists of every shape and kind
    hand = load_hand("allegro")
    f64 = torch.float64
    wrist = torch.tensor([[0.01, -0.02, 0.3, 0.5, 0.5, -0.5, 0.5]], dtype=f64)
    q = torch.as_tensor(np.linspace(hand.lower, hand.upper, 5)[1:2], dtype=f64)  # (1, 16)
    matrix = torch.eye(4, dtype=f64)
    matrix[:3, :3] = torch.as_tensor(
        Rotation.from_quat(wrist[0, 3:].numpy(), scalar_first=True).as_matrix()
    )
    matrix[:3, 3] = wrist[0, :3]
    apis = {
        "fingertip_positions": hand.fingertip_positions,
        "link_poses": hand.link_poses,
        "surface_points": hand.surface_points,
    }
    refs = {name: fn(wrist, q).numpy() for name, fn in apis.items()}

    def same(api: str, batch: int = 1, atol: float = 1e-12) -> Callable[[Any], str | None]:
        want = np.repeat(refs[api], batch, axis=0)

        def check(result) -> str | None:
            if not isinstance(result, torch.Tensor) or tuple(result.shape) != want.shape:
                return f"returned {getattr(result, 'shape', type(result).__name__)}, expected {want.shape}"  # fmt: skip
            err = float(np.abs(result.detach().double().numpy() - want).max(initial=0))
            return None if err <= atol else f"off by {err:.3g}"

        return check

    q0, w0 = q[0], wrist[0]
    good: list[tuple[str, Any, Any, int, float]] = [
        ("q (16,)", wrist, q0, 1, 1e-12),
        ("q numpy", wrist, q.numpy(), 1, 1e-12),
        ("q numpy (16,)", wrist, q0.numpy(), 1, 1e-12),
        ("q list", wrist, q.tolist(), 1, 1e-12),
        ("q flat list", wrist, q0.tolist(), 1, 1e-12),
        ("q tuple", wrist, tuple(q0.tolist()), 1, 1e-12),
        ("q float32", wrist, q.float(), 1, 1e-5),
        ("q numpy float32", wrist, q.numpy().astype(np.float32), 1, 1e-5),
        ("q batch 3, wrist 1", wrist, q.repeat(3, 1), 3, 1e-12),
        ("wrist batch 3, q (16,)", wrist.repeat(3, 1), q0, 3, 1e-12),
        ("wrist (7,)", w0, q, 1, 1e-12),
        ("wrist list", w0.tolist(), q, 1, 1e-12),
        ("wrist numpy", wrist.numpy(), q, 1, 1e-12),
        ("wrist float32", wrist.float(), q, 1, 1e-6),
        ("wrist (4, 4)", matrix, q, 1, 1e-12),
        ("wrist (1, 4, 4)", matrix[None], q, 1, 1e-12),
        ("wrist quat norm 1.001", torch.cat([w0[:3], 1.001 * w0[3:]])[None], q, 1, 1e-12),
        ("q requires_grad", wrist, q.clone().requires_grad_(True), 1, 1e-12),
    ]
    for api, fn in apis.items():
        for name, w, j, batch, atol in good:
            cases.append(Case(f"{api}({name})", "hands", lambda fn=fn, w=w, j=j: fn(w, j), "ok", same(api, batch, atol)))  # fmt: skip
    zero_quat = w0.clone()
    zero_quat[3:] = 0
    scaled_matrix = matrix.clone()
    scaled_matrix[:3, :3] *= 2
    row = matrix.clone()
    row[3, 0] = 1
    bad: list[tuple[str, Any, Any]] = [
        ("q int", wrist, 5),
        ("q None", wrist, None),
        ("q text", wrist, "0" * 16),
        ("q dict", wrist, {"ffj0": 0.0}),
        ("q bool", wrist, torch.zeros(1, 16, dtype=torch.bool)),
        ("q numpy bool", wrist, np.zeros(16, dtype=bool)),
        ("q complex", wrist, np.zeros(16, dtype=complex)),
        ("q ragged", wrist, [[0.0] * 16, [0.0] * 15]),
        ("q (1, 17)", wrist, torch.zeros(1, 17, dtype=f64)),
        ("q (2, 1, 16)", wrist, torch.zeros(2, 1, 16, dtype=f64)),
        ("q NaN", wrist, np.full(16, np.nan)),
        ("q inf", wrist, torch.full((1, 16), float("inf"), dtype=f64)),
        ("q object strings", wrist, np.array(["a"] * 16, dtype=object)),
        ("wrist (1, 6)", torch.zeros(1, 6, dtype=f64), q),
        ("wrist (1, 3, 3)", torch.eye(3, dtype=f64)[None], q),
        ("wrist zero quaternion", zero_quat, q),
        ("wrist non-unit quaternion", [0, 0, 0, 1, 1, 1, 1], q),
        ("wrist NaN", [0, 0, float("nan"), 1, 0, 0, 0], q),
        ("wrist text", "0 0 0 1 0 0 0", q),
        ("wrist None", None, q),
        ("wrist scaled 4x4", scaled_matrix, q),
        ("wrist 4x4 last row", row, q),
        ("wrist 2 for q 3", wrist.repeat(2, 1), q.repeat(3, 1)),
    ]
    for api, fn in apis.items():
        for name, w, j in bad:
            cases.append(Case(f"{api}({name})", "hands", lambda fn=fn, w=w, j=j: fn(w, j), "error"))  # fmt: skip
    tips = hand.fingertip_positions
    cases.append(Case("fingertip_positions(names text)", "hands", lambda: tips(wrist, q, "th"), "error"))  # fmt: skip
    cases.append(Case("fingertip_positions(names unknown)", "hands", lambda: tips(wrist, q, ["xx"]), "error"))  # fmt: skip
    one = refs["fingertip_positions"][:, :1]
    cases.append(Case("fingertip_positions(names [th])", "hands", lambda: tips(wrist, q, ["th"]), "ok", lambda r: None if np.allclose(r.numpy(), one, atol=1e-12) else "wrong tip"))  # fmt: skip
    cases.append(Case("check_joints(list)", "hands", lambda: hand.check_joints([0.0] * 16), "ok"))
    cases.append(Case("check_joints(None)", "hands", lambda: hand.check_joints(None), "error"))
    cases.append(Case("check_joints(text)", "hands", lambda: hand.check_joints("abc"), "error"))
    return cases


def build_cases(seed: int, scale: int, tmp: Path, groups: tuple[str, ...]) -> list[Case]:
    rng = np.random.default_rng(seed)
    files = _files(tmp / "files")
    work = tmp / "work"
    work.mkdir(parents=True, exist_ok=True)
    builders: dict[str, Callable[[], list[Case]]] = {
        "objects": lambda: object_cases(rng, scale),
        "files": lambda: file_cases(files, work),
        "library": lambda: library_cases(rng, scale),
        "text": lambda: text_cases(rng, scale),
        "grasps": lambda: grasp_cases(files, work),
        "validate": lambda: validate_cases(files),
        "plan": plan_cases,
        "jobs": lambda: jobs_cases(files, work),
        "cli": lambda: cli_cases(files, work),
        "hands": lambda: hand_cases(work),
    }
    cases: list[Case] = []
    for group in groups:
        cases += builders[group]()
    return cases


# ---------------------------------------------------------------------- worker
def run_case(case: Case) -> Outcome:
    from models.errors import DrograspError

    start = time.perf_counter()
    try:
        result = case.fn()
    except DrograspError as err:
        kind = "clean_error" if case.expect in ("error", "either") else "wrong_result"
        detail = f"{type(err).__name__}: {err}"[:300]
        if kind == "clean_error" and case.match and case.match not in str(err):
            kind, detail = "wrong_result", f"error does not name {case.match!r}: {detail}"
    except Exception as err:  # noqa: BLE001 - what the fuzz looks for
        kind = "other_exception"
        frame = traceback.extract_tb(err.__traceback__)[-1]
        where = f"{Path(frame.filename).name}:{frame.lineno}"
        detail = f"{type(err).__name__} at {where}: {str(err)[:200]}"
    else:
        if case.expect == "error":
            kind, detail = "accepted_bad", f"returned {type(result).__name__}"
        else:
            problem = case.check(result) if case.check else None
            kind = "wrong_result" if problem else "ok"
            detail = problem or ""
    return Outcome(case.name, case.group, kind, detail, time.perf_counter() - start)


def worker(seed: int, scale: int, tmp: Path, groups: tuple[str, ...]) -> None:
    """Run cases by index, read from stdin; one JSON outcome per line on the original stdout.
    Everything the cases print (and the C libraries' output) goes to a log file instead."""
    out = os.fdopen(os.dup(1), "w", buffering=1)
    log = os.open(str(tmp / "worker.log"), os.O_WRONLY | os.O_CREAT | os.O_APPEND)
    os.dup2(log, 1)
    os.dup2(log, 2)
    sys.stdout = sys.stderr = open(log, "w", buffering=1, closefd=False)  # noqa: SIM115
    os.environ.setdefault("DROGRASP_CACHE", str(tmp / "cache"))
    cases = build_cases(seed, scale, tmp, groups)
    out.write(json.dumps({"ready": [[c.name, c.group] for c in cases]}) + "\n")
    for line in sys.stdin:
        index = int(line)
        outcome = run_case(cases[index])
        out.write(json.dumps(outcome.__dict__) + "\n")


# ---------------------------------------------------------------------- parent
@dataclass
class Report:
    outcomes: list[Outcome] = field(default_factory=list)

    def count(self, kind: str, groups: tuple[str, ...] | None = None) -> int:
        return sum(o.kind == kind and (groups is None or o.group in groups) for o in self.outcomes)

    def failures(self, groups: tuple[str, ...] | None = None) -> list[Outcome]:
        good = ("clean_error", "ok")
        return [
            o for o in self.outcomes if o.kind not in good and (groups is None or o.group in groups)
        ]

    def figures(self, groups: tuple[str, ...] | None = None) -> dict[str, int]:
        chosen = [o for o in self.outcomes if groups is None or o.group in groups]
        kinds = Counter(o.kind for o in chosen)
        signatures = {o.detail.split(":")[0] for o in chosen if o.kind == "other_exception"}
        return {
            "cases": len(chosen),
            "clean_errors": kinds["clean_error"],
            "correct_results": kinds["ok"],
            "other_exceptions": kinds["other_exception"],
            "distinct_signatures": len(signatures),
            "hangs": kinds["hang"],
            "crashes": kinds["crash"],
            "bad_input_accepted": kinds["accepted_bad"],
            "wrong_results": kinds["wrong_result"],
            "cli_tracebacks": sum(o.kind == "other_exception" for o in chosen if o.group == "cli"),
        }


class _Worker:
    def __init__(self, seed: int, scale: int, tmp: Path, groups: tuple[str, ...]):
        cmd = [sys.executable, "-m", "tests.fuzz_cases", "--worker", "--seed", str(seed)]
        cmd += ["--scale", str(scale), "--tmp", str(tmp), "--groups", ",".join(groups)]
        env = os.environ | {"PYTHONPATH": str(REPO), "OMP_NUM_THREADS": "1"}
        self.proc = subprocess.Popen(
            cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=REPO, env=env
        )
        first = self.read(300.0)
        if not first:
            self.kill()
            raise RuntimeError(f"fuzz worker did not start; see {tmp / 'worker.log'}")
        self.names = [tuple(n) for n in json.loads(first)["ready"]]

    def read(self, timeout: float) -> str | None:
        """The next line; None after `timeout` s without one, "" when the worker died."""
        ready, _, _ = select.select([self.proc.stdout], [], [], timeout)
        if not ready:
            return None
        return self.proc.stdout.readline()

    def kill(self) -> None:
        self.proc.kill()
        self.proc.wait()


def run_fuzz(
    seed: int = 0,
    scale: int = 1,
    groups: tuple[str, ...] = GROUPS,
    timeout: float = 30.0,
    tmp: Path | None = None,
    progress: bool = False,
) -> Report:
    import tempfile

    tmp = Path(tmp or tempfile.mkdtemp(prefix="drograsp_fuzz_"))
    tmp.mkdir(parents=True, exist_ok=True)
    report = Report()
    worker_ = _Worker(seed, scale, tmp, groups)
    names = worker_.names
    total = len(names)
    index = 0
    while index < total:
        worker_.proc.stdin.write(f"{index}\n")
        worker_.proc.stdin.flush()
        start = time.perf_counter()
        line = worker_.read(timeout)
        if not line:
            hung = line is None  # else the worker died: its pipe closed
            if not hung:
                try:
                    worker_.proc.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    pass
            code = worker_.proc.poll()
            worker_.kill()
            kind = "hang" if hung else "crash"
            detail = f"no answer in {timeout:g} s" if hung else f"worker died, exit {code}"
            name, group = names[index]
            report.outcomes.append(Outcome(name, group, kind, detail, time.perf_counter() - start))
            worker_ = _Worker(seed, scale, tmp, groups)
        else:
            report.outcomes.append(Outcome(**json.loads(line)))
        if progress:
            o = report.outcomes[-1]
            print(f"{index + 1}/{total} {o.kind:<15} {o.seconds:6.2f}s {o.group}: {o.name[:60]} {o.detail[:120] if o.kind not in ('ok', 'clean_error') else ''}", file=sys.stderr, flush=True)  # fmt: skip
        index += 1
    worker_.proc.stdin.close()
    worker_.kill()
    return report


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--scale", type=int, default=1)
    p.add_argument("--groups", default=",".join(GROUPS))
    p.add_argument("--timeout", type=float, default=30.0)
    p.add_argument("--tmp", type=Path)
    p.add_argument("--worker", action="store_true")
    p.add_argument("--progress", action="store_true")
    p.add_argument("--json", action="store_true")
    args = p.parse_args()
    groups = tuple(g for g in args.groups.split(",") if g)
    if args.worker:
        worker(args.seed, args.scale, args.tmp, groups)
        return
    start = time.perf_counter()
    report = run_fuzz(args.seed, args.scale, groups, args.timeout, args.tmp, args.progress)
    figures = {"all": report.figures()}
    for g in groups:
        figures[g] = report.figures((g,))
    if args.json:
        print(json.dumps(figures, indent=1))
    else:
        for g, f in figures.items():
            print(g, " ".join(f"{k}={v}" for k, v in f.items()))
        for o in report.failures():
            print(f"FAIL {o.kind} [{o.group}] {o.name}: {o.detail}")
    print(f"wall time {time.perf_counter() - start:.1f} s", file=sys.stderr)


if __name__ == "__main__":
    main()
