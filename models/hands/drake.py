"""Put a hand into a Drake MultibodyPlant with a floating wrist.

Drake filters only parent-child collision pairs (and links welded together). Links on fixed
joints (a fingertip link) are filtered as MuJoCo filters them: against their own rigid body and
its parent rigid body (`KinematicTree.rigid_neighbour_pairs`). The hand.json ignore list
(neighbours whose geometry overlaps by design) is always filtered; the other hand-hand pairs are
filtered too unless `filter_self_collisions=False`. The grasp program keeps them: with every
hand-hand pair filtered, solutions put fingers through each other and MuJoCo then pushes the
object away.

With `merge_hull_links` (the grasp program's simplified hand), the boxes of each link named in
hand.json `program_hull_links` become one convex hull (it contains them, so a hull without
penetration means boxes without it too): LEAP's 71 vendor boxes become 21 shapes and each
signed-distance query has far fewer pairs. Collision meshes (ShadowHand's distal links: the
vendor's hulls of 1067 and 1165 vertices) keep PROGRAM_MESH_VERTICES of their hull's vertices
there; MuJoCo validates with the full hull.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from functools import cached_property

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.geometry import CollisionFilterDeclaration, Convex, GeometrySet
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import CoulombFriction

from models.hands.primitives import primitive_mesh
from models.hands.surface import farthest_point_sample
from models.reproducible import rounded

# Hull vertices a collision mesh keeps in the grasp program (farthest-point thinned, an inner
# approximation). ShadowHand's full distal hulls made solves 1.5x slower than the capsules they
# replaced; with 64 vertices solves take 1.1x as long and the full hull's vertices stay within
# 0.9 (finger) and 1.0 mm (thumb) of the thinned one (docs/hands_log.md).
PROGRAM_MESH_VERTICES = 64


class DrakeHand:
    """Where a hand lives in a plant: model instance, root body, joint indices, geometries.

    Joint indices are read on first use, which must come after `plant.Finalize()`."""

    def __init__(self, plant, instance, root_body, joint_names: list[str], geometry_ids: list):
        self._plant = plant
        self._joints = [plant.GetJointByName(n, instance) for n in joint_names]
        self.instance = instance
        self.root_body = root_body
        self.geometry_ids = geometry_ids

    @cached_property
    def joint_position_index(self) -> np.ndarray:
        """q index in the plant of each joint, in hand joint order."""
        return np.array([j.position_start() for j in self._joints])

    @cached_property
    def joint_velocity_index(self) -> np.ndarray:
        """v index in the plant of each joint, in hand joint order."""
        return np.array([j.velocity_start() for j in self._joints])

    def positions(self, plant, wrist: np.ndarray, q: np.ndarray) -> np.ndarray:
        """Full plant position vector for a hand alone in `plant`: wrist [xyz, wxyz] + joints."""
        full = np.zeros(plant.num_positions())
        start = self.root_body.floating_positions_start()
        full[start : start + 4] = np.asarray(wrist[3:7]) / np.linalg.norm(wrist[3:7])
        full[start + 4 : start + 7] = wrist[:3]
        full[self.joint_position_index] = q
        return full

    def set_state(self, plant, context, wrist: np.ndarray, q: np.ndarray) -> None:
        pose = RigidTransform(
            Quaternion(np.asarray(wrist[3:7]) / np.linalg.norm(wrist[3:7])), wrist[:3]
        )
        plant.SetFreeBodyPose(context, self.root_body, pose)
        positions = plant.GetPositions(context)
        positions[self.joint_position_index] = q
        plant.SetPositions(context, positions)


def _box_corners(hand, link: str) -> np.ndarray:
    """Corners (N, 3) of the link's collision boxes in the link frame."""
    boxes = [g for g in hand.tree.geoms[link] if g.kind == "box"]
    return rounded(np.concatenate([primitive_mesh(g).vertices for g in boxes]))


def thinned_hull(geom) -> np.ndarray:
    """(N, 3) link-frame vertices of a mesh geom's hull, thinned to PROGRAM_MESH_VERTICES."""
    verts = geom.vertices
    if len(verts) > PROGRAM_MESH_VERTICES:
        verts = verts[farthest_point_sample(verts, PROGRAM_MESH_VERTICES)]
    return rounded(verts @ geom.pose[:3, :3].T + geom.pose[:3, 3])


