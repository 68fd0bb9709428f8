"""Export the project's grasps to DexGraspBench: rows in a hand file's frame, and its objects.

`export_dexgraspbench(grasps, out_dir, hand_xml)` writes `out_dir/grasps.npz` in the layout of
DexGraspBench's grasp files (and of ../shared/reference/dexgraspbench/grasps.npz): arrays
`object`, `scale`, `obj_pose` and `{pregrasp,grasp,squeeze}_qpos`, a row being 7 root values
(xyz + quaternion wxyz of the hand file's root frame in the world) then the file's hinge joints
in file order. A grasp's wrist poses are those of the project hand's root link, so each is
composed with the fixed transform between the two frames, computed from the files
(`models.hands.mjcf_frame`); joints are matched by name, or through a joint map {grasp joint:
file joint} as `drograsp validate --joint-map` takes it.

Each grasp's object is written once under `out_dir/objects/<name>/` in DexGraspBench's object
layout: `convex_pieces/convex_piece_%03d.obj` (the project's own collision pieces, the ones its
validation used), `simplified.obj` (the mesh, or the pieces' union for a cloud) and `info.json`.
Meshes are normalized as DexGraspBench's are (bounding-box centre at the origin, divided by half
the bounding-box diagonal); the row's `scale` multiplies them back and its `obj_pose` puts the
object where it was for the grasp. `info.json`'s mass (density 1, scale 1) and gravity centre
are those of the collision pieces, so that both evaluators give the object exactly the
protocol's mass, as the project's validation does (DexGraspBench's own files take them from the
visual mesh, which differs by the few percent the pieces cover beyond it).

Then `drograsp validate out_dir/grasps.npz --hand-xml HAND_FILE --objects out_dir/objects`
simulates the same grasps with the hand file.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from models.errors import DrograspError, GraspError, ObjectError
from models.grasp import PHASES, Grasp, to_dexgraspbench
from models.hands import load_hand
from models.hands.mjcf_frame import RootOffset, mjcf_root_offset
from models.objects import ObjectModel
from planner.objectref import object_ref, resolve_object
from planner.validation.hands import mjcf_joint_names

GRASPS_FILE = "grasps.npz"
OBJECTS_DIR = "objects"
IDENTITY_QUAT = (1.0, 0.0, 0.0, 0.0)


@dataclass
class ExportResult:
    """What `export_dexgraspbench` wrote."""

    grasps_file: Path
    objects_dir: Path
    hand: str
    root_offset: RootOffset
    object_names: list[str]  # per grasp
    objects_written: list[str]  # distinct object folders


@dataclass(frozen=True)
class ObjectFolder:
    """A written object: its folder name and how a row places it (scale, obj_pose)."""

    name: str
    scale: float
    pose: np.ndarray


def check_out_dir(out_dir: str | Path) -> Path:
    """`out_dir` as a Path if it is, or can be created as, a writable folder; else a
    DrograspError (nothing is created here)."""
    path = Path(out_dir).expanduser()
    if path.exists() and not path.is_dir():
        raise DrograspError(f"{out_dir}: exists and is not a folder; give a folder to write into")
    probe = path
    while not probe.exists():
        if probe.parent == probe:
            break
        probe = probe.parent
    if not probe.is_dir():
        raise DrograspError(f"{out_dir}: cannot be created: {probe} is not a folder")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise DrograspError(f"{out_dir}: cannot be created or written: {probe} is not writable")
    return path


def read_joint_map(path: str | Path | None) -> dict[str, str]:
    """A joint map file: JSON {grasp joint name: hand file joint name}."""
    if path is None:
        return {}
    try:
        data = json.loads(Path(path).read_text())
    except OSError as err:
        raise DrograspError(f"cannot read joint map {path}: {err.strerror or err}") from None
    except json.JSONDecodeError as err:
        raise DrograspError(f"joint map {path} is not JSON: {err}") from None
    if not isinstance(data, dict) or not all(
        isinstance(k, str) and isinstance(v, str) for k, v in data.items()
    ):
        raise DrograspError(
            f"joint map {path}: expected a JSON object of names, {{grasp joint: XML joint}}"
        )
    return data


def _safe(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_.") or "object"


def object_name(obj: ObjectModel, pieces: Sequence[trimesh.Trimesh]) -> str:
    """A folder name: `<category>_<seed>` for a library object, else the object's name with a
    hash of its collision pieces (two different meshes with the same file name stay apart)."""
    ref = object_ref(obj)
    if "category" in ref:
        return _safe(f"{ref['category']}_{ref['seed']}")
    digest = hashlib.sha1()
    for piece in pieces:
        digest.update(np.ascontiguousarray(piece.vertices, dtype=np.float64).tobytes())
        digest.update(np.ascontiguousarray(piece.faces, dtype=np.int64).tobytes())
    base = Path(ref["path"]).stem if "path" in ref else obj.name
    return f"{_safe(base)}_{digest.hexdigest()[:8]}"


def _obj_text(vertices: np.ndarray, faces: np.ndarray) -> str:
    # full precision: the pieces read back are the pieces the project validated, to the last bits
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in np.asarray(vertices, dtype=float).tolist()]
    lines += [f"f {a} {b} {c}" for a, b, c in (np.asarray(faces, dtype=np.int64) + 1).tolist()]
    return "\n".join(lines) + "\n"


def _write_text(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def write_object(
    obj: ObjectModel, objects_dir: str | Path, pieces: Sequence[trimesh.Trimesh] | None = None
) -> ObjectFolder:
    """Write `obj` (collision pieces, visual mesh, info.json) in DexGraspBench's object layout
    under `objects_dir/<name>/`; return the name and the row's scale and obj_pose."""
    pieces = list(obj.collision_pieces() if pieces is None else pieces)
    if not pieces:
        raise ObjectError(f"object {obj.name!r} has no collision pieces to export")
    visual = obj.mesh if obj.mesh is not None else trimesh.util.concatenate(pieces)
    lo, hi = visual.vertices.min(axis=0), visual.vertices.max(axis=0)
    centre = 0.5 * (lo + hi)
    scale = 0.5 * float(np.linalg.norm(hi - lo))
    if not scale > 0:
        raise ObjectError(f"object {obj.name!r} has an empty bounding box; cannot normalize it")
    name = object_name(obj, pieces)
    folder = Path(objects_dir) / name
    (folder / "convex_pieces").mkdir(parents=True, exist_ok=True)
    for old in (folder / "convex_pieces").glob("convex_piece_*.obj"):
        old.unlink()  # a folder written before with more pieces keeps none of them
    volume, moment = 0.0, np.zeros(3)
    for i, piece in enumerate(pieces):
        verts = (np.asarray(piece.vertices, dtype=np.float64) - centre) / scale
        _write_text(
            folder / "convex_pieces" / f"convex_piece_{i:03d}.obj", _obj_text(verts, piece.faces)
        )
        normalized = trimesh.Trimesh(verts, piece.faces, process=False)
        volume += float(normalized.volume)
        moment += float(normalized.volume) * np.asarray(normalized.center_mass)
    simplified = trimesh.Trimesh((visual.vertices - centre) / scale, visual.faces, process=False)
    _write_text(folder / "simplified.obj", _obj_text(simplified.vertices, simplified.faces))
    info = {
        "gravity_center": (moment / volume).tolist() if volume > 0 else [0.0, 0.0, 0.0],
        "obb": [float(x) for x in simplified.bounding_box_oriented.primitive.extents],
        "scale": 1.0,
        "density": 1.0,
        "mass": volume,
    }
    _write_text(folder / "info.json", json.dumps(info, indent=1) + "\n")
    return ObjectFolder(name, scale, np.concatenate([centre, IDENTITY_QUAT]))


