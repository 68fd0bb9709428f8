"""How a saved grasp names its object, so `drograsp view`, exports and batch jobs can rebuild it.

A reference is small JSON: a library object is {"category", "seed"}; a file is {"path"} with
its labels file ("part_labels"), its scale, or labels given as arrays ("face_labels" or
"point_labels" with "part_names"); an object made from arrays carries its geometry itself
({"cloud": [...]} or {"vertices": [...], "faces": [...]}), so a grasp planned from the Python
API on an array can be viewed again like one planned from the CLI.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from models.errors import ObjectError
from models.objects import ObjectModel, load_object, make_object
from models.objects.loading import as_array, from_mesh, part_names_arg, with_labels_file
from models.paths import input_file

INLINE_DECIMALS = 7  # inline coordinates to 0.1 micrometre


def _labels(obj: ObjectModel) -> dict[str, Any]:
    """Labels given as arrays (not from a file), inline."""
    if not obj.labelled or obj.labels_source is not None:
        return {}
    key = "face_labels" if obj.mesh is not None else "point_labels"
    values = obj.face_labels if obj.mesh is not None else obj.cloud_labels
    return {key: [int(x) for x in values], "part_names": list(obj.part_names)}


def object_ref(obj: ObjectModel) -> dict[str, Any]:
    """A JSON-able reference that rebuilds `obj` (see the module docstring)."""
    if obj.category is not None and obj.seed is not None and obj.source is None:
        return {"category": obj.category, "seed": int(obj.seed)}
    ref: dict[str, Any]
    if obj.source is not None:
        ref = {"path": str(Path(obj.source).resolve())}
        if obj.source_scale != 1.0:
            ref["scale"] = obj.source_scale
        if obj.labels_source is not None:
            ref["part_labels"] = obj.labels_source
        if obj.viewpoint is not None:  # in the file's units, as load_object takes it
            ref["viewpoint"] = [float(x) / obj.source_scale for x in obj.viewpoint]
    elif obj.mesh is not None:
        ref = {
            "name": obj.name,
            "vertices": np.round(obj.mesh.vertices, INLINE_DECIMALS).tolist(),
            "faces": np.asarray(obj.mesh.faces).tolist(),
        }
    else:
        ref = {"name": obj.name, "cloud": np.round(obj.cloud, INLINE_DECIMALS).tolist()}
        if obj.cloud_normals is not None:
            ref["normals"] = np.round(obj.cloud_normals, INLINE_DECIMALS).tolist()
        if obj.viewpoint is not None:
            ref["viewpoint"] = [float(x) for x in obj.viewpoint]
    ref |= _labels(obj)
    if obj.pieces != "auto":
        ref["pieces"] = obj.pieces
    return ref


def resolve_object(ref: Any) -> ObjectModel:
    """Rebuild the object an `object_ref` names, or an ObjectError saying what is missing."""
    if not isinstance(ref, Mapping) or not ref:
        raise ObjectError(
            f"the grasp names its object only as {ref!r}; pass --object CATEGORY --seed N or "
            "--mesh FILE (grasps written by this version carry their object)"
        )
    pieces = ref.get("pieces", "auto")
    if "category" in ref:
        seed = ref.get("seed", 0)
        if isinstance(seed, float) and seed.is_integer():
            seed = int(seed)  # JSON numbers written by other tools
        obj = make_object(ref["category"], seed)
    elif "path" in ref:
        if not isinstance(ref["path"], str) or not isinstance(ref.get("part_labels", ""), str):
            raise ObjectError(
                f"the object reference's path and part_labels must be a path (a file name), "
                f"got {ref['path']!r}"
            )
        scale = ref.get("scale", 1.0)
        viewpoint = ref.get("viewpoint")
        obj = load_labelled(ref["path"], ref.get("part_labels"), scale=scale, viewpoint=viewpoint)
    elif "cloud" in ref:
        obj = load_object(
            as_array(ref["cloud"], "cloud of the object reference"),
            name=str(ref.get("name", "cloud")),
            normals=ref.get("normals"),
            viewpoint=ref.get("viewpoint"),
        )
    elif "vertices" in ref and "faces" in ref:
        import trimesh

        verts = as_array(ref["vertices"], "vertices of the object reference")
        faces = as_array(ref["faces"], "faces of the object reference")
        if verts.ndim != 2 or verts.shape[1] != 3 or faces.ndim != 2 or faces.shape[1] != 3:
            raise ObjectError("the object reference's vertices and faces must be (N, 3) lists")
        mesh = trimesh.Trimesh(verts.astype(float), faces.astype(np.int64), process=False)
        obj = from_mesh(mesh, str(ref.get("name", "mesh")))
    else:
        raise ObjectError(
            f"the object reference {sorted(ref)} has neither category, path, cloud nor "
            "vertices; pass --object CATEGORY --seed N or --mesh FILE"
        )
    obj = _inline_labels(obj, ref)
    if pieces != "auto":
        obj.pieces = pieces
    return obj


def _inline_labels(obj: ObjectModel, ref: Mapping[str, Any]) -> ObjectModel:
    import dataclasses

    from models.objects.loading import label_array

    key = "face_labels" if obj.mesh is not None else "point_labels"
    if key not in ref:
        return obj
    names = part_names_arg(ref.get("part_names"))
    count = len(obj.mesh.faces) if obj.mesh is not None else len(obj.cloud)
    labels = label_array(ref[key], count, names, f"{key} of the object reference")
    field = "face_labels" if obj.mesh is not None else "cloud_labels"
    return dataclasses.replace(obj, **{field: labels, "part_names": names, "_derived": {}})


def load_labelled(
    path: str | Path,
    part_labels: str | Path | None = None,
    *,
    scale: float = 1.0,
    viewpoint: Sequence[float] | None = None,
) -> ObjectModel:
    """Load a mesh or cloud, with part labels from a JSON file: {"part_names": [...], and
    "face_labels": [...] for a mesh or "point_labels": [...] for a cloud}. A mesh's
    `<stem>.parts.json` beside it is used when no file is given. The mesh is cleaned once;
    face labels may follow the file's faces or the loader's (see `with_labels_file`).
    `viewpoint`: the camera position of a single-view scan (a cloud)."""
    obj = load_object(path, scale=scale, viewpoint=viewpoint)
    if part_labels is None:
        return obj
    return with_labels_file(obj, input_file(part_labels, "part labels file", ObjectError))
