"""Write the convex hulls of a vendor hand model's collision meshes into a project hand folder.

Developer tool, run where `../shared/reference` exists:

    python tools/vendor_hulls.py shadow /work/shared/reference/dexgraspbench/hand/shadow_right_hand.xml \
        rh_ffdistal rh_mfdistal rh_rfdistal rh_lfdistal rh_thdistal

For each named body, every collision geom of type mesh is replaced by its convex hull (which is
what MuJoCo collides with anyway), written in the body's frame as
`models/hands/<hand>/meshes/<mesh>_hull.obj`, and the hand's URDF collision for that link is
meant to name it (`<mesh filename="meshes/<mesh>_hull.obj"/>`). The hull keeps every hull vertex
of the vendor mesh: a hull thinned to 96 or 32 vertices changed 9-10 of 126 verdicts on the
planner's ShadowHand grasps against the vendor file, the full hull 1 (docs/hands_log.md).
The vendor's licence must be shipped beside the hulls (the script copies it).
"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

import mujoco
import numpy as np
import trimesh

OUT = Path(__file__).resolve().parents[1] / "models" / "hands"


def body_hulls(xml: Path, bodies: list[str]) -> dict[str, tuple[str, trimesh.Trimesh]]:
    """{body: (mesh name, convex hull in the body frame)} for the bodies' collision meshes."""
    model = mujoco.MjModel.from_xml_path(str(xml))
    out = {}
    for body in bodies:
        bid = model.body(body).id
        for g in range(model.ngeom):
            if model.geom_bodyid[g] != bid or model.geom_type[g] != mujoco.mjtGeom.mjGEOM_MESH:
                continue
            if model.geom_contype[g] == 0 and model.geom_conaffinity[g] == 0:
                continue
            mid = model.geom_dataid[g]
            start, count = model.mesh_vertadr[mid], model.mesh_vertnum[mid]
            verts = model.mesh_vert[start : start + count].astype(float)
            rot = np.zeros(9)
            mujoco.mju_quat2Mat(rot, model.geom_quat[g])
            verts = verts @ rot.reshape(3, 3).T + model.geom_pos[g]
            out[body] = (model.mesh(mid).name, trimesh.convex.convex_hull(verts))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("hand")
    parser.add_argument("xml", type=Path)
    parser.add_argument("bodies", nargs="+")
    parser.add_argument("--license", type=Path, help="vendor licence file to ship beside them")
    args = parser.parse_args()
    folder = OUT / args.hand / "meshes"
    folder.mkdir(parents=True, exist_ok=True)
    for body, (mesh, hull) in body_hulls(args.xml, args.bodies).items():
        path = folder / f"{mesh}_hull.obj"
        path.write_text(trimesh.exchange.obj.export_obj(hull, digits=8, include_normals=False))
        print(f"{body}: {path.relative_to(OUT)} ({len(hull.vertices)} vertices)")
    if args.license:
        shutil.copy(args.license, folder / "LICENSE")


if __name__ == "__main__":
    main()
