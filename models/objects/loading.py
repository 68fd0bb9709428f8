"""load_object: a user's mesh file, cloud file or array, checked and cleaned into an ObjectModel.

Real scans are rarely clean (open boundaries, UV-seam duplicate vertices, zero-area faces), so a
mesh is repaired as far as is safe and otherwise accepted; only input no hand could grasp, or that
is probably in the wrong unit, is refused, with a message saying how to fix it.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import trimesh

from ..errors import ObjectError
from .model import ObjectModel
from .validation import check_coordinates

MESH_SUFFIXES = (".obj", ".stl", ".ply", ".glb", ".gltf", ".off")
CLOUD_SUFFIXES = (".npy", ".pcd", ".xyz", ".txt", ".ply")


def load_object(
    source: str | Path | np.ndarray,
    *,
    name: str | None = None,
    scale: float = 1.0,
    normals: np.ndarray | None = None,
    labels: np.ndarray | None = None,
    part_names: tuple[str, ...] | list[str] = (),
    viewpoint: np.ndarray | None = None,
) -> ObjectModel:
    """Load a mesh (obj, stl, ply, glb) or a cloud ((N, 3) array, .npy, .ply, .pcd, .xyz) in metres.

    `scale` multiplies coordinates first (0.001 for millimetres). For a cloud, `normals` (N, 3) are
    used as given, else estimated (toward `viewpoint` for a single-view scan); `labels` (N,) with
    `part_names` label its points. A mesh file with a `<stem>.parts.json` beside it (as written by
    `drograsp objects export`) gets its per-face part labels back.
    """
    if isinstance(source, np.ndarray) or (not isinstance(source, str | Path)):
        arr = np.asarray(source)
        if arr.ndim == 2 and arr.shape[1] == 6 and normals is None:
            arr, normals = arr[:, :3], arr[:, 3:]
        return _from_cloud(
            arr, name or "cloud", None, scale, normals, labels, part_names, viewpoint
        )
    path = Path(source).expanduser()
    if not path.exists():
        raise ObjectError(f"object file not found: {path}; check the path and the working folder")
    if path.is_dir():
        raise ObjectError(f"{path} is a folder; give a mesh or point-cloud file inside it")
    suffix = path.suffix.lower()
    if suffix not in MESH_SUFFIXES + CLOUD_SUFFIXES:
        raise ObjectError(
            f"cannot read {path.name}: unsupported format {suffix!r}; use a mesh"
            f" ({', '.join(MESH_SUFFIXES)}) or a cloud ({', '.join(CLOUD_SUFFIXES)})"
        )
    stem = name or path.stem
    try:
        if suffix == ".npy":
            arr = np.load(path, allow_pickle=False)
            if arr.ndim == 2 and arr.shape[1] == 6 and normals is None:
                arr, normals = arr[:, :3], arr[:, 3:]
            return _from_cloud(arr, stem, str(path), scale, normals, labels, part_names, viewpoint)
        if suffix in (".xyz", ".txt"):
            arr = np.loadtxt(path, ndmin=2)[:, :3]
            return _from_cloud(arr, stem, str(path), scale, normals, labels, part_names, viewpoint)
        if suffix == ".pcd":
            arr, pcd_normals = _read_pcd(path)
            normals = pcd_normals if normals is None else normals
            return _from_cloud(arr, stem, str(path), scale, normals, labels, part_names, viewpoint)
        loaded = trimesh.load(str(path), process=False, force=None)
    except ObjectError:
        raise
    except Exception as err:  # noqa: BLE001 - any parser failure means an unreadable file
        raise ObjectError(
            f"could not read {path}: {type(err).__name__}: {err}; is the file complete and"
            " really in the format its extension says?"
        ) from err
    if isinstance(loaded, trimesh.Scene):
        geoms = [g for g in loaded.dump() if isinstance(g, trimesh.Trimesh) and len(g.faces)]
        if not geoms:
            raise ObjectError(f"{path} holds no triangle mesh; export the object as triangles")
        loaded = trimesh.util.concatenate(geoms)
    if isinstance(loaded, trimesh.PointCloud) or (
        isinstance(loaded, trimesh.Trimesh) and len(loaded.faces) == 0
    ):
        arr = np.asarray(loaded.vertices)
        return _from_cloud(arr, stem, str(path), scale, normals, labels, part_names, viewpoint)
    if not isinstance(loaded, trimesh.Trimesh):
        raise ObjectError(f"{path} holds a {type(loaded).__name__}, not a mesh or point cloud")
    face_labels, names = _read_sidecar(path, len(loaded.faces))
    return from_mesh(loaded, stem, str(path), scale, face_labels, names)


def from_mesh(
    mesh: trimesh.Trimesh,
    name: str,
    source: str | None = None,
    scale: float = 1.0,
    face_labels: np.ndarray | None = None,
    part_names: tuple[str, ...] = (),
) -> ObjectModel:
    """Check and clean a triangle mesh (merge seam duplicates, drop zero-area faces)."""
    verts = check_coordinates(np.asarray(mesh.vertices) * scale, "mesh", min_points=4)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    clean = trimesh.Trimesh(verts, faces, process=False)
    keep = np.ones(len(faces), dtype=bool)
    keep &= clean.area_faces > 1e-14
    keep &= (
        (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    )
    if not keep.any():
        raise ObjectError(f"the mesh {name} is degenerate: every face has zero area")
    clean.update_faces(keep)
    if face_labels is not None:
        face_labels = np.asarray(face_labels)[keep]
    clean.merge_vertices(merge_tex=True, merge_norm=True)
    clean.remove_unreferenced_vertices()
    check_coordinates(clean.vertices[np.unique(clean.faces)], "mesh", min_points=3)
    if clean.is_watertight and clean.volume < 0:
        clean.invert()
    return ObjectModel(
        name=name, mesh=clean, face_labels=face_labels, part_names=tuple(part_names), source=source
    )


def _from_cloud(
    arr: np.ndarray,
    name: str,
    source: str | None,
    scale: float,
    normals: np.ndarray | None,
    labels: np.ndarray | None,
    part_names: tuple[str, ...] | list[str],
    viewpoint: np.ndarray | None,
) -> ObjectModel:
    pts = check_coordinates(np.asarray(arr, dtype=float) * scale if np.asarray(arr).size else arr)
    if normals is not None:
        normals = np.asarray(normals, dtype=float)
        if normals.shape != pts.shape or not np.isfinite(normals).all():
            raise ObjectError(
                f"normals must be a finite array of shape {pts.shape}, got {normals.shape}"
            )
        length = np.linalg.norm(normals, axis=1, keepdims=True)
        if (length < 1e-9).any():
            raise ObjectError("some normals have zero length; pass normals=None to estimate them")
        normals = normals / length
    if labels is not None:
        labels = np.asarray(labels, dtype=np.int64)
        if labels.shape != (len(pts),):
            raise ObjectError(
                f"labels must have one entry per point ({len(pts)}), got {labels.shape}"
            )
        if not part_names or labels.min() < 0 or labels.max() >= len(part_names):
            raise ObjectError("labels need part_names with one name per label value 0..max(labels)")
    return ObjectModel(
        name=name,
        cloud=pts,
        cloud_normals=normals,
        cloud_labels=labels,
        part_names=tuple(part_names) if labels is not None else (),
        source=source,
        viewpoint=None if viewpoint is None else np.asarray(viewpoint, dtype=float),
    )


def _read_pcd(path: Path) -> tuple[np.ndarray, np.ndarray | None]:
    try:
        import open3d as o3d
    except (ImportError, OSError) as err:  # open3d loads system libraries (libusb, libGL)
        raise ObjectError(
            f"reading {path.name} needs Open3D, which failed to import ({err}); install the "
            "missing system library (Debian/Ubuntu: apt-get install libusb-1.0-0 libgl1) or "
            "convert the cloud to .ply, .npy or .xyz"
        ) from err
    pcd = o3d.io.read_point_cloud(str(path))
    pts = np.asarray(pcd.points)
    if len(pts) == 0:
        raise ObjectError(f"could not read any points from {path}; is it a valid PCD file?")
    return pts, (np.asarray(pcd.normals) if pcd.has_normals() else None)


def _read_sidecar(path: Path, n_faces: int) -> tuple[np.ndarray | None, tuple[str, ...]]:
    side = path.with_suffix(".parts.json")
    if not side.exists():
        return None, ()
    try:
        data = json.loads(side.read_text())
        labels = np.asarray(data["face_labels"], dtype=np.int64)
        names = tuple(data["part_names"])
    except (ValueError, KeyError, TypeError) as err:
        raise ObjectError(f"cannot read part labels {side}: {err}; delete or fix the file") from err
    if len(labels) != n_faces or (len(labels) and (labels.min() < 0 or labels.max() >= len(names))):
        raise ObjectError(
            f"{side} labels {len(labels)} faces but {path.name} has {n_faces}; they do not belong"
            " together (re-export both, or delete the .parts.json)"
        )
    return labels, names
