"""Union of labelled parts into one watertight mesh with a part label on every face.

manifold3d keeps the provenance of every triangle through a boolean (run_original_id), so each
face of the union knows which part it came from: labels are exact, never guessed by proximity.
"""

from __future__ import annotations

from dataclasses import dataclass

import manifold3d as m3
import numpy as np
import trimesh

from .shapes import Solid


@dataclass
class Assembly:
    """A generated object: watertight mesh, per-face labels, and labelled convex pieces.

    Frame: upright as the object rests (+z up), axis-aligned bounding box centred at the origin.
    """

    mesh: trimesh.Trimesh
    face_labels: np.ndarray  # (F,) int, index into part_names
    part_names: tuple[str, ...]
    pieces: list[np.ndarray]  # convex point sets, same frame as the mesh
    piece_labels: np.ndarray  # (P,) int


def assemble(parts: dict[str, list[Solid]]) -> Assembly:
    """Union every part's solids, label faces by provenance, centre the bounding box at 0."""
    names = tuple(parts)
    originals: list[m3.Manifold] = []
    id_to_label: dict[int, int] = {}
    pieces: list[np.ndarray] = []
    piece_labels: list[int] = []
    for label, name in enumerate(names):
        solids = parts[name]
        merged = m3.Manifold.batch_boolean([s.manifold for s in solids], m3.OpType.Add)
        merged = merged.as_original()
        id_to_label[merged.original_id()] = label
        originals.append(merged)
        for s in solids:
            pieces.extend(s.pieces)
            piece_labels.extend([label] * len(s.pieces))
    union = m3.Manifold.batch_boolean(originals, m3.OpType.Add)
    if union.status() != m3.Error.NoError or union.is_empty():
        raise RuntimeError(f"union of parts {names} failed: {union.status()}")
    out = union.to_mesh64()
    verts = np.asarray(out.vert_properties, dtype=float)[:, :3]
    faces = np.asarray(out.tri_verts, dtype=np.int64)
    runs = np.asarray(out.run_index, dtype=np.int64) // 3
    labels = np.empty(len(faces), dtype=np.int64)
    for k, oid in enumerate(out.run_original_id):
        labels[runs[k] : runs[k + 1]] = id_to_label[int(oid)]
    order = np.argsort(labels, kind="stable")
    faces, labels = faces[order], labels[order]
    lo, hi = verts.min(0), verts.max(0)
    centre = 0.5 * (lo + hi)
    verts = verts - centre
    mesh = trimesh.Trimesh(verts, faces, process=False)
    return Assembly(
        mesh=mesh,
        face_labels=labels,
        part_names=names,
        pieces=[p - centre for p in pieces],
        piece_labels=np.asarray(piece_labels, dtype=np.int64),
    )
