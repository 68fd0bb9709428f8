"""Write a project hand URDF whose kinematics mirror a MuJoCo Menagerie model.

Developer tool, run once per hand where `../shared/reference/hands` exists:

    python tools/build_hand_urdf.py shadow

Facts carried over from the vendor model: body names and frames, joint names, order, axes and
limits, masses and inertias. A joint-less child body (a fingertip body) is either fused into
its parent (`fuse`) or kept as its own link attached by a fixed joint (`fixed`), with its own
mass, inertia and geometry, as the vendor model has it: per hand in SOURCES, or `--static`.
A separate light tip body makes MuJoCo's fingertip contacts softer than a tip fused into a
heavier distal link (Allegro: inverse body weight 41.6 vs 21.3), so hands whose vendor model
has one keep it. Geometry is
project-authored: each vendor collision geom becomes a primitive (box, capsule, sphere); a
mesh collision geom becomes the capsule fitted to its vertices (principal axis, radius at the
90th percentile of the radial distance), so every link is simple enough for Drake's signed
distance and identical in Drake, MuJoCo and PyTorch. The metadata file is written by hand.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from xml.sax.saxutils import quoteattr

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

REFERENCE = Path(__file__).resolve().parents[2] / "shared" / "reference" / "hands"
OUT = Path(__file__).resolve().parents[1] / "models" / "hands"

# hand name -> (Menagerie file, root body of the hand with the wrist removed, what becomes of
# joint-less child bodies: "fuse" into the parent or keep as a "fixed" link)
SOURCES = {
    "shadow": ("shadow_hand/right_hand.xml", "rh_palm", "fuse"),
    "allegro": ("wonik_allegro/right_hand.xml", "palm", "fixed"),
    "leap": ("leap_hand/right_hand.xml", "palm", "fuse"),
}


def fmt(values) -> str:
    return " ".join(f"{float(v):.10g}" for v in np.atleast_1d(values))


def rpy(quat_wxyz: np.ndarray) -> np.ndarray:
    return Rotation.from_quat(quat_wxyz, scalar_first=True).as_euler("xyz")


def fit_capsule(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Capsule (centre, axis rotation quat wxyz, radius, half-length) fitted to points."""
    centre = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - centre)
    axis = vt[0]
    t = (points - centre) @ axis
    radial = np.linalg.norm((points - centre) - np.outer(t, axis), axis=1)
    radius = float(np.percentile(radial, 90))
    lo, hi = t.min(), t.max()
    centre = centre + axis * (lo + hi) / 2
    half = max((hi - lo) / 2 - radius, 1e-3)
    # rotation taking +z to axis
    rot, _ = Rotation.align_vectors([axis], [[0, 0, 1]])
    return centre, rot.as_quat(scalar_first=True), radius, half


def geom_xml(kind: str, name: str, pos, quat, size) -> str:
    origin = f'<origin xyz="{fmt(pos)}" rpy="{fmt(rpy(quat))}"/>'
    if kind == "box":
        shape = f'<box size="{fmt(2 * np.asarray(size))}"/>'
    elif kind == "sphere":
        shape = f'<sphere radius="{size[0]:.10g}"/>'
    else:  # capsule: radius, full cylinder length
        shape = f'<capsule radius="{size[0]:.10g}" length="{2 * size[1]:.10g}"/>'
    return (
        f"    <visual>{origin}<geometry>{shape}</geometry></visual>\n"
        f"    <collision name={quoteattr(name)}>{origin}<geometry>{shape}</geometry></collision>\n"
    )


def link_geoms(model: mujoco.MjModel, body: int) -> str:
    out = []
    name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, body)
    for g in range(model.ngeom):
        if model.geom_bodyid[g] != body:
            continue
        if model.geom_contype[g] == 0 and model.geom_conaffinity[g] == 0:
            continue
        gtype, size = model.geom_type[g], model.geom_size[g]
        pos, quat = model.geom_pos[g].copy(), model.geom_quat[g].copy()
        gname = f"{name}_c{len(out)}"
        if gtype == mujoco.mjtGeom.mjGEOM_BOX:
            out.append(geom_xml("box", gname, pos, quat, size))
        elif gtype == mujoco.mjtGeom.mjGEOM_SPHERE:
            out.append(geom_xml("sphere", gname, pos, quat, size[:1]))
        elif gtype == mujoco.mjtGeom.mjGEOM_CAPSULE:
            out.append(geom_xml("capsule", gname, pos, quat, size[:2]))
        elif gtype == mujoco.mjtGeom.mjGEOM_CYLINDER:
            # a cylinder becomes the capsule of the same radius and overall length
            out.append(
                geom_xml("capsule", gname, pos, quat, [size[0], max(size[1] - size[0], 1e-3)])
            )
        elif gtype == mujoco.mjtGeom.mjGEOM_MESH:
            mid = model.geom_dataid[g]
            start, count = model.mesh_vertadr[mid], model.mesh_vertnum[mid]
            verts = model.mesh_vert[start : start + count].astype(float)
            rot = Rotation.from_quat(quat, scalar_first=True)
            verts = rot.apply(verts) + pos
            c, q, r, h = fit_capsule(verts)
            out.append(geom_xml("capsule", gname, c, q, [r, h]))
        else:
            raise ValueError(f"unsupported geom type {gtype} on {name}")
    return "".join(out)


