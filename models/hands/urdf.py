"""A small URDF reader: the kinematic tree and primitive geometry the project needs.

Drake and MuJoCo parse the same file with their own parsers; this reader exists so the
PyTorch kinematics and the surface sampler see exactly the same frames without either
simulator installed in the loop.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from models.errors import HandError


@dataclass(frozen=True)
class Geom:
    """A collision shape in its link's frame. size: box half-extents, (r,), (r, half-length),
    or () for a convex mesh, whose hull vertices (in the geom frame) are `vertices`."""

    kind: str  # "box" | "sphere" | "capsule" | "mesh" (collided as its convex hull)
    pose: np.ndarray  # 4x4 in the link frame
    size: tuple[float, ...]
    name: str = ""
    vertices: np.ndarray | None = field(default=None, repr=False)
    file: Path | None = None  # a mesh's file (absolute), for Drake and MuJoCo


@dataclass(frozen=True)
class Joint:
    name: str
    parent: str
    child: str
    origin: np.ndarray  # 4x4, child frame in parent frame at q = 0
    axis: np.ndarray  # unit 3-vector in the child frame (zero for a fixed joint)
    lower: float
    upper: float
    kind: str = "revolute"  # "revolute" (continuous included) | "fixed"

    @property
    def moves(self) -> bool:
        return self.kind != "fixed"


@dataclass
class KinematicTree:
    """Links in topological order (root first) and one joint per non-root link: revolute (the
    hand's degrees of freedom) or fixed (a link rigidly attached to its parent, such as a
    fingertip body: Drake welds it, MuJoCo keeps it as a body without a joint)."""

    name: str
    root: str
    links: list[str]
    joints: dict[str, Joint]  # keyed by child link; revolute and fixed
    geoms: dict[str, list[Geom]] = field(default_factory=dict)

    def parent_joint(self, link: str) -> Joint | None:
        return self.joints.get(link)

    @property
    def moving_joints(self) -> list[Joint]:
        """The revolute joints (the hand's degrees of freedom), in link order."""
        return [self.joints[link] for link in self.links[1:] if self.joints[link].moves]

    def rigid_link(self, link: str) -> str:
        """The link that `link` moves with: itself, unless a fixed joint attaches it to its
        parent, then that parent's rigid link (the root for links fixed to the root). MuJoCo
        calls it the weld body; links sharing one are a single rigid body."""
        joint = self.joints.get(link)
        while joint is not None and not joint.moves:
            link = joint.parent
            joint = self.joints.get(link)
        return link

    def rigid_neighbour_pairs(self) -> list[tuple[str, str]]:
        """Link pairs that MuJoCo never collides and that no joint joins directly.

        MuJoCo's parent filter works on rigid bodies (its weld bodies): links of one rigid body,
        and a rigid body and its parent rigid body, never collide. Drake filters only links
        joined by a joint and links welded together: a fingertip link on a fixed joint would
        collide with its finger's middle link, and a link below a fixed spacer link with the
        link above the spacer. Empty for a tree without fixed joints."""

        def parent_rigid(rigid: str) -> str | None:
            joint = self.joints.get(rigid)
            return None if joint is None else self.rigid_link(joint.parent)

        rigid = {link: self.rigid_link(link) for link in self.links}
        pairs = []
        for i, a in enumerate(self.links):
            for b in self.links[i + 1 :]:
                joined = any(
                    (j := self.joints.get(x)) is not None and j.parent == y
                    for x, y in ((a, b), (b, a))
                )
                ra, rb = rigid[a], rigid[b]
                if not joined and (ra == rb or parent_rigid(ra) == rb or parent_rigid(rb) == ra):
                    pairs.append((a, b))
        return pairs


def _origin(elem: ET.Element | None) -> np.ndarray:
    pose = np.eye(4)
    if elem is None:
        return pose
    xyz = [float(v) for v in elem.get("xyz", "0 0 0").split()]
    rpy = [float(v) for v in elem.get("rpy", "0 0 0").split()]
    pose[:3, :3] = Rotation.from_euler("xyz", rpy).as_matrix()
    pose[:3, 3] = xyz
    return pose


def _geom(elem: ET.Element, path: Path) -> Geom:
    pose = _origin(elem.find("origin"))
    shape = elem.find("geometry")
    child = None if shape is None else next(iter(shape), None)
    if child is None:
        raise HandError(f"{path}: a <collision> has no geometry")
    if child.tag == "box":
        size = tuple(float(v) / 2 for v in child.get("size", "").split())
        return Geom("box", pose, size, elem.get("name", ""))
    if child.tag == "sphere":
        return Geom("sphere", pose, (float(child.get("radius")),), elem.get("name", ""))
    if child.tag in ("capsule", "cylinder"):
        r, length = float(child.get("radius")), float(child.get("length"))
        return Geom("capsule", pose, (r, length / 2), elem.get("name", ""))
    if child.tag == "mesh":
        return _mesh_geom(child, pose, elem.get("name", ""), path)
    raise HandError(
        f"{path}: collision geometry <{child.tag}> is not supported; use box, sphere, capsule "
        "or mesh (collided as its convex hull)"
    )


def _mesh_geom(elem: ET.Element, pose: np.ndarray, name: str, path: Path) -> Geom:
    """A <mesh filename="..."/> collision: the file relative to the URDF's folder, collided as
    its convex hull (what MuJoCo and Drake's signed distance use for a mesh anyway)."""
    import trimesh

    filename = elem.get("filename", "")
    if not filename or "://" in filename:
        raise HandError(
            f"{path}: mesh filename {filename!r}: give a path relative to the URDF's folder "
            "(package:// and URLs are not resolved)"
        )
    file = (path.parent / filename).resolve()
    if elem.get("scale") is not None:
        raise HandError(
            f"{path}: mesh {filename}: scale the file itself instead of a URDF scale attribute"
        )
    try:
        mesh = trimesh.load(file, force="mesh", process=False)
        hull = trimesh.convex.convex_hull(np.asarray(mesh.vertices, dtype=float))
    except Exception as err:  # noqa: BLE001 - any reader failure is the same bad input
        raise HandError(f"{path}: cannot read collision mesh {file}: {err}") from None
    if len(hull.vertices) < 4 or not hull.volume > 0:
        raise HandError(f"{path}: collision mesh {file} has no volume")
    return Geom("mesh", pose, (), name, np.asarray(hull.vertices, dtype=float), file)


def read_urdf(path: Path) -> KinematicTree:
    """Parse a hand URDF: revolute (or continuous) joints and fixed joints, anywhere in the tree."""
    try:
        root_elem = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as err:
        raise HandError(f"cannot read URDF {path}: {err}") from err
    geoms: dict[str, list[Geom]] = {}
    for link in root_elem.findall("link"):
        geoms[link.get("name")] = [_geom(c, path) for c in link.findall("collision")]
    joints: dict[str, Joint] = {}
    for j in root_elem.findall("joint"):
        name, jtype = j.get("name"), j.get("type")
        parent_elem, child_elem = j.find("parent"), j.find("child")
        if parent_elem is None or child_elem is None:
            raise HandError(f"{path}: joint {name} needs <parent link> and <child link>")
        parent, child = parent_elem.get("link"), child_elem.get("link")
        for link in (parent, child):
            if link not in geoms:
                raise HandError(f"{path}: joint {name} names link {link!r}, which has no <link>")
        if child in joints:
            raise HandError(
                f"{path}: link {child} is the child of joints {joints[child].name} and {name}"
            )
        if jtype == "fixed":
            joints[child] = Joint(
                name, parent, child, _origin(j.find("origin")), np.zeros(3), 0.0, 0.0, "fixed"
            )
            continue
        if jtype not in ("revolute", "continuous"):
            raise HandError(
                f"{path}: joint {name} is {jtype}; hand URDFs use revolute (or continuous) "
                "joints for the fingers and fixed joints for rigidly attached links"
            )
        axis_elem = j.find("axis")
        axis = np.array(
            [float(v) for v in (axis_elem.get("xyz") if axis_elem is not None else "1 0 0").split()]
        )
        if not np.linalg.norm(axis) > 0:
            raise HandError(f"{path}: joint {name} has a zero axis")
        limit = j.find("limit")
        lower = float(limit.get("lower", -np.pi)) if limit is not None else -np.pi
        upper = float(limit.get("upper", np.pi)) if limit is not None else np.pi
        joints[child] = Joint(
            name=name,
            parent=parent,
            child=child,
            origin=_origin(j.find("origin")),
            axis=axis / np.linalg.norm(axis),
            lower=lower,
            upper=upper,
        )
    roots = [name for name in geoms if name not in joints]
    if len(roots) != 1:
        raise HandError(f"{path}: expected one root link, found {roots}")
    order, frontier = [], [roots[0]]
    children: dict[str, list[str]] = {}
    for j in joints.values():
        children.setdefault(j.parent, []).append(j.child)
    while frontier:  # depth first, children in file order: the order MuJoCo and Menagerie use
        link = frontier.pop()
        order.append(link)
        frontier.extend(reversed(children.get(link, [])))
    if len(order) != len(geoms):  # a cycle leaves links unreachable from the root
        lost = sorted(set(geoms) - set(order))
        raise HandError(f"{path}: links {lost} are not connected to the root link {roots[0]}")
    return KinematicTree(root_elem.get("name", path.stem), roots[0], order, joints, geoms)
