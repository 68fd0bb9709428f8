"""make_object: a procedural library instance as an ObjectModel, and its export to disk."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..errors import ObjectError
from .library import category, check_seed, make_assembly
from .model import ObjectModel


def make_object(category_name: str, seed: int = 0) -> ObjectModel:
    """The instance `seed` of a library category: labelled watertight mesh, exact convex pieces.

    Upright (+z up; long tools lie along x), axis-aligned bounding box centred at the origin.
    """
    cat = category(category_name)
    seed = check_seed(seed)
    asm = make_assembly(cat.name, seed)
    return ObjectModel(
        name=f"{cat.name}_{seed:05d}",
        mesh=asm.mesh,
        face_labels=asm.face_labels,
        part_names=asm.part_names,
        category=cat.name,
        seed=int(seed),
        construction_pieces=asm.pieces,
    )


def obj_text(vertices: np.ndarray, faces: np.ndarray, header: str = "") -> str:
    """Wavefront OBJ with fixed formatting (micrometre precision), so output is byte-stable."""
    lines = [f"# {line}" for line in header.splitlines()]
    lines += [f"v {x:.7f} {y:.7f} {z:.7f}" for x, y, z in np.asarray(vertices, dtype=float)]
    lines += [f"f {a} {b} {c}" for a, b, c in np.asarray(faces, dtype=np.int64) + 1]
    return "\n".join(lines) + "\n"


def export_object(obj: ObjectModel, out: str | Path) -> tuple[Path, Path | None]:
    """Write the mesh as OBJ and, if labelled, `<stem>.parts.json` (per-face labels, part names)."""
    if obj.mesh is None:
        raise ObjectError("only a mesh can be exported as OBJ")
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    header = f"drograsp object {obj.name}" + (
        f" (category {obj.category}, seed {obj.seed})" if obj.category else ""
    )
    out.write_text(obj_text(obj.mesh.vertices, obj.mesh.faces, header))
    if not obj.labelled:
        return out, None
    side = out.with_suffix(".parts.json")
    data = {
        "object": obj.name,
        "category": obj.category,
        "seed": obj.seed,
        "part_names": list(obj.part_names),
        "face_labels": [int(x) for x in obj.face_labels],
    }
    side.write_text(json.dumps(data, separators=(",", ":")) + "\n")
    return out, side
