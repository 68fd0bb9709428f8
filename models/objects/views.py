"""What a depth camera sees of an object: a single-view cloud, and objects turned in space.

A single-view cloud is the set of surface points a pinhole depth camera at one viewpoint hits
(Open3D ray casting against the mesh), each moved along its ray by Gaussian depth noise. It is
an unlabelled cloud like a user's scan, with normals estimated toward the camera; the part
labels of the faces hit ride along (`labels`), so evaluation can score the part a grasp touches
or hand them to a planner that is allowed labels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import ObjectError
from .loading import import_open3d, load_object
from .model import ObjectModel


@dataclass(frozen=True)
class Camera:
    """A pinhole depth camera looking at the object's centre from `distance` metres, at an
    elevation above the horizontal and an azimuth about the vertical."""

    azimuth_deg: float = 30.0
    elevation_deg: float = 30.0
    distance: float = 0.5
    # half a RealSense D435's 640 x 480 depth stream: a pen at 0.5 m is still a few hundred rays
    width: int = 320
    height: int = 240
    fov_deg: float = 30.0  # vertical field of view
    depth_noise: float = 0.001  # m, standard deviation along the ray

    def position(self, target: np.ndarray) -> np.ndarray:
        az, el = np.radians(self.azimuth_deg), np.radians(self.elevation_deg)
        direction = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        return np.asarray(target, dtype=float) + self.distance * direction


def single_view(
    obj: ObjectModel, camera: Camera | None = None, seed: int = 0, min_points: int = 600
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """(points (N, 3), their part labels (N,) or None, the camera position) the camera sees
    of the object's mesh. ObjectError when the object has no mesh or the view holds fewer than
    `min_points` points (the object is too far or too small for the camera)."""
    if obj.mesh is None:
        raise ObjectError("a single view is rendered from a mesh; this object is a cloud")
    o3d = import_open3d("rendering a single view")
    cam = camera or Camera()
    mesh = obj.mesh
    target = mesh.bounds.mean(axis=0)
    eye = cam.position(target)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(np.asarray(mesh.vertices, dtype=np.float32)),
        o3d.core.Tensor(np.asarray(mesh.faces, dtype=np.uint32)),
    )
    rays = o3d.t.geometry.RaycastingScene.create_rays_pinhole(
        fov_deg=cam.fov_deg,
        center=target.astype(np.float32).tolist(),
        eye=eye.astype(np.float32).tolist(),
        up=[0.0, 0.0, 1.0],
        width_px=cam.width,
        height_px=cam.height,
    )
    hits = scene.cast_rays(rays)
    t = hits["t_hit"].numpy().reshape(-1)
    face = hits["primitive_ids"].numpy().reshape(-1)
    r = rays.numpy().reshape(-1, 6)
    seen = np.isfinite(t)
    if seen.sum() < min_points:
        raise ObjectError(
            f"the camera sees {int(seen.sum())} points of the object, fewer than {min_points}: "
            "move it closer or widen the image"
        )
    direction = r[seen, 3:] / np.linalg.norm(r[seen, 3:], axis=1, keepdims=True)
    rng = np.random.default_rng(seed)
    depth = t[seen] * np.linalg.norm(r[seen, 3:], axis=1) + rng.normal(
        0.0, cam.depth_noise, seen.sum()
    )
    points = r[seen, :3] + direction * depth[:, None]
    labels = None if obj.face_labels is None else np.asarray(obj.face_labels)[face[seen]]
    return points.astype(np.float64), labels, eye


def single_view_object(
    obj: ObjectModel, camera: Camera | None = None, seed: int = 0, labelled: bool = False
) -> ObjectModel:
    """The single view as an ObjectModel cloud (normals estimated toward the camera); with
    `labelled`, the hit faces' part labels and the object's part names come along."""
    points, labels, eye = single_view(obj, camera, seed)
    keep = labelled and labels is not None and obj.part_names
    return load_object(
        points,
        name=f"{obj.name}_view",
        viewpoint=eye,
        labels=labels if keep else None,
        part_names=obj.part_names if keep else (),
    )


def sampled_cloud_object(
    obj: ObjectModel, points: int = 4096, seed: int = 0, labelled: bool = False
) -> ObjectModel:
    """`points` random samples of the whole surface as a cloud, normals estimated as for a
    user's cloud (no viewpoint): the object as a complete scan or a simulator gives it, planned
    with collision pieces made from the cloud rather than from the mesh. With `labelled`, the
    samples' part labels and the object's part names come along."""
    sample = obj.sample_cloud(points, seed)
    keep = labelled and sample.labels is not None and obj.part_names
    return load_object(
        sample.points,
        name=f"{obj.name}_cloud",
        labels=sample.labels if keep else None,
        part_names=obj.part_names if keep else (),
    )


def random_turn(seed: int, max_tilt_deg: float = 30.0) -> np.ndarray:
    """A 3x3 rotation: any yaw, then a tilt about a random horizontal axis up to `max_tilt_deg`
    (objects stand on something: upside-down mugs are another task)."""
    rng = np.random.default_rng(seed)
    yaw = Rotation.from_euler("z", rng.uniform(0, 2 * np.pi))
    angle = rng.uniform(0, 2 * np.pi)
    axis = np.array([np.cos(angle), np.sin(angle), 0.0])
    tilt = Rotation.from_rotvec(axis * np.radians(rng.uniform(0, max_tilt_deg)))
    return (tilt * yaw).as_matrix()


def turned(obj: ObjectModel, rotation: np.ndarray) -> ObjectModel:
    """The object rotated about the origin (a generated object's bounding-box centre), labels
    kept. Its seed is dropped: `make_object(category, seed)` no longer makes it."""
    from dataclasses import replace

    rot = np.asarray(rotation, dtype=float)
    if rot.shape != (3, 3) or not np.allclose(rot @ rot.T, np.eye(3), atol=1e-6):
        raise ObjectError("rotation must be a 3x3 rotation matrix")
    mesh = None
    if obj.mesh is not None:
        mesh = obj.mesh.copy()
        transform = np.eye(4)
        transform[:3, :3] = rot
        mesh.apply_transform(transform)
    return replace(
        obj,
        name=f"{obj.name}_turned",
        mesh=mesh,
        cloud=None if obj.cloud is None else obj.cloud @ rot.T,
        cloud_normals=None if obj.cloud_normals is None else obj.cloud_normals @ rot.T,
        viewpoint=None if obj.viewpoint is None else rot @ obj.viewpoint,
        construction_pieces=(
            None
            if obj.construction_pieces is None
            else [np.asarray(p) @ rot.T for p in obj.construction_pieces]
        ),
        seed=None,
        source=None,
        _derived={},
    )