def grasp_objects(
    grasps: Sequence[Grasp], override: ObjectModel | None = None
) -> list[ObjectModel]:
    """Each grasp's object: `override` for all when given, else the one its record names
    (`metrics["object"]`, as `drograsp plan --out` writes it); rebuilt once per reference."""
    if override is not None:
        return [override] * len(grasps)
    cache: dict[str, ObjectModel] = {}
    out = []
    for grasp in grasps:
        ref = grasp.metrics.get("object")
        if not isinstance(ref, Mapping) or not ref:
            raise ObjectError(
                "a grasp record names no object (metrics['object'], written by `drograsp plan "
                "--out`); pass --object CATEGORY --seed N or --mesh FILE"
            )
        key = json.dumps(ref, sort_keys=True)
        if key not in cache:
            cache[key] = resolve_object(dict(ref))
        out.append(cache[key])
    return out


def export_dexgraspbench(
    grasps: Sequence[Grasp],
    out_dir: str | Path,
    hand_xml: str | Path,
    *,
    joint_map: Mapping[str, str] | None = None,
    objects: Sequence[ObjectModel] | ObjectModel | None = None,
) -> ExportResult:
    """Write `grasps` (one project hand) as `out_dir/grasps.npz` rows for the hand file
    `hand_xml`, and their objects under `out_dir/objects` (see the module docstring).

    `objects` is one ObjectModel for all grasps, one per grasp, or None to rebuild each from
    its record; `joint_map` maps the grasps' joint names to the file's where they differ.
    """
    grasps = list(grasps)
    if not grasps:
        raise GraspError("no grasps to export")
    hands = sorted({g.hand for g in grasps})
    if len(hands) > 1:
        raise GraspError(
            f"the grasps are of several hands ({', '.join(hands)}); a hand file describes one: "
            "export each hand's grasps separately"
        )
    out = check_out_dir(out_dir)
    xml = Path(hand_xml).expanduser()
    if not xml.is_file():
        raise DrograspError(f"{hand_xml}: no such hand file")
    hand = load_hand(hands[0])
    joint_map = dict(joint_map or {})
    for grasp in grasps:
        grasp.check_hand(hand.joint_names, hand.name)
    xml_joints = mjcf_joint_names(str(xml.resolve()))
    offset = mjcf_root_offset(hand, xml, joint_map)
    rows = [
        to_dexgraspbench(
            g,
            root_offset=offset.pose,
            xml_joint_names=xml_joints,
            joint_names=hand.joint_names,
            joint_map=joint_map,
        )
        for g in grasps
    ]
    if isinstance(objects, ObjectModel) or objects is None:
        models = grasp_objects(grasps, objects)
    else:
        models = list(objects)
        if len(models) != len(grasps):
            raise ObjectError(f"{len(models)} objects for {len(grasps)} grasps")
    try:
        (out / OBJECTS_DIR).mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise DrograspError(f"{out_dir}: cannot create it: {err.strerror or err}") from None
    written: dict[int, ObjectFolder] = {}
    for model in models:
        if id(model) not in written:
            written[id(model)] = write_object(model, out / OBJECTS_DIR)
    folders = [written[id(m)] for m in models]
    arrays = {
        "object": np.array([f.name for f in folders], dtype=str),
        "scale": np.array([f.scale for f in folders], dtype=np.float64),
        "obj_pose": np.stack([f.pose for f in folders]),
    }
    for phase in PHASES:
        arrays[f"{phase}_qpos"] = np.stack([r[f"{phase}_qpos"] for r in rows])
    target = out / GRASPS_FILE
    tmp = out / f".{GRASPS_FILE}.{os.getpid()}.tmp"
    with open(tmp, "wb") as fh:
        np.savez(fh, **arrays)
    os.replace(tmp, target)
    distinct = list(dict.fromkeys(f.name for f in folders))
    return ExportResult(
        target, out / OBJECTS_DIR, hand.name, offset, [f.name for f in folders], distinct
    )
