"""Grasps in Drake's Meshcat: the object with its parts coloured, the hand at pregrasp, grasp
and squeeze, and the anchors.

`show_live` serves the scene on localhost with a phase slider; `write_html` writes a
self-contained page (Meshcat's StaticHtml) in which the three phases play as an animation, with
a caption (hand, instruction, verdict, part, phases). Meshcat always runs a web server: it is
bound to localhost only, never to every interface; a page's server announces nothing and stops
once the page is written (it serves no one; Drake's "Meshcat listening" line is muted).
"""

from __future__ import annotations

import html
import logging
import time
from pathlib import Path

import numpy as np
import torch
from pydrake.geometry import Box, Capsule, Meshcat, MeshcatAnimation, MeshcatParams, Rgba, Sphere
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.perception import PointCloud

from models.grasp import Grasp
from models.hands import HandModel
from models.objects import ObjectModel
from planner.results import is_uncertain

PART_COLOURS = [
    (0.90, 0.45, 0.10),
    (0.15, 0.50, 0.85),
    (0.20, 0.70, 0.30),
    (0.80, 0.20, 0.50),
    (0.55, 0.40, 0.80),
    (0.85, 0.75, 0.15),
]
HAND_RGBA = Rgba(0.25, 0.25, 0.28, 0.85)
ANCHOR_RGBA = Rgba(0.95, 0.1, 0.1, 1.0)
PHASES = ("pregrasp", "grasp", "squeeze")


def new_meshcat() -> Meshcat:
    """A Meshcat bound to localhost (Drake's default listens on every interface), without
    Drake's "Meshcat listening" line: callers that serve say where themselves."""
    log = logging.getLogger("drake")
    level = log.level
    log.setLevel(logging.WARNING)
    try:
        return Meshcat(MeshcatParams(host="localhost"))
    finally:
        log.setLevel(level)


def caption(grasp: Grasp) -> str:
    """What a page shows in text: hand, instruction, verdict, part and the phases."""
    m = grasp.metrics
    verdict = {True: "holds", False: "does not hold"}.get(m.get("success"), "not validated")
    if is_uncertain(m.get("success"), m.get("validation")):
        checks = m["validation"]["cloud_checks"]
        slipped = checks["of"] - checks["held"]
        verdict = f"uncertain: held on the cloud, slipped on {slipped} of {checks['of']} checks"
    parts = [grasp.hand, grasp.instruction or "", verdict]
    if m.get("part"):
        parts.append(f"part touched: {m['part']}")
    if m.get("squeeze_depth") is not None:
        parts.append(f"squeeze depth {m['squeeze_depth']:g}")
    return " · ".join(p for p in parts if p)


def _with_caption(page: str, text: str) -> str:
    box = (
        '<div style="position:fixed;left:8px;bottom:8px;z-index:10;padding:6px 10px;'
        'background:rgba(255,255,255,0.85);font:14px sans-serif;border-radius:4px">'
        f"<b>{html.escape(text)}</b><br>phases: pregrasp &rarr; grasp &rarr; squeeze (open "
        "Animations and press play; the red dots are the anchors)</div>"
    )
    head, sep, rest = page.partition("<body>")
    return f"{head}{sep}\n{box}{rest}" if sep else page


def _transform(matrix: np.ndarray) -> RigidTransform:
    return RigidTransform(RotationMatrix(matrix[:3, :3]), matrix[:3, 3])


def _shape(geom):
    if geom.kind == "box":
        return Box(*(2 * np.asarray(geom.size)))
    if geom.kind == "sphere":
        return Sphere(geom.size[0])
    return Capsule(geom.size[0], 2 * geom.size[1])


def draw_object(meshcat: Meshcat, obj: ObjectModel, path: str = "/object") -> None:
    """The object: a mesh split by part label, or the surface points coloured by part."""
    if obj.mesh is not None:
        mesh = obj.mesh
        labels = obj.face_labels if obj.face_labels is not None else np.zeros(len(mesh.faces), int)
        for k in np.unique(labels):
            faces = mesh.faces[labels == k]
            used, inverse = np.unique(faces, return_inverse=True)
            name = obj.part_names[k] if obj.part_names else "mesh"
            rgb = PART_COLOURS[int(k) % len(PART_COLOURS)]
            meshcat.SetTriangleMesh(
                f"{path}/{name}",
                mesh.vertices[used].T.astype(float),
                inverse.reshape(-1, 3).T.astype(np.int32),
                Rgba(*rgb, 1.0),
            )
        return
    # one point-cloud object per part (a sphere per point made a 4 MB page that software WebGL
    # took minutes to draw)
    labels = obj.point_labels if obj.point_labels is not None else np.zeros(len(obj.points), int)
    for k in np.unique(labels):
        rgb = PART_COLOURS[int(k) % len(PART_COLOURS)]
        name = obj.part_names[k] if obj.part_names else "cloud"
        pts = obj.points[labels == k]
        cloud = PointCloud(len(pts))
        cloud.mutable_xyzs()[:] = pts.T
        meshcat.SetObject(f"{path}/{name}", cloud, 0.004, Rgba(*rgb, 1.0))


def _link_poses(hand: HandModel, grasp: Grasp, phase: str) -> np.ndarray:
    wrist = torch.tensor(grasp.wrist_pose(phase)[None], dtype=torch.float64)
    q = torch.tensor(np.asarray(grasp.joints(phase))[None], dtype=torch.float64)
    return hand.link_poses(wrist, q)[0].numpy()


