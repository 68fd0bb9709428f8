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


def _numbers(text: str | None, n: int, what: str, path: Path, *, positive=False) -> list[float]:
    """`n` finite numbers (> 0 where `positive`) from an attribute's text, else HandError."""
    try:
        values = [float(v) for v in (text or "").split()]
    except ValueError:
        values = []
    if len(values) != n or not all(np.isfinite(values)) or (positive and min(values) <= 0):
        kind = "positive numbers" if positive else "finite numbers"
        count = "one" if n == 1 else str(n)
        raise HandError(
            f"{path}: {what} must be {count} {kind[:-1] if n == 1 else kind}, got {text!r}"
        )
    return values


def _origin(elem: ET.Element | None, path: Path, where: str) -> np.ndarray:
    pose = np.eye(4)
    if elem is None:
        return pose
    xyz = _numbers(elem.get("xyz", "0 0 0"), 3, f"{where} <origin xyz>", path)
    rpy = _numbers(elem.get("rpy", "0 0 0"), 3, f"{where} <origin rpy>", path)
    pose[:3, :3] = Rotation.from_euler("xyz", rpy).as_matrix()
    pose[:3, 3] = xyz
    return pose


def _geom(elem: ET.Element, path: Path, link: str) -> Geom:
    where = f"link {link}'s <collision>"
    pose = _origin(elem.find("origin"), path, where)
    shape = elem.find("geometry")
    child = None if shape is None else next(iter(shape), None)
    if child is None:
        raise HandError(f"{path}: {where} has no geometry")
    name = elem.get("name", "")
    if child.tag == "box":
        size = _numbers(child.get("size"), 3, f"{where} <box size>", path, positive=True)
        return Geom("box", pose, tuple(v / 2 for v in size), name)
    if child.tag == "sphere":
        (r,) = _numbers(child.get("radius"), 1, f"{where} <sphere radius>", path, positive=True)
        return Geom("sphere", pose, (r,), name)
    if child.tag in ("capsule", "cylinder"):
        what = f"{where} <{child.tag}"
        (r,) = _numbers(child.get("radius"), 1, f"{what} radius>", path, positive=True)
        (length,) = _numbers(child.get("length"), 1, f"{what} length>", path, positive=True)
        return Geom("capsule", pose, (r, length / 2), name)
    if child.tag == "mesh":
        return _mesh_geom(child, pose, name, path)
    raise HandError(
        f"{path}: collision geometry <{child.tag}> is not supported; use box, sphere, capsule "
        "or mesh (collided as its convex hull)"
    )


