"""load_object: a user's mesh file, cloud file or array, checked and cleaned into an ObjectModel.

Real scans are rarely clean (open boundaries, UV-seam duplicate vertices, zero-area faces), so a
mesh is repaired as far as is safe and otherwise accepted; only input no hand could grasp, or that
is probably in the wrong unit, is refused, with a message saying how to fix it.
"""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from ..errors import ObjectError
from ..paths import input_file
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
    used as given, else estimated (toward `viewpoint`, the camera of a single-view scan, in the
    cloud's units and scaled with it); `labels` (N,) with
    `part_names` label its points. A mesh file with a `<stem>.parts.json` beside it (as written by
    `drograsp objects export`) gets its per-face part labels back.
    """
    scale = _scale(scale)
    if name is not None and not isinstance(name, str):
        raise ObjectError(f"name must be a string, got {type(name).__name__}")
    names = part_names_arg(part_names)
    viewpoint = _point3(viewpoint, "viewpoint")
    if not isinstance(source, str | Path | os.PathLike | bytes):
        arr = as_array(source, "cloud")
        if arr.ndim == 2 and arr.shape[1] == 6 and normals is None:
            arr, normals = arr[:, :3], arr[:, 3:]
        return _from_cloud(arr, name or "cloud", None, scale, normals, labels, names, viewpoint)
    path = input_file(source, "object file", ObjectError)
    obj = _load_file(path, name, scale, normals, labels, names, viewpoint)
    obj.source_scale = scale
    return obj


def _load_file(
    path: Path,
    name: str | None,
    scale: float,
    normals: np.ndarray | None,
    labels: np.ndarray | None,
    names: tuple[str, ...],
    viewpoint: np.ndarray | None,
) -> ObjectModel:
    suffix = path.suffix.lower()
    if suffix not in MESH_SUFFIXES + CLOUD_SUFFIXES:
        raise ObjectError(
            f"cannot read {path.name}: unsupported format {suffix!r}; use a mesh"
            f" ({', '.join(MESH_SUFFIXES)}) or a cloud ({', '.join(CLOUD_SUFFIXES)})"
        )
    if path.stat().st_size == 0:
        raise ObjectError(f"{path} is empty (0 bytes); was it written completely?")
    stem = name or path.stem
    try:
        if suffix == ".npy":
            arr = as_array(np.load(path, allow_pickle=False), "cloud")
            if arr.ndim == 2 and arr.shape[1] == 6 and normals is None:
                arr, normals = arr[:, :3], arr[:, 3:]
            return _from_cloud(arr, stem, str(path), scale, normals, labels, names, viewpoint)
        if suffix in (".xyz", ".txt"):
            arr = np.loadtxt(path, ndmin=2)
            if arr.shape[1] < 3:
                raise ObjectError(
                    f"{path.name} has {arr.shape[1]} columns; a cloud needs x y z per line"
                )
            return _from_cloud(
                arr[:, :3], stem, str(path), scale, normals, labels, names, viewpoint
            )
        if suffix == ".pcd":
            arr, pcd_normals = _read_pcd(path)
            normals = pcd_normals if normals is None else normals
            return _from_cloud(arr, stem, str(path), scale, normals, labels, names, viewpoint)
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
        return _from_cloud(arr, stem, str(path), scale, normals, labels, names, viewpoint)
    if not isinstance(loaded, trimesh.Trimesh):
        raise ObjectError(f"{path} holds a {type(loaded).__name__}, not a mesh or point cloud")
    if labels is not None or names:
        raise ObjectError(
            f"labels and part_names label a cloud's points; {path.name} is a mesh: give its "
            "per-face labels in a labels file (drograsp objects label)"
        )
    face_labels, side_names, side = _read_sidecar(path, len(loaded.faces))
    obj = from_mesh(loaded, stem, str(path), scale, face_labels, side_names)
    obj.labels_source = None if side is None else str(side)
    return obj


# ---------------------------------------------------------------------- argument checks
def _scale(value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise ObjectError(f"scale must be a positive number (0.001 for millimetres), got {value!r}")
    scale = float(value)
    if not np.isfinite(scale) or scale <= 0:
        raise ObjectError(
            f"scale must be a positive finite number (0.001 for millimetres), got {scale}; a "
            "negative scale would mirror the object"
        )
    return scale


def _point3(value: object, what: str) -> np.ndarray | None:
    if value is None:
        return None
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ObjectError(f"{what} must be 3 numbers (x, y, z), got {value!r}") from None
    if arr.shape != (3,) or not np.isfinite(arr).all():
        raise ObjectError(f"{what} must be 3 finite numbers (x, y, z), got {value!r}")
    return arr


def as_array(value: object, what: str = "cloud") -> np.ndarray:
    """A user's array (numpy, nested lists, a torch tensor) as a real-valued numpy array, or an
    ObjectError saying what it is and what is expected."""
    if hasattr(value, "detach") and hasattr(value, "cpu"):  # a torch tensor, maybe with grad
        value = value.detach().cpu().numpy()
    if value is None or isinstance(value, dict | set | frozenset | str | bytes | int | float):
        raise ObjectError(
            f"cannot use {type(value).__name__} as a {what}: give an (N, 3) array of x, y, z "
            "in metres, or a path to a mesh or cloud file"
        )
    try:
        arr = np.asarray(value)
    except (ValueError, TypeError) as err:
        raise ObjectError(
            f"the {what} is not a rectangular array ({err}); give an (N, 3) array, every row x, "
            "y, z"
        ) from None
    if arr.dtype.names:
        raise ObjectError(
            f"the {what} is a structured array with fields {arr.dtype.names}; give plain "
            "coordinates, e.g. np.column_stack([a['x'], a['y'], a['z']])"
        )
    if arr.dtype.kind not in "iuf":
        kinds = {"b": "booleans", "c": "complex numbers", "O": "Python objects", "U": "text"}
        kind = kinds.get(arr.dtype.kind, f"dtype {arr.dtype}")
        raise ObjectError(f"the {what} holds {kind}; give float coordinates in metres")
    return arr


def part_names_arg(value: object) -> tuple[str, ...]:
    """Part names: a list or tuple of distinct non-empty strings (or nothing)."""
    if value is None:
        return ()
    if isinstance(value, str):
        raise ObjectError(
            f"part_names must be a list of names such as [{value!r}], not the string {value!r} "
            "(a string would become one part per letter)"
        )
    try:
        names = tuple(value)  # type: ignore[arg-type]
    except TypeError:
        raise ObjectError(f"part_names must be a list of strings, got {value!r}") from None
    if not all(isinstance(n, str) and n.strip() for n in names):
        raise ObjectError(f"part_names must be non-empty strings, got {list(names)!r}")
    if len(set(names)) != len(names):
        raise ObjectError(f"part_names must be distinct, got {list(names)!r}")
    return names


def label_array(value: object, count: int, names: tuple[str, ...], what: str) -> np.ndarray:
    """Integer labels, one per point or face, each naming one of `names`."""
    try:
        arr = np.asarray(value)
    except (ValueError, TypeError) as err:
        raise ObjectError(f"{what} are not a flat list of integers ({err})") from None
    if arr.ndim != 1 or arr.dtype.kind not in "iuf" or arr.dtype.kind == "b":
        raise ObjectError(
            f"{what} must be a flat list of integers (indices into the part names), got shape "
            f"{arr.shape} of {arr.dtype}"
        )
    if arr.dtype.kind == "f":
        if not (np.isfinite(arr).all() and (arr == np.round(arr)).all()):
            raise ObjectError(f"{what} must be whole numbers (indices into the part names)")
    labels = arr.astype(np.int64)
    if len(labels) != count:
        raise ObjectError(f"{what} have {len(labels)} entries; one per {count} is needed")
    if not names:
        raise ObjectError(f"{what} need part_names: one name per label value")
    if len(labels) and (labels.min() < 0 or labels.max() >= len(names)):
        raise ObjectError(
            f"{what} must lie in 0..{len(names) - 1} (one per part name {list(names)}), got "
            f"{int(labels.min())}..{int(labels.max())}"
        )
    return labels


def from_mesh(
    mesh: trimesh.Trimesh,
    name: str,
    source: str | None = None,
    scale: float = 1.0,
    face_labels: np.ndarray | None = None,
    part_names: tuple[str, ...] = (),
) -> ObjectModel:
    """Check and clean a triangle mesh (merge seam duplicates, drop zero-area faces).

    The cleaned mesh keeps the faces it keeps in their order; `ObjectModel.source_faces` says
    which face of `mesh` each one is, so labels made for the file's faces still apply."""
    verts = check_coordinates(np.asarray(mesh.vertices) * scale, "mesh", min_points=4)
    faces = np.asarray(mesh.faces)
    if faces.ndim != 2 or faces.shape[1] != 3 or faces.dtype.kind not in "iu":
        raise ObjectError(f"the mesh {name} has faces of shape {faces.shape}; expected (F, 3)")
    faces = faces.astype(np.int64)
    if len(faces) and (faces.min() < 0 or faces.max() >= len(verts)):
        raise ObjectError(
            f"the mesh {name} is damaged: a face refers to vertex {int(faces.max()) + 1} but it "
            f"has {len(verts)} vertices; re-export it"
        )
    clean = trimesh.Trimesh(verts, faces, process=False)
    keep = np.ones(len(faces), dtype=bool)
    keep &= clean.area_faces > 1e-14
    keep &= (
        (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    )
    if not keep.any():
        raise ObjectError(f"the mesh {name} is degenerate: every face has zero area")
    if face_labels is not None:
        face_labels = label_array(face_labels, len(faces), tuple(part_names), "face labels")
        face_labels = face_labels[keep]
    clean.update_faces(keep)
    clean.merge_vertices(merge_tex=True, merge_norm=True)
    clean.remove_unreferenced_vertices()
    check_coordinates(clean.vertices[np.unique(clean.faces)], "mesh", min_points=3)
    # outward normals: by the enclosed volume's sign, also for an open scan whose faces are
    # wound consistently (its volume is that of the surface closed across its holes)
    if (clean.is_watertight or clean.is_winding_consistent) and clean.volume < 0:
        clean.invert()
    return ObjectModel(
        name=name,
        mesh=clean,
        face_labels=face_labels,
        part_names=tuple(part_names) if face_labels is not None else (),
        source=source,
        source_faces=np.flatnonzero(keep),
        source_face_count=len(faces),
    )


def _from_cloud(
    arr: np.ndarray,
    name: str,
    source: str | None,
    scale: float,
    normals: np.ndarray | None,
    labels: np.ndarray | None,
    part_names: tuple[str, ...],
    viewpoint: np.ndarray | None,
) -> ObjectModel:
    pts = check_coordinates(arr * scale if arr.size else arr)
    if viewpoint is not None:
        viewpoint = viewpoint * scale  # in the cloud's units, like its points
    if normals is not None:
        normals = as_array(normals, "normals").astype(float)
        if normals.shape != pts.shape or not np.isfinite(normals).all():
            raise ObjectError(
                f"normals must be a finite array of shape {pts.shape}, got {normals.shape}"
            )
        length = np.linalg.norm(normals, axis=1, keepdims=True)
        if (length < 1e-9).any():
            raise ObjectError("some normals have zero length; pass normals=None to estimate them")
        normals = normals / length
    if labels is not None:
        labels = label_array(labels, len(pts), part_names, "labels")
    elif part_names:
        raise ObjectError(
            "part_names name the values of labels; give labels (one per point) with them"
        )
    return ObjectModel(
        name=name,
        cloud=pts,
        cloud_normals=normals,
        cloud_labels=labels,
        part_names=part_names if labels is not None else (),
        source=source,
        viewpoint=viewpoint,
    )


def import_open3d(purpose: str, alternative: str = "") -> Any:
    """Open3D, or an ObjectError saying `purpose` needs it and which system library is missing:
    Open3D loads libusb and libGL when imported, which a slim machine may lack."""
    try:
        import open3d
    except (ImportError, OSError) as err:
        raise ObjectError(
            f"{purpose} needs Open3D, which failed to import ({err}); install the missing system "
            "library (Debian/Ubuntu: apt-get install libusb-1.0-0 libgl1)" + alternative
        ) from err
    return open3d


def _read_pcd(path: Path) -> tuple[np.ndarray, np.ndarray | None]:
    o3d = import_open3d(f"reading {path.name}", " or convert the cloud to .ply, .npy or .xyz")
    pcd = o3d.io.read_point_cloud(str(path))
    pts = np.asarray(pcd.points)
    if len(pts) == 0:
        raise ObjectError(f"could not read any points from {path}; is it a valid PCD file?")
    return pts, (np.asarray(pcd.normals) if pcd.has_normals() else None)


def _read_sidecar(
    path: Path, n_faces: int
) -> tuple[np.ndarray | None, tuple[str, ...], Path | None]:
    side = path.with_suffix(".parts.json")
    if not side.exists():
        return None, (), None
    data = read_labels_json(side)
    if "face_labels" not in data:
        raise ObjectError(f"{side} has no face_labels; fix it or delete it")
    names = part_names_arg(data.get("part_names"))
    try:
        labels = label_array(data["face_labels"], n_faces, names, f"the face labels of {side}")
    except ObjectError as err:
        raise ObjectError(
            f"{err} ({path.name} has {n_faces} faces); they do not belong together: re-export "
            "both, or delete the .parts.json"
        ) from None
    return labels, names, side


def read_labels_json(path: str | Path) -> dict:
    """A labels file's JSON object, or an ObjectError naming the file."""
    path = input_file(path, "part labels file", ObjectError)
    try:
        data = json.loads(path.read_bytes().decode("utf-8"))
    except UnicodeDecodeError:
        raise ObjectError(f"{path} is not UTF-8 text; a labels file is JSON") from None
    except ValueError as err:
        raise ObjectError(
            f"cannot read part labels {path}: not JSON ({err}); fix or re-write it"
        ) from None
    if not isinstance(data, dict):
        raise ObjectError(
            f"{path} must hold a JSON object with part_names and face_labels (mesh) or "
            "point_labels (cloud)"
        )
    return data


def with_labels_file(obj: ObjectModel, path: str | Path) -> ObjectModel:
    """`obj` labelled from a labels file: {"part_names": [...], and "face_labels": [...] for a
    mesh or "point_labels": [...] for a cloud}.

    A mesh's face labels may follow the file's own faces (as any tool that reads the file counts
    them) or the loader's (`drograsp objects label` writes those: degenerate faces dropped); a
    file that also lists "face_centres" is matched to the mesh by face geometry instead, so it
    fits whatever order the faces come in."""
    data = read_labels_json(path)
    names = part_names_arg(data.get("part_names"))
    if not names:
        raise ObjectError(f'{path} has no part_names; list the parts, e.g. ["body", "handle"]')
    if obj.mesh is not None:
        if "face_labels" not in data:
            raise ObjectError(f"{path}: a mesh needs face_labels (one per face)")
        labels = _face_labels(obj, data, names, str(path))
        out = dataclasses.replace(obj, face_labels=labels, part_names=names, _derived={})
    else:
        if "point_labels" not in data:
            raise ObjectError(f"{path}: a cloud needs point_labels (one per point)")
        labels = label_array(data["point_labels"], len(obj.cloud), names, f"point labels of {path}")
        out = dataclasses.replace(obj, cloud_labels=labels, part_names=names, _derived={})
    out.labels_source = str(Path(path).resolve())
    return out


def _face_labels(obj: ObjectModel, data: dict, names: tuple[str, ...], where: str) -> np.ndarray:
    mesh = obj.mesh
    n_loaded = len(mesh.faces)
    n_file = obj.source_face_count or n_loaded
    raw = data["face_labels"]
    if "face_centres" in data:
        centres = as_array(data["face_centres"], "face centres")
        if centres.ndim != 2 or centres.shape[1] != 3 or not np.isfinite(centres).all():
            raise ObjectError(f"{where}: face_centres must be finite (F, 3) coordinates")
        labels = label_array(raw, len(centres), names, f"face labels of {where}")
        from scipy.spatial import cKDTree

        dist, idx = cKDTree(centres).query(mesh.triangles_center)
        scale = float(np.ptp(mesh.vertices, axis=0).max())
        if float(dist.max()) > 0.01 * scale:
            raise ObjectError(
                f"{where}: its face_centres do not match this mesh (a face is "
                f"{1000 * float(dist.max()):.1f} mm from the nearest); is it the labels file of "
                "another mesh or in another unit?"
            )
        return labels[idx]
    count = len(raw) if isinstance(raw, list | tuple) else None
    if count == n_loaded or obj.source_faces is None:
        return label_array(raw, n_loaded, names, f"face labels of {where}")
    if count == n_file:
        return label_array(raw, n_file, names, f"face labels of {where}")[obj.source_faces]
    raise ObjectError(
        f"{where} labels {count} faces but the mesh has {n_file} in its file ({n_loaded} after "
        "dropping degenerate faces); write the labels in either order, or let `drograsp "
        "objects label MESH OUT.json` write a labels file in the loader's order"
    )