def inertial_xml(model: mujoco.MjModel, body: int) -> str:
    mass = max(float(model.body_mass[body]), 1e-3)
    inertia = np.maximum(model.body_inertia[body], 1e-8)
    return (
        f'    <inertial><origin xyz="{fmt(model.body_ipos[body])}" '
        f'rpy="{fmt(rpy(model.body_iquat[body]))}"/><mass value="{mass:.10g}"/>'
        f'<inertia ixx="{inertia[0]:.10g}" ixy="0" ixz="0" iyy="{inertia[1]:.10g}" iyz="0" '
        f'izz="{inertia[2]:.10g}"/></inertial>\n'
    )


def build(hand: str, static: str | None = None) -> str:
    rel, root_name, default_static = SOURCES[hand]
    static = static or default_static
    if static not in ("fuse", "fixed"):
        raise ValueError(f"static must be 'fuse' or 'fixed', not {static!r}")
    spec = mujoco.MjSpec.from_file(str(REFERENCE / rel))
    # fuse: fold joint-less tip bodies into their parent; fixed: keep them as bodies
    spec.compiler.fusestatic = static == "fuse"
    model = spec.compile()
    root = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, root_name)
    links, joints = [], []
    for body in range(model.nbody):
        # keep the root and every body below it
        b = body
        while b not in (0, root):
            b = model.body_parentid[b]
        if b != root:
            continue
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, body)
        links.append(
            f"  <link name={quoteattr(name)}>\n{inertial_xml(model, body)}"
            f"{link_geoms(model, body)}  </link>\n"
        )
        if body == root:
            continue
        parent = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, model.body_parentid[body])
        if model.body_jntnum[body] == 0:  # a joint-less body kept (static="fixed")
            joints.append(
                f'  <joint name={quoteattr(name + "_fixed")} type="fixed">\n'
                f"    <parent link={quoteattr(parent)}/><child link={quoteattr(name)}/>\n"
                f'    <origin xyz="{fmt(model.body_pos[body])}" rpy="{fmt(rpy(model.body_quat[body]))}"/>\n'
                f"  </joint>\n"
            )
            continue
        if model.body_jntnum[body] != 1:
            raise ValueError(f"body {name} has {model.body_jntnum[body]} joints; expected 1")
        j = model.body_jntadr[body]
        jname = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j)
        lo, hi = model.jnt_range[j]
        joints.append(
            f'  <joint name={quoteattr(jname)} type="revolute">\n'
            f"    <parent link={quoteattr(parent)}/><child link={quoteattr(name)}/>\n"
            f'    <origin xyz="{fmt(model.body_pos[body])}" rpy="{fmt(rpy(model.body_quat[body]))}"/>\n'
            f'    <axis xyz="{fmt(model.jnt_axis[j])}"/>\n'
            f'    <limit lower="{lo:.10g}" upper="{hi:.10g}" effort="10" velocity="5"/>\n'
            f"  </joint>\n"
        )
    kept = "; tip bodies kept as fixed links" if static == "fixed" else ""
    header = (
        '<?xml version="1.0"?>\n'
        f"<!-- drograsp {hand} hand: kinematics mirror MuJoCo Menagerie ({rel}, root body"
        f" {root_name}, wrist removed{kept}); primitive geometry authored by"
        " tools/build_hand_urdf.py -->\n"
        f'<robot name="{hand}">\n'
    )
    return header + "".join(links) + "".join(joints) + "</robot>\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("hands", nargs="*", default=list(SOURCES))
    parser.add_argument(
        "--static",
        choices=("fuse", "fixed"),
        default=None,
        help="joint-less child bodies: fuse into the parent, or keep as links on fixed joints "
        "(default: per hand, see SOURCES)",
    )
    args = parser.parse_args()
    for hand in args.hands:
        path = OUT / hand / "hand.urdf"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(build(hand, args.static))
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