def _program_urdf(hand, links: tuple[str, ...]) -> str:
    """The hand's URDF text without the collision boxes of `links` and without meshes (the
    collision ones are added back simplified; the program draws nothing)."""
    root = ET.parse(hand.urdf_path).getroot()
    for elem in root.findall("link"):
        for shape in elem.findall("collision") + elem.findall("visual"):
            boxed = elem.get("name") in links and shape.find("geometry/box") is not None
            if (boxed and shape.tag == "collision") or shape.find("geometry/mesh") is not None:
                elem.remove(shape)
    return ET.tostring(root, encoding="unicode")


def add_hand_to_plant(
    hand, plant, scene_graph=None, filter_self_collisions: bool = True, merge_hull_links=False
) -> DrakeHand:
    """Parse the hand's URDF into `plant` (not yet finalized); call `plant.Finalize()` after
    adding everything else."""
    parser = Parser(plant)
    parser.SetAutoRenaming(True)
    hulls = hand.meta.program_hull_links if merge_hull_links else ()
    meshes = [
        (link, i, g)
        for link, geoms in hand.tree.geoms.items()
        for i, g in enumerate(geoms)
        if g.kind == "mesh"
    ]
    if merge_hull_links and (hulls or meshes):
        (instance,) = parser.AddModelsFromString(_program_urdf(hand, hulls), "urdf")
    else:
        (instance,) = parser.AddModels(str(hand.urdf_path))
    bodies = {name: plant.GetBodyByName(name, instance) for name in hand.link_names}
    for link, i, geom in meshes if merge_hull_links else ():
        plant.RegisterCollisionGeometry(
            bodies[link],
            RigidTransform(),
            Convex(thinned_hull(geom).T, f"{hand.name}_{link}_mesh{i}"),
            f"{link}_mesh{i}",
            CoulombFriction(1.0, 1.0),
        )
    for link in hulls:
        plant.RegisterCollisionGeometry(
            bodies[link],
            RigidTransform(),
            Convex(_box_corners(hand, link).T, f"{hand.name}_{link}_hull"),
            f"{link}_hull",
            CoulombFriction(1.0, 1.0),
        )
    geometry_ids = [g for b in bodies.values() for g in plant.GetCollisionGeometriesForBody(b)]
    if scene_graph is not None:
        manager = scene_graph.collision_filter_manager()
        for a, b in hand.tree.rigid_neighbour_pairs():  # as MuJoCo's parent filter does
            manager.Apply(
                CollisionFilterDeclaration().ExcludeBetween(
                    GeometrySet(plant.GetCollisionGeometriesForBody(bodies[a])),
                    GeometrySet(plant.GetCollisionGeometriesForBody(bodies[b])),
                )
            )
        if filter_self_collisions:
            manager.Apply(CollisionFilterDeclaration().ExcludeWithin(GeometrySet(geometry_ids)))
        else:
            for a, b in hand.meta.ignore_collision_pairs:
                manager.Apply(
                    CollisionFilterDeclaration().ExcludeBetween(
                        GeometrySet(plant.GetCollisionGeometriesForBody(bodies[a])),
                        GeometrySet(plant.GetCollisionGeometriesForBody(bodies[b])),
                    )
                )
    return DrakeHand(plant, instance, bodies[hand.root_link], hand.joint_names, geometry_ids)


def drake_link_poses(hand, configs: np.ndarray) -> np.ndarray:
    """(C, L, 4, 4) poses of `hand.link_names` in Drake, wrist at the identity, at joint
    configurations `configs` (C, dof): the hand as parsed from its URDF. The grasp program's
    simplified hand (merged hulls, thinned meshes, no hand-hand filter) is built too, and its
    signed distances queried once. Raises what Drake raises; HandModel.check turns that into a
    HandError naming the file."""
    from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
    from pydrake.systems.framework import DiagramBuilder

    out = np.zeros((len(configs), len(hand.link_names), 4, 4))
    wrist = np.array([0, 0, 0, 1.0, 0, 0, 0])
    for program in (False, True):
        builder = DiagramBuilder()
        plant, scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
        handle = add_hand_to_plant(
            hand, plant, scene_graph, filter_self_collisions=not program, merge_hull_links=program
        )
        plant.Finalize()
        diagram = builder.Build()
        context = plant.GetMyMutableContextFromRoot(diagram.CreateDefaultContext())
        for k, q in enumerate(configs):
            handle.set_state(plant, context, wrist, q)
            if program:
                query = plant.get_geometry_query_input_port().Eval(context)
                query.ComputeSignedDistancePairwiseClosestPoints(0.001)
                break
            for i, link in enumerate(hand.link_names):
                pose = plant.EvalBodyPoseInWorld(
                    context, plant.GetBodyByName(link, handle.instance)
                )
                out[k, i] = pose.GetAsMatrix4()
    return out
