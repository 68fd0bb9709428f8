"""Put a hand into a Drake MultibodyPlant with a floating wrist.

Drake filters only parent-child collision pairs; the grasp program must not fight the
hand's own geometry, so hand-hand pairs are filtered explicitly (all of them by default,
or only the metadata's ignore list plus neighbours for self-collision checks).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.geometry import CollisionFilterDeclaration, GeometrySet
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser


@dataclass
class DrakeHand:
    """Where a hand lives in a plant: model instance, root body, joint position indices."""

    instance: object
    root_body: object
    joint_position_index: np.ndarray  # q index in the plant of each joint, in hand joint order
    geometry_ids: list

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


def add_hand_to_plant(
    hand, plant, scene_graph=None, filter_self_collisions: bool = True
) -> DrakeHand:
    """Parse the hand's URDF into `plant` (not yet finalized). Call `plant.Finalize()` after
    adding everything; indices in the returned DrakeHand are valid after finalizing."""
    parser = Parser(plant)
    parser.SetAutoRenaming(True)
    (instance,) = parser.AddModels(str(hand.urdf_path))
    bodies = {name: plant.GetBodyByName(name, instance) for name in hand.link_names}
    geometry_ids = [g for b in bodies.values() for g in plant.GetCollisionGeometriesForBody(b)]
    if scene_graph is not None:
        manager = scene_graph.collision_filter_manager()
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
    return _LazyDrakeHand(plant, instance, bodies[hand.root_link], hand.joint_names, geometry_ids)


class _LazyDrakeHand(DrakeHand):
    """DrakeHand whose joint indices are looked up on first use (after Finalize)."""

    def __init__(self, plant, instance, root_body, joint_names, geometry_ids):
        self._plant, self._names = plant, joint_names
        self.instance, self.root_body, self.geometry_ids = instance, root_body, geometry_ids
        self._index = None

    @property
    def joint_velocity_index(self) -> np.ndarray:
        """v index in the plant of each joint, in hand joint order."""
        return np.array(
            [self._plant.GetJointByName(n, self.instance).velocity_start() for n in self._names]
        )

    @property
    def joint_position_index(self) -> np.ndarray:  # type: ignore[override]
        if self._index is None:
            self._index = np.array(
                [self._plant.GetJointByName(n, self.instance).position_start() for n in self._names]
            )
        return self._index
