"""ObjectModel: one graspable object, from a mesh or a point cloud, with everything derived from it.

Surface samples, normals, random and farthest-point clouds and collision pieces are computed on
first use and kept, so loading is cheap and a planner asks only for what it needs.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
import trimesh

from ..errors import ObjectError
from . import collision, surface

DENSE_POINTS = 16384


@dataclass
class Samples:
    """Points on the object's surface with outward unit normals and part labels (or None)."""

    points: np.ndarray  # (n, 3) metres
    normals: np.ndarray  # (n, 3)
    labels: np.ndarray | None  # (n,) index into ObjectModel.part_names
    index: np.ndarray | None = None  # (n,) rows of ObjectModel.points, where drawn from them

    def __len__(self) -> int:
        return len(self.points)


@dataclass(eq=False)
class ObjectModel:
    """An object in metres. Exactly one of `mesh` and `cloud` is the source geometry.

    Generated objects (see `make_object`) are upright (+z up, long tools along x) with the
    bounding box centred at the origin; loaded objects keep the caller's frame.
    """

    name: str
    mesh: trimesh.Trimesh | None = None
    cloud: np.ndarray | None = None  # (N, 3) when loaded from a point cloud
    cloud_normals: np.ndarray | None = None  # given with the cloud, else estimated on demand
    cloud_labels: np.ndarray | None = None  # (N,) part label per cloud point, if known
    face_labels: np.ndarray | None = None  # (F,) part label per mesh face, if known
    part_names: tuple[str, ...] = ()
    category: str | None = None
    seed: int | None = None
    source: str | None = None  # file path, or None for arrays and generated objects
    viewpoint: np.ndarray | None = None  # camera position of a single-view cloud
    # a completed single view: how its hidden side was guessed (models.objects.completion.
    # Completion.kind: "swept", "mirrored", "swept+mirrored" or "as seen"); None otherwise
    completed_by: str | None = None
    construction_pieces: list[np.ndarray] | None = None  # convex point sets known by construction
    # a loaded mesh's faces in its file: mesh face i is the file's face source_faces[i] (the
    # loader drops degenerate faces), of source_face_count in all
    source_faces: np.ndarray | None = field(default=None, repr=False)
    source_face_count: int | None = None
    labels_source: str | None = None  # the labels file the part labels came from, if any
    source_scale: float = 1.0  # the scale `source` was loaded with
    # what collision_pieces("auto") uses: "auto" (see there), "coacd" or "surface"
    pieces: str = "auto"
    _derived: dict = field(default_factory=dict, repr=False)

    def __setattr__(self, name: str, value: object) -> None:
        if name == "pieces" and value not in PIECE_METHODS:
            raise ObjectError(f"pieces must be one of {', '.join(PIECE_METHODS)}, not {value!r}")
        super().__setattr__(name, value)

    # ---- surface -------------------------------------------------------------------------
    @property
    def is_cloud(self) -> bool:
        return self.mesh is None

    @property
    def labelled(self) -> bool:
        return bool(self.part_names) and (
            self.face_labels is not None if self.mesh is not None else self.cloud_labels is not None
        )

    def _surface(self) -> Samples:
        if "surface" not in self._derived:
            if self.mesh is not None:
                labels = self.face_labels if self.labelled else None
                pts, nrm, lab = surface.sample_mesh(self.mesh, DENSE_POINTS, 0, labels)
            else:
                pts = self.cloud
                nrm = self.cloud_normals
                if nrm is None:
                    nrm = surface.estimate_normals(pts, viewpoint=self.viewpoint)
                lab = self.cloud_labels if self.labelled else None
            self._derived["surface"] = Samples(pts, nrm, lab, np.arange(len(pts)))
        return self._derived["surface"]

    @property
    def points(self) -> np.ndarray:
        """Dense surface points: 16384 area-weighted samples of a mesh, or the cloud itself."""
        return self._surface().points

    @property
    def normals(self) -> np.ndarray:
        """Outward unit normals at `points` (estimated and oriented for a bare cloud)."""
        return self._surface().normals

    @property
    def point_labels(self) -> np.ndarray | None:
        """Part label of each of `points` (index into part_names), or None when unlabelled."""
        return self._surface().labels

    @property
    def extents(self) -> np.ndarray:
        src = self.mesh.vertices if self.mesh is not None else self.cloud
        return np.ptp(src, axis=0)

    def part_of(self, label: int) -> str:
        return self.part_names[label]

    def sample_cloud(self, n: int = 2048, seed: int = 0) -> Samples:
        """A random n-point cloud: fresh area-weighted samples of a mesh, a subset of a cloud.

        A cloud with fewer than n points is drawn with replacement.
        """
        if self.mesh is not None:
            labels = self.face_labels if self.labelled else None
            pts, nrm, lab = surface.sample_mesh(self.mesh, n, seed + 1, labels)
            return Samples(pts, nrm, lab)
        base = self._surface()
        rng = np.random.default_rng(seed)
        idx = rng.choice(len(base), size=n, replace=n > len(base))
        return Samples(
            base.points[idx],
            base.normals[idx],
            None if base.labels is None else base.labels[idx],
            idx,
        )

    def fps(self, n: int = 512) -> Samples:
        """n farthest-point samples of `points` (deterministic; cached per n)."""
        key = f"fps{n}"
        if key not in self._derived:
            base = self._surface()
            idx = surface.farthest_point_indices(base.points, n)
            lab = None if base.labels is None else base.labels[idx]
            self._derived[key] = Samples(base.points[idx], base.normals[idx], lab, idx)
        return self._derived[key]

    # ---- collision -----------------------------------------------------------------------
    def collision_pieces(self, method: str = "auto") -> list[trimesh.Trimesh]:
        """Convex hulls covering the object, for Drake `Convex` and MuJoCo mesh geoms.

        method: "auto" (construction pieces for generated objects; CoACD for watertight meshes,
        surface pieces for open ones, on which CoACD may never finish; cloud pieces for clouds;
        or what `self.pieces` names), "construction", "coacd" (in a subprocess with a time
        limit, cached on disk), "surface" (cloud pieces from the mesh's surface samples, in
        about a second) or "cloud" (from surface points).
        """
        method, open_mesh = self._piece_method(method)
        key = f"pieces-{method}"
        if open_mesh and key not in self._derived:  # once per object, not per caller
            warnings.warn(
                f"{self.name}: the mesh is open (not watertight), and CoACD may never finish "
                "on an open mesh; using pieces from its surface samples instead (close the "
                "mesh's holes for CoACD's pieces)",
                OpenMeshWarning,
                stacklevel=2,
            )
        if key not in self._derived:
            if method == "construction":
                if self.construction_pieces is None:
                    raise ObjectError(
                        "this object has no construction pieces; use 'coacd' or 'cloud'"
                    )
                pieces = collision.hulls(self.construction_pieces)
            elif method in ("coacd", "surface"):
                if self.mesh is None:
                    raise ObjectError(
                        f"{method!r} pieces need a mesh; a bare cloud uses method='cloud'"
                    )
                if method == "coacd":
                    pieces = collision.coacd_pieces(self.mesh, name=self.name)
                else:
                    normals = self.normals
                    if not self.mesh.is_winding_consistent:  # face normals point either way
                        normals = surface.estimate_normals(self.points)
                    pieces = collision.cloud_pieces(self.points, normals)
            else:
                pieces = collision.cloud_pieces(self.points, self.normals)
            if not pieces:
                raise ObjectError(
                    f"{self.name}: the {method} decomposition gave no piece with volume; is "
                    "the object a thin sheet?"
                )
            self._derived[key] = pieces
        return self._derived[key]

    def _piece_method(self, method: str) -> tuple[str, bool]:
        """The method "auto" stands for here, and whether it chose surface pieces for an open
        mesh (which deserves a warning)."""
        if method == "auto" and self.pieces != "auto":
            method = self.pieces
        if method == "auto":
            if self.construction_pieces is not None:
                return "construction", False
            if self.mesh is None:
                return "cloud", False
            return ("coacd", False) if self.mesh.is_watertight else ("surface", True)
        if method not in PIECE_METHODS:
            raise ObjectError(f"unknown method {method!r}: one of {', '.join(PIECE_METHODS)}")
        return method, False

    def piece_variants(self, count: int, keep: float = 0.7) -> list[list[trimesh.Trimesh]]:
        """`count` other sets of collision pieces of a bare cloud, each made from a seeded random
        `keep` share of its points; [] where `collision_pieces()` are not a cloud's (a mesh's
        pieces are the surface itself). A cloud's pieces follow the real surface only to about
        the points' spacing, and a grasp that holds on them but slips on these often slips on
        the real object (docs/planner_log.md, "Cloud checks"): the planner checks its grasps on
        them too (PlannerSettings.cloud_checks)."""
        if count <= 0 or self._piece_method("auto")[0] != "cloud":
            return []
        made = self._derived.setdefault(f"piece-variants-{keep}", [])
        pts, nrm = self.points, self.normals
        while len(made) < count:
            rng = np.random.default_rng([len(made), 7])
            kept = rng.random(len(pts)) < keep
            pieces = collision.cloud_pieces(pts[kept], nrm[kept], seed=len(made) + 1)
            if not pieces:
                raise ObjectError(f"{self.name}: a subset of the cloud gave no piece with volume")
            made.append(pieces)
        return made[:count]


PIECE_METHODS = ("auto", "construction", "coacd", "surface", "cloud")


class OpenMeshWarning(UserWarning):
    """An open mesh got surface pieces instead of CoACD's."""