def _check_visual(elem: ET.Element, path: Path, link: str) -> None:
    """A <visual>: the project draws nothing from it, but Drake and MuJoCo parse it (and Drake
    aborts on a box of negative size), so its numbers are checked as a collision's are."""
    where = f"link {link}'s <visual>"
    _origin(elem.find("origin"), path, where)
    shape = elem.find("geometry")
    child = None if shape is None else next(iter(shape), None)
    if child is None:
        raise HandError(f"{path}: {where} has no geometry")
    what = f"{where} <{child.tag}"
    if child.tag == "box":
        _numbers(child.get("size"), 3, f"{what} size>", path, positive=True)
    elif child.tag == "sphere":
        _numbers(child.get("radius"), 1, f"{what} radius>", path, positive=True)
    elif child.tag in ("capsule", "cylinder"):
        _numbers(child.get("radius"), 1, f"{what} radius>", path, positive=True)
        _numbers(child.get("length"), 1, f"{what} length>", path, positive=True)
    elif child.tag == "mesh":
        if not child.get("filename"):
            raise HandError(f"{path}: {where} <mesh> has no filename")
        scale = child.get("scale")
        if scale is not None and len(scale.split()) != 1:
            _numbers(scale, 3, f"{what} scale>", path, positive=True)
        elif scale is not None:
            _numbers(scale, 1, f"{what} scale>", path, positive=True)
    else:
        raise HandError(
            f"{path}: {where} has geometry <{child.tag}>; use box, sphere, cylinder, capsule or "
            "mesh"
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


def _check_inertial(link: ET.Element, path: Path) -> None:
    """An <inertial>, where given, with a finite mass >= 0 and a finite inertia whose principal
    moments are >= 0 (MuJoCo and Drake read it; the planner does not)."""
    inertial = link.find("inertial")
    if inertial is None:
        return
    where = f"link {link.get('name')}'s <inertial>"
    _origin(inertial.find("origin"), path, where)
    mass = inertial.find("mass")
    if mass is None:
        raise HandError(f"{path}: {where} has no <mass value=...>")
    (value,) = _numbers(mass.get("value"), 1, f"{where} <mass value>", path)
    if value < 0:
        raise HandError(f"{path}: {where} has a negative mass {value:g}")
    inertia = inertial.find("inertia")
    if inertia is None:
        raise HandError(f"{path}: {where} has no <inertia ixx ixy ixz iyy iyz izz>")
    keys = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
    i = {k: _numbers(inertia.get(k, "0"), 1, f"{where} <inertia {k}>", path)[0] for k in keys}
    matrix = np.array(
        [
            [i["ixx"], i["ixy"], i["ixz"]],
            [i["ixy"], i["iyy"], i["iyz"]],
            [i["ixz"], i["iyz"], i["izz"]],
        ]
    )
    moments = np.linalg.eigvalsh(matrix)
    if moments.min() < -1e-12 * max(1.0, abs(moments).max()):
        raise HandError(
            f"{path}: {where}'s inertia is not physical (principal moments "
            f"{', '.join(f'{m:.3g}' for m in moments)}; they must be >= 0)"
        )


def _revolute(j: ET.Element, name: str, jtype: str, path: Path) -> tuple[np.ndarray, float, float]:
    """A revolute or continuous joint's unit axis and limits (continuous: -pi..pi, the range
    the planner searches; the simulators leave it unlimited)."""
    axis_elem = j.find("axis")
    if axis_elem is None or axis_elem.get("xyz") is None:
        raise HandError(
            f'{path}: joint {name} needs <axis xyz="x y z"/>: URDF\'s default axis (1 0 0) '
            "is rarely a finger's; write it out if it is"
        )
    axis = np.array(_numbers(axis_elem.get("xyz"), 3, f"joint {name} <axis xyz>", path))
    if not np.linalg.norm(axis) > 1e-9:
        raise HandError(f"{path}: joint {name} has a zero axis; give its rotation axis")
    if jtype == "continuous":
        return axis, -np.pi, np.pi
    limit = j.find("limit")
    if limit is None or limit.get("lower") is None or limit.get("upper") is None:
        raise HandError(
            f'{path}: revolute joint {name} needs <limit lower="..." upper="..."> (rad); '
            'use type="continuous" for a joint without limits'
        )
    for key in ("effort", "velocity"):
        if limit.get(key) is not None:
            (value,) = _numbers(limit.get(key), 1, f"joint {name} <limit {key}>", path)
            if value < 0:
                raise HandError(f"{path}: joint {name} <limit {key}> must be 0 or more")
    (lower,) = _numbers(limit.get("lower"), 1, f"joint {name} <limit lower>", path)
    (upper,) = _numbers(limit.get("upper"), 1, f"joint {name} <limit upper>", path)
    if not lower < upper:
        raise HandError(
            f"{path}: joint {name} has limits lower {lower:g} >= upper {upper:g}; lower must be "
            "below upper"
        )
    return axis, lower, upper


def read_urdf(path: Path) -> KinematicTree:
    """Parse a hand URDF: revolute (or continuous) joints and fixed joints, anywhere in the
    tree. Every attribute the project or the simulators read is checked: HandError names the
    file, the element and what it must be."""
    try:
        root_elem = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as err:
        raise HandError(f"cannot read URDF {path}: {err}") from err
    if root_elem.tag != "robot":
        raise HandError(f"{path}: a URDF's root element is <robot>, not <{root_elem.tag}>")
    geoms: dict[str, list[Geom]] = {}
    for link in root_elem.findall("link"):
        name = link.get("name")
        if not name:
            raise HandError(f"{path}: a <link> has no name")
        if name in geoms:
            raise HandError(f"{path}: two links are named {name}; link names must be unique")
        _check_inertial(link, path)
        for visual in link.findall("visual"):
            _check_visual(visual, path, name)
        geoms[name] = [_geom(c, path, name) for c in link.findall("collision")]
    if not geoms:
        raise HandError(f"{path}: the URDF has no <link>")
    joints: dict[str, Joint] = {}
    names: set[str] = set()
    for j in root_elem.findall("joint"):
        name, jtype = j.get("name"), j.get("type")
        if not name:
            raise HandError(f"{path}: a <joint> has no name")
        if name in names:
            raise HandError(f"{path}: two joints are named {name}; joint names must be unique")
        names.add(name)
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
        if j.find("mimic") is not None:
            raise HandError(
                f"{path}: joint {name} has a <mimic>; give joints driven together as hand.json "
                "couplings instead"
            )
        origin = _origin(j.find("origin"), path, f"joint {name}")
        dynamics = j.find("dynamics")
        for key in ("damping", "friction"):
            if dynamics is not None and dynamics.get(key) is not None:
                (value,) = _numbers(dynamics.get(key), 1, f"joint {name} <dynamics {key}>", path)
                if value < 0:
                    raise HandError(f"{path}: joint {name} <dynamics {key}> must be 0 or more")
        if jtype == "fixed":
            joints[child] = Joint(name, parent, child, origin, np.zeros(3), 0.0, 0.0, "fixed")
            continue
        if jtype is None:
            raise HandError(
                f'{path}: joint {name} has no type; give type="revolute", "continuous" or "fixed"'
            )
        if jtype not in ("revolute", "continuous"):
            raise HandError(
                f"{path}: joint {name} is {jtype}; hand URDFs use revolute (or continuous) "
                "joints for the fingers and fixed joints for rigidly attached links"
            )
        axis, lower, upper = _revolute(j, name, jtype, path)
        joints[child] = Joint(
            name=name,
            parent=parent,
            child=child,
            origin=origin,
            axis=axis / np.linalg.norm(axis),
            lower=lower,
            upper=upper,
        )
    roots = [name for name in geoms if name not in joints]
    if len(roots) != 1:
        raise HandError(
            f"{path}: expected one root link (the palm; every other link the child of one "
            f"joint), found {len(roots)}: {roots[:10]}"
        )
    if not any(geoms.values()):
        raise HandError(
            f"{path}: the hand has no <collision> geometry; give its links boxes, capsules, "
            "spheres or meshes"
        )
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
