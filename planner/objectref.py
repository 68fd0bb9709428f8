"""How a saved grasp names its object, so `drograsp view` and batch jobs can rebuild it."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from models.errors import ObjectError
from models.objects import ObjectModel, load_object, make_object
from models.objects.loading import from_mesh


def object_ref(obj: ObjectModel) -> dict[str, Any]:
    """A small JSON-able reference: library (category, seed) or a file path."""
    if obj.category is not None and obj.seed is not None and obj.source is None:
        return {"category": obj.category, "seed": int(obj.seed)}
    if obj.source is not None:
        return {"path": str(Path(obj.source).resolve())}
    return {"name": obj.name}


def resolve_object(ref: dict[str, Any]) -> ObjectModel:
    """Rebuild the object an `object_ref` names; a bare array object cannot be rebuilt."""
    if "category" in ref:
        return make_object(ref["category"], int(ref.get("seed", 0)))
    if "path" in ref:
        return load_labelled(ref["path"], ref.get("part_labels"))
    raise ObjectError(
        f"the grasp names its object only as {ref}; pass --object CATEGORY --seed N or --mesh FILE"
    )


def load_labelled(path: str | Path, part_labels: str | Path | None = None) -> ObjectModel:
    """Load a mesh or cloud, with part labels from a JSON file: {"part_names": [...], and
    "face_labels": [...] for a mesh or "point_labels": [...] for a cloud}. A mesh's
    `<stem>.parts.json` beside it is used when no file is given."""
    obj = load_object(path)
    if part_labels is None:
        return obj
    try:
        data = json.loads(Path(part_labels).read_text())
        names = tuple(data["part_names"])
    except (OSError, ValueError, KeyError, TypeError) as err:
        raise ObjectError(
            f"cannot read part labels {part_labels}: {err}; expected JSON with part_names and "
            "face_labels (mesh) or point_labels (cloud)"
        ) from err
    if obj.mesh is not None and "face_labels" in data:
        labels = np.asarray(data["face_labels"], dtype=np.int64)
        if len(labels) != len(obj.mesh.faces):
            raise ObjectError(
                f"{part_labels} labels {len(labels)} faces but the mesh has {len(obj.mesh.faces)}"
            )
        return from_mesh(obj.mesh, obj.name, obj.source, 1.0, labels, names)
    if "point_labels" in data:
        labels = np.asarray(data["point_labels"], dtype=np.int64)
        return load_object(path, labels=labels, part_names=names)
    raise ObjectError(f"{part_labels}: a mesh needs face_labels, a cloud point_labels")