def draw_hand(meshcat: Meshcat, hand: HandModel, path: str = "/hand") -> None:
    for link in hand.link_names:
        for i, geom in enumerate(hand.tree.geoms[link]):
            if geom.kind == "mesh":  # a convex mesh (vendor hull): drawn as its hull
                from scipy.spatial import ConvexHull

                verts = np.asarray(geom.vertices, dtype=float)
                faces = ConvexHull(verts).simplices
                meshcat.SetTriangleMesh(
                    f"{path}/{link}/{i}", verts.T, faces.T.astype(np.int32), HAND_RGBA
                )
            else:
                meshcat.SetObject(f"{path}/{link}/{i}", _shape(geom), HAND_RGBA)
            meshcat.SetTransform(f"{path}/{link}/{i}", _transform(geom.pose))


def pose_hand(meshcat: Meshcat, hand: HandModel, poses: np.ndarray, path: str = "/hand") -> None:
    for link, pose in zip(hand.link_names, poses, strict=True):
        meshcat.SetTransform(f"{path}/{link}", _transform(pose))


def draw_anchors(meshcat: Meshcat, anchors: np.ndarray | None, path: str = "/anchors") -> None:
    if anchors is None:
        return
    for i, p in enumerate(np.asarray(anchors)):
        meshcat.SetObject(f"{path}/{i}", Sphere(0.004), ANCHOR_RGBA)
        meshcat.SetTransform(f"{path}/{i}", RigidTransform(p))


def build_scene(meshcat: Meshcat, grasp: Grasp, obj: ObjectModel, hand: HandModel) -> None:
    meshcat.Delete()
    meshcat.SetProperty("/Grid", "visible", False)
    meshcat.SetProperty("/Axes", "visible", False)
    draw_object(meshcat, obj)
    draw_hand(meshcat, hand)
    draw_anchors(meshcat, grasp.anchors)
    pose_hand(meshcat, hand, _link_poses(hand, grasp, "grasp"))
    centre = obj.points.mean(axis=0)
    extent = float(np.linalg.norm(obj.extents))
    meshcat.SetCameraPose(centre + np.array([0.7, -0.9, 0.6]) * max(extent, 0.15), centre)


def _interpolated(hand: HandModel, grasp: Grasp, phase: float) -> np.ndarray:
    """Link poses at a continuous phase in [0, 2]: 0 pregrasp, 1 grasp, 2 squeeze."""
    lo = int(np.clip(np.floor(phase), 0, 1))
    w = float(np.clip(phase - lo, 0, 1))
    a, b = PHASES[lo], PHASES[lo + 1]
    q = (1 - w) * np.asarray(grasp.joints(a)) + w * np.asarray(grasp.joints(b))
    wrist = (1 - w) * grasp.wrist_pose(a) + w * grasp.wrist_pose(b)
    qt = torch.tensor(q[None], dtype=torch.float64)
    return hand.link_poses(torch.tensor(wrist[None], dtype=torch.float64), qt)[0].numpy()


def write_html(
    grasp: Grasp, obj: ObjectModel, hand: HandModel, out: str | Path, text: str | None = None
) -> Path:
    """A self-contained page: the three phases play as an animation (loop it with the
    Animations controls), captioned with `text` (default: `caption(grasp)`); it opens without
    a server."""
    # A Meshcat of its own (0.1 s): a shared one carried every earlier page's leftovers into
    # the next (a page for one grasp grew with each page before it, and software WebGL slowed
    # with it); the server stops when the Meshcat is dropped.
    meshcat = new_meshcat()
    build_scene(meshcat, grasp, obj, hand)
    fps = 10
    anim = MeshcatAnimation(frames_per_second=fps)
    frames = np.concatenate([np.full(5, 0.0), np.linspace(0, 2, 20), np.full(10, 2.0)])
    for frame, phase in enumerate(frames):
        for link, pose in zip(hand.link_names, _interpolated(hand, grasp, phase), strict=True):
            anim.SetTransform(frame, f"/hand/{link}", _transform(pose))
    meshcat.SetAnimation(anim)
    page = _with_caption(meshcat.StaticHtml(), caption(grasp) if text is None else text)
    from models.paths import output_file, write_text_atomic

    return write_text_atomic(output_file(out, (".html", ".htm"), "page"), page, "page")


def show_live(
    grasp: Grasp, obj: ObjectModel, hand: HandModel, seconds: float | None = None
) -> None:
    """Serve the scene on localhost with a phase slider until Ctrl+C (or `seconds`)."""
    meshcat = new_meshcat()
    build_scene(meshcat, grasp, obj, hand)
    slider = "phase: 0 pregrasp, 1 grasp, 2 squeeze"
    meshcat.AddSlider(slider, 0.0, 2.0, 0.05, 1.0)
    print(f"Meshcat is serving the grasp at {meshcat.web_url()} (Ctrl+C to stop)", flush=True)
    last, start = None, time.monotonic()
    while seconds is None or time.monotonic() - start < seconds:
        value = meshcat.GetSliderValue(slider)
        if value != last:
            pose_hand(meshcat, hand, _interpolated(hand, grasp, value))
            last = value
        time.sleep(0.05)
