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
    """A collision primitive in its link's frame. size: box half-extents, (r,), or (r, half-length)."""

    kind: str  # "box" | "sphere" | "capsule"
    pose: np.ndarray  # 4x4 in the link frame
    size: tuple[float, ...]
    name: str = ""


@dataclass(frozen=True)
class Joint:
    name: str
    parent: str
    child: str
    origin: np.ndarray  # 4x4, child frame in parent frame at q = 0
    axis: np.ndarray  # unit 3-vector in the child frame
    lower: float
    upper: float


@dataclass
class KinematicTree:
    """Links in topological order (root first) and one revolute joint per non-root link."""

    name: str
    root: str
    links: list[str]
    joints: dict[str, Joint]  # keyed by child link
    geoms: dict[str, list[Geom]] = field(default_factory=dict)

    def parent_joint(self, link: str) -> Joint | None:
        return self.joints.get(link)


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
    raise HandError(
        f"{path}: collision geometry <{child.tag}> is not supported; use box, sphere or capsule"
    )


def read_urdf(path: Path) -> KinematicTree:
    """Parse a hand URDF (revolute and fixed joints; fixed joints are not allowed below the root)."""
    try:
        root_elem = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as err:
        raise HandError(f"cannot read URDF {path}: {err}") from err
    geoms: dict[str, list[Geom]] = {}
    for link in root_elem.findall("link"):
        geoms[link.get("name")] = [_geom(c, path) for c in link.findall("collision")]
    joints: dict[str, Joint] = {}
    for j in root_elem.findall("joint"):
        jtype = j.get("type")
        if jtype not in ("revolute", "continuous"):
            raise HandError(
                f"{path}: joint {j.get('name')} is {jtype}; hand URDFs use revolute joints only "
                "(merge fixed links into their parent)"
            )
        axis = np.array([float(v) for v in j.find("axis").get("xyz").split()])
        limit = j.find("limit")
        lower = float(limit.get("lower", -np.pi)) if limit is not None else -np.pi
        upper = float(limit.get("upper", np.pi)) if limit is not None else np.pi
        child = j.find("child").get("link")
        joints[child] = Joint(
            name=j.get("name"),
            parent=j.find("parent").get("link"),
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
    return KinematicTree(root_elem.get("name", path.stem), roots[0], order, joints, geoms)
