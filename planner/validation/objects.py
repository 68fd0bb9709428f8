"""Objects as the validator sees them: convex collision pieces in the object frame.

Accepts neutral inputs so that it works with any object source: a list of vertex arrays (or
(vertices, faces) pairs, or trimesh meshes), anything with a `collision_pieces()` method (the
project's ObjectModel), or a DexGraspBench object folder (`convex_pieces/*.obj` + `info.json`).
"""

from __future__ import annotations

import functools
import hashlib
import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from models.errors import ObjectError


@dataclass(frozen=True)
class Piece:
    """One convex collision piece: vertices (N x 3, object frame, metres) and optional faces."""

    vertices: np.ndarray
    faces: np.ndarray | None = None


@dataclass(frozen=True)
class CollisionObject:
    """An object for the validator. `volume` sets the density that gives the protocol's mass
    (DexGraspBench takes it from the visual mesh); by default the pieces' hull volumes."""

    name: str
    pieces: tuple[Piece, ...]
    volume: float | None = None
    key: str = field(default="", compare=False)

    def mass_volume(self) -> float:
        if self.volume is not None:
            return float(self.volume)
        return float(sum(_hull_volume(p.vertices) for p in self.pieces))


def _hull_volume(vertices: np.ndarray) -> float:
    try:
        return float(ConvexHull(vertices).volume)
    except (QhullError, ValueError):
        return 0.0


def _piece(item: Any, index: int, scale: float) -> Piece:
    faces = None
    if hasattr(item, "vertices") and hasattr(item, "faces"):
        verts, faces = item.vertices, item.faces
    elif isinstance(item, dict):
        verts, faces = item.get("vertices"), item.get("faces")
    elif isinstance(item, tuple) and len(item) == 2:
        verts, faces = item
    else:
        verts = item
    try:
        verts = np.asarray(verts, dtype=np.float64) * float(scale)
    except (TypeError, ValueError) as err:
        raise ObjectError(f"collision piece {index}: unreadable vertices ({err})") from None
    if verts.ndim != 2 or verts.shape[1] != 3 or verts.shape[0] < 4:
        raise ObjectError(
            f"collision piece {index}: expected at least 4 vertices of shape (N, 3), "
            f"got {verts.shape}"
        )
    if not np.all(np.isfinite(verts)):
        raise ObjectError(f"collision piece {index}: NaN or infinite vertices")
    if faces is not None:
        faces = np.asarray(faces, dtype=np.int32)
        if faces.ndim != 2 or faces.shape[1] != 3 or faces.size == 0:
            faces = None
        elif faces.min() < 0 or faces.max() >= len(verts):
            raise ObjectError(f"collision piece {index}: face indices out of range")
    return Piece(verts, faces)


def _content_key(name: str, pieces: Sequence[Piece], volume: float | None) -> str:
    h = hashlib.sha1(name.encode())
    for p in pieces:
        h.update(np.ascontiguousarray(p.vertices).tobytes())
        if p.faces is not None:
            h.update(np.ascontiguousarray(p.faces).tobytes())
    h.update(repr(volume).encode())
    return h.hexdigest()


def as_collision_object(
    obj: Any, scale: float = 1.0, name: str | None = None, volume: float | None = None
) -> CollisionObject:
    """Normalize any supported object input; `scale` multiplies the vertices."""
    if isinstance(obj, CollisionObject):
        if scale == 1.0 and (name is None or name == obj.name) and volume is None:
            return obj
        if volume is None and obj.volume is not None:
            volume = obj.volume * scale**3
        return as_collision_object(list(obj.pieces), scale, name or obj.name, volume)
    if isinstance(obj, str | Path):
        return load_object_dir(obj, scale)
    label = name or str(getattr(obj, "name", "object"))
    if hasattr(obj, "collision_pieces"):
        items = obj.collision_pieces()
    elif isinstance(obj, np.ndarray) and obj.ndim == 2:
        items = [obj]
    elif isinstance(obj, Sequence) and not isinstance(obj, str):
        items = list(obj)
    else:
        raise ObjectError(
            f"cannot use {type(obj).__name__} as an object: give collision pieces (a list of "
            "vertex arrays), an object with collision_pieces(), or an object folder"
        )
    if len(items) == 0:
        raise ObjectError(f"object {label!r} has no collision pieces")
    pieces = tuple(_piece(item, i, scale) for i, item in enumerate(items))
    if volume is not None and not volume > 0:
        raise ObjectError(f"object {label!r}: volume must be positive, got {volume}")
    return CollisionObject(label, pieces, volume, _content_key(label, pieces, volume))


# ---------------------------------------------------------------------- DexGraspBench folders
def _read_obj(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and triangulated faces of a Wavefront OBJ (enough for convex pieces)."""
    verts, faces = [], []
    for line in path.read_text().splitlines():
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "v":
            verts.append([float(x) for x in parts[1:4]])
        elif parts[0] == "f":
            idx = [int(p.split("/")[0]) for p in parts[1:]]
            idx = [i - 1 if i > 0 else len(verts) + i for i in idx]
            faces.extend([idx[0], idx[k], idx[k + 1]] for k in range(1, len(idx) - 1))
    return np.asarray(verts, dtype=np.float64), np.asarray(faces, dtype=np.int32)


def _reference_volume(folder: Path, scale: float) -> float | None:
    """Volume at `scale` from DexGraspBench's info.json (mass / density at its own scale)."""
    info_path = folder / "info.json"
    if not info_path.is_file():
        return None
    try:
        info = json.loads(info_path.read_text())
        unit = info["mass"] / (info["density"] * info.get("scale", 1.0) ** 3)
    except (KeyError, TypeError, ValueError, ZeroDivisionError):
        return None
    return float(unit * scale**3) if unit > 0 else None


def load_object_dir(folder: str | Path, scale: float = 1.0) -> CollisionObject:
    """A DexGraspBench object folder: `convex_pieces/*.obj` scaled by `scale` (cached)."""
    return _load_object_dir(str(Path(folder).resolve()), float(scale))


@functools.lru_cache(maxsize=64)
def _load_object_dir(folder_name: str, scale: float) -> CollisionObject:
    folder = Path(folder_name)
    files = sorted((folder / "convex_pieces").glob("*.obj"))
    if not files:
        raise ObjectError(f"{folder}: no convex_pieces/*.obj collision pieces")
    pieces = [_read_obj(f) for f in files]
    return as_collision_object(pieces, scale, folder.name, _reference_volume(folder, scale))


def find_object(objects_dir: str | Path, name: str, scale: float = 1.0) -> CollisionObject:
    """Object `name` from a folder of DexGraspBench objects, with a clear error if absent."""
    root = Path(objects_dir)
    if not root.is_dir():
        raise ObjectError(f"{objects_dir}: no such objects folder")
    folder = root / name
    if not folder.is_dir():
        known = sorted(p.name for p in root.iterdir() if p.is_dir())
        raise ObjectError(f"unknown object {name!r} in {root}; known objects: {known}")
    return load_object_dir(folder, scale)
