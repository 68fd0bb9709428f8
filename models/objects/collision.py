"""Convex collision pieces for Drake (Convex) and MuJoCo (mesh geoms).

Three sources, one output type (a list of convex `trimesh.Trimesh` hulls, in the object's frame):
- generated objects: the pieces their construction already knows (instant, exact);
- watertight meshes: CoACD, cached on disk by a hash of the mesh and the parameters (13-18 s,
  up to minutes, per real mesh, so it must never run twice), in a subprocess with a time limit;
- open meshes: cloud pieces from their surface samples (CoACD may never finish on them);
- bare clouds: clusters of surface points, each hull thickened inward along the normals and split
  until it covers no empty space, so cavities (a mug's inside, its handle's hole) stay open.
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import tempfile
import time
import zipfile
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import trimesh
from scipy.cluster.vq import kmeans2
from scipy.spatial import ConvexHull, QhullError, cKDTree

from ..errors import ObjectError
from ..reproducible import rounded
from .cache import cache_dir

COACD_DEFAULTS: dict[str, object] = {
    "threshold": 0.05,
    "max_convex_hull": -1,
    "preprocess_mode": "auto",
    "preprocess_resolution": 50,
    "resolution": 2000,
    "mcts_nodes": 20,
    "mcts_iterations": 150,
    "mcts_max_depth": 3,
    "seed": 0,
}


def hulls(point_sets: Sequence[np.ndarray], min_volume: float = 1e-10) -> list[trimesh.Trimesh]:
    """Convex hulls of point sets, dropping any without volume (MuJoCo rejects flat meshes)."""
    out = []
    for pts in point_sets:
        # rounded first: the hull, and every solve and simulation on it, is then the same on
        # every machine (models.reproducible)
        mesh = hull_mesh(rounded(pts), min_volume=min_volume)
        if mesh is not None:
            out.append(mesh)
    return out


def hull_mesh(
    pts: np.ndarray, qhull: ConvexHull | None = None, min_volume: float = 1e-10
) -> trimesh.Trimesh | None:
    """Outward-wound triangle mesh of a point set's hull (None when it has no volume).

    Built straight from qhull's facets and plane equations: several times faster than
    trimesh.convex.convex_hull, which matters at a hundred pieces per cloud.
    """
    if qhull is None:
        if len(pts) < 4:
            return None
        try:
            qhull = ConvexHull(pts)
        except QhullError:
            return None
    if qhull.volume <= min_volume:
        return None
    used = qhull.vertices
    remap = np.full(len(pts), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    faces = remap[qhull.simplices]
    verts = pts[used]
    tri = verts[faces]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    flip = np.einsum("ij,ij->i", normal, qhull.equations[:, :3]) < 0
    faces[flip] = faces[flip][:, ::-1]
    return trimesh.Trimesh(verts, faces, process=False)


def coacd_pieces(
    mesh: trimesh.Trimesh,
    use_cache: bool = True,
    *,
    name: str = "the mesh",
    timeout: float | None = None,
    **params: object,
) -> list[trimesh.Trimesh]:
    """CoACD approximate convex decomposition of a mesh, cached by content hash.

    The key covers the vertex and face bytes, the parameters and the CoACD version, so a changed
    mesh or setting never reads a stale entry. Set DROGRASP_CACHE to move the cache.

    CoACD runs in a subprocess (`models.objects.coacd_worker`): where it aborts (it does on
    some geometry) or runs past `timeout` seconds (default $DROGRASP_COACD_TIMEOUT or 900; it
    never finishes on some open meshes) an ObjectError says so, and this process lives on.
    Progress goes to stderr while it runs (a first decomposition takes minutes on a scan).
    """
    import coacd

    opts = {**COACD_DEFAULTS, **params}
    verts = np.ascontiguousarray(mesh.vertices, dtype=np.float64)
    faces = np.ascontiguousarray(mesh.faces, dtype=np.int64)
    digest = hashlib.sha256()
    digest.update(verts.tobytes())
    digest.update(faces.tobytes())
    digest.update(json.dumps(opts, sort_keys=True).encode())
    digest.update(getattr(coacd, "__version__", "1").encode())
    path = cache_dir("coacd") / f"{digest.hexdigest()[:32]}.npz"
    if use_cache and path.exists():
        try:
            return _read_pieces(path)
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
            pass  # a damaged entry is recomputed below
    parts = _run_coacd(verts, faces, opts, name, coacd_timeout(timeout))
    pieces = hulls(parts)
    if use_cache:
        _write_pieces(path, pieces)
    return pieces


def coacd_timeout(timeout: float | None = None) -> float:
    """Seconds CoACD may run: `timeout`, else $DROGRASP_COACD_TIMEOUT, else 900."""
    if timeout is None:
        text = os.environ.get("DROGRASP_COACD_TIMEOUT", "900")
        try:
            timeout = float(text)
        except ValueError:
            raise ObjectError(
                f"DROGRASP_COACD_TIMEOUT={text!r} is not a number of seconds"
            ) from None
    if not timeout > 0:
        raise ObjectError(f"the CoACD time limit must be positive seconds, got {timeout}")
    return float(timeout)


def _run_coacd(
    verts: np.ndarray, faces: np.ndarray, opts: dict, name: str, timeout: float
) -> list[np.ndarray]:
    with tempfile.TemporaryDirectory(prefix="drograsp_coacd_") as tmp:
        src, dst = Path(tmp) / "mesh.npz", Path(tmp) / "pieces.npz"
        np.savez(src, vertices=verts, faces=faces)
        cmd = [sys.executable, "-m", "models.objects.coacd_worker", str(src), str(dst)]
        cmd.append(json.dumps(opts))
        root = str(Path(__file__).resolve().parents[2])
        path = os.pathsep.join(p for p in (root, os.environ.get("PYTHONPATH")) if p)
        env = os.environ | {"PYTHONPATH": path}
        start = time.monotonic()
        say = _progress(name, len(faces))
        with open(Path(tmp) / "log.txt", "w+") as log:
            proc = subprocess.Popen(cmd, stdout=log, stderr=log, env=env, cwd=tmp)
            try:
                while True:
                    try:
                        code = proc.wait(timeout=min(5.0, timeout))
                        break
                    except subprocess.TimeoutExpired:
                        elapsed = time.monotonic() - start
                        if elapsed >= timeout:
                            raise ObjectError(
                                f"CoACD did not finish the convex decomposition of {name} in "
                                f"{timeout:.0f} s (it may never finish on an open or damaged "
                                "mesh); close the mesh's holes, allow more time with "
                                "DROGRASP_COACD_TIMEOUT=SECONDS, or use surface pieces "
                                "(collision_pieces('surface'), drograsp plan --pieces surface)"
                            ) from None
                        say(elapsed)
            finally:
                if proc.poll() is None:
                    proc.kill()
                    proc.wait()
            say(time.monotonic() - start, done=True)
            if code != 0 or not dst.exists():
                log.seek(0)
                tail = " ".join(log.read().split())[-300:]
                how = f"was killed by signal {-code}" if code < 0 else f"exited with status {code}"
                raise ObjectError(
                    f"CoACD failed on {name}: it {how} ({tail or 'no message'}); the mesh is "
                    "probably degenerate (flat, or damaged faces): repair it, or use surface "
                    "pieces (collision_pieces('surface'), drograsp plan --pieces surface)"
                )
        with np.load(dst) as data:
            return [np.asarray(data[f"v{i}"]) for i in range(int(data["count"]))]


def _progress(name: str, faces: int):
    """A progress line on stderr every 10 s (a first decomposition takes minutes)."""
    state = {"last": 0.0}
    interactive = sys.stderr.isatty()
    print(
        f"convex decomposition of {name} ({faces} faces) with CoACD: first time for this mesh, "
        "cached afterwards; it can take several minutes",
        file=sys.stderr,
        flush=True,
    )

    def say(elapsed: float, done: bool = False) -> None:
        if done:
            end = "\n" if interactive else ""
            print(
                f"{end}convex decomposition of {name}: {elapsed:.0f} s", file=sys.stderr, flush=True
            )
            return
        if elapsed - state["last"] >= 10.0:
            state["last"] = elapsed
            if interactive:
                print(f"\r  CoACD running: {elapsed:.0f} s", end="", file=sys.stderr, flush=True)
            else:
                print(f"  CoACD running: {elapsed:.0f} s", file=sys.stderr, flush=True)

    return say


def _write_pieces(path: Path, pieces: list[trimesh.Trimesh]) -> None:
    arrays = {}
    for i, p in enumerate(pieces):
        arrays[f"v{i}"] = np.asarray(p.vertices)
        arrays[f"f{i}"] = np.asarray(p.faces)
    tmp = path.with_suffix(f".{os.getpid()}.tmp.npz")
    np.savez_compressed(tmp, count=len(pieces), **arrays)
    os.replace(tmp, path)


def _read_pieces(path: Path) -> list[trimesh.Trimesh]:
    with np.load(path) as data:
        return [
            trimesh.Trimesh(data[f"v{i}"], data[f"f{i}"], process=False)
            for i in range(int(data["count"]))
        ]


def cloud_pieces(
    points: np.ndarray,
    normals: np.ndarray,
    *,
    thickness: float = 0.003,
    slack: float = 0.0015,
    clusters: int = 24,
    min_points: int = 12,
    seed: int = 0,
) -> list[trimesh.Trimesh]:
    """Fast approximate convex pieces of a surface cloud (a few tenths of a second for 20k points).

    k-means groups nearby points; each group plus its copy pushed inward along the normals by
    `thickness`, or by 80% of the wall under a point where that is thinner (`wall_thickness`: a
    blade, a cup's wall), spans a convex slab under the surface. A slab with a probe point
    farther than `slack` plus twice the point spacing from the cloud, on the outer side of its nearest point,
    bridges a gap (a handle's hole, a mug's opening) and is split in two until it does not; so a
    piece pokes out of the object by at most about that distance, at concave places.
    """
    pts = np.asarray(points, dtype=float)
    nrm = np.asarray(normals, dtype=float)
    tree = cKDTree(pts)
    probe = pts[:: max(1, len(pts) // 2000)]
    spacing = float(np.median(tree.query(probe, k=2)[0][:, 1]))
    tol = slack + 2.0 * spacing
    rng = np.random.default_rng(seed)
    walls = wall_thickness(pts, nrm, tree, thickness)
    k = int(min(clusters, max(1, len(pts) // min_points)))
    _, assign = kmeans2(pts, k, minit="++", iter=8, seed=rng)
    todo = [np.flatnonzero(assign == c) for c in range(k)]
    accepted: list[trimesh.Trimesh] = []
    while todo:
        members = todo.pop()
        if len(members) < 4:
            continue
        slab = np.vstack([pts[members], pts[members] - walls[members, None] * nrm[members]])
        try:
            qhull = ConvexHull(slab)
        except QhullError:
            continue  # flat or tiny: no volume to collide with
        if len(members) < 2 * min_points or _stays_in_object(slab, qhull, tree, nrm, tol, rng):
            piece = hull_mesh(slab, qhull)
            if piece is not None:
                accepted.append(piece)
            continue
        todo.extend(_split(pts[members], members))
    return accepted


def wall_thickness(
    pts: np.ndarray, normals: np.ndarray, tree: cKDTree, most: float, share: float = 0.8
) -> np.ndarray:
    """Per point, `share` of the distance to the wall's other sheet behind it (points within
    `most` / `share` whose normals face the other way), between a quarter of `most` and `most`:
    a slab no deeper than that stays inside a scissors blade or a mug's wall instead of poking
    out of its far side."""
    reach = most / share
    out = np.full(len(pts), most)
    for i, near in enumerate(tree.query_ball_point(pts, reach)):
        near = np.asarray(near)
        behind = np.einsum("ij,j->i", pts[i] - pts[near], normals[i])
        other = (normals[near] @ normals[i] < -0.5) & (behind > 1e-4)
        if other.any():
            out[i] = min(most, share * float(behind[other].min()))
    return np.maximum(out, 0.25 * most)


def _stays_in_object(
    slab: np.ndarray,
    qhull: ConvexHull,
    tree: cKDTree,
    normals: np.ndarray,
    tol: float,
    rng: np.random.Generator,
) -> bool:
    """True when no probe inside the slab's hull lies clearly outside the object.

    A probe is outside when it is farther than tol from the cloud and on the outer side of its
    nearest point (along that point's normal): a hole, a hollow, a gap between parts. Deep probes
    behind the surface are inside a solid and fine, so solid objects need few pieces.
    """
    v = slab[qhull.vertices]
    tri = slab[qhull.simplices]
    centre = v.mean(0)
    w = rng.dirichlet(np.full(len(v), 0.3), size=64)
    probes = np.vstack([tri.mean(1), w @ v, 0.5 * (tri.mean(1) + centre), centre[None]])
    dist, idx = tree.query(probes, k=1)
    far = dist > tol
    if not far.any():
        return True
    side = np.einsum("ij,ij->i", normals[idx[far]], probes[far] - tree.data[idx[far]])
    return bool((side < 0).all())


def _split(pts: np.ndarray, members: np.ndarray) -> list[np.ndarray]:
    """Halve a cluster across its longest principal direction, at the median."""
    centred = pts - pts.mean(0)
    axis = np.linalg.svd(centred, full_matrices=False)[2][0]
    proj = centred @ axis
    cut = np.median(proj)
    return [members[proj <= cut], members[proj > cut]]


def contains(pieces: Sequence[trimesh.Trimesh], point: Sequence[float], tol: float = 0.0) -> bool:
    """Whether a point lies inside any convex piece (by its face planes, within tol)."""
    p = np.asarray(point, dtype=float)
    for piece in pieces:
        offs = np.einsum("ij,ij->i", piece.face_normals, p - piece.triangles[:, 0])
        if np.all(offs <= tol):
            return True
    return False
