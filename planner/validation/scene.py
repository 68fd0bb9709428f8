"""The compiled MuJoCo scene of one hand and one object under a protocol, cached per process.

Compiling is the slow part of a small test (meshes, hulls, inertia), so a scene is built once per
(hand, object, physics settings) and reused for every grasp and every object pose: the object
sits at the origin of the spec and its pose goes into qpos.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass

import mujoco
import numpy as np

from models.errors import HandError
from planner.validation.hands import FREE_JOINT, MOCAP_BODY, WELD, WELD_DATA, HandAdapter
from planner.validation.objects import CollisionObject
from planner.validation.protocol import Protocol

OBJECT_BODY = "object"
OBJECT_JOINT = "object_free"

_INTEGRATORS = {
    "euler": mujoco.mjtIntegrator.mjINT_EULER,
    "implicit": mujoco.mjtIntegrator.mjINT_IMPLICIT,
    "implicitfast": mujoco.mjtIntegrator.mjINT_IMPLICITFAST,
    "rk4": mujoco.mjtIntegrator.mjINT_RK4,
}
_SOLVERS = {
    "newton": mujoco.mjtSolver.mjSOL_NEWTON,
    "cg": mujoco.mjtSolver.mjSOL_CG,
    "pgs": mujoco.mjtSolver.mjSOL_PGS,
}
_CONES = {"elliptic": mujoco.mjtCone.mjCONE_ELLIPTIC, "pyramidal": mujoco.mjtCone.mjCONE_PYRAMIDAL}
_JACOBIANS = {
    "dense": mujoco.mjtJacobian.mjJAC_DENSE,
    "sparse": mujoco.mjtJacobian.mjJAC_SPARSE,
    "auto": mujoco.mjtJacobian.mjJAC_AUTO,
}


@dataclass
class Scene:
    """A compiled hand + object model with the addresses the validator reads and writes."""

    model: mujoco.MjModel
    data: mujoco.MjData
    scratch: mujoco.MjData
    joint_qpos: np.ndarray  # qpos address of each grasp joint
    joint_dof: np.ndarray  # dof address of each grasp joint
    wrist_qpos: int
    mocap: int
    object_body: int
    object_qpos: int
    object_dof: int  # dof address of the object's free joint (3 linear, then 3 angular)
    object_geoms: np.ndarray
    hand_body: np.ndarray  # bool per body: part of the hand
    object_mass: float


# MuJoCo's arena for contacts and constraints (`<size memory>`; its default is sized from the
# model, 15 MB for LEAP with a can's pieces): a closing LEAP hand on the pieces of a
# single-view cloud of a YCB soup can made 422 contacts and 1106 constraint rows and aborted
# the validation with "mj_stackAlloc: out of memory" (eval.real_objects). Only what is
# reserved changes: the simulation is the same.
ARENA_BYTES = 256 * 2**20


def _configure(spec: mujoco.MjSpec, protocol: Protocol) -> None:
    opt = spec.option
    opt.timestep = protocol.timestep
    opt.integrator = _INTEGRATORS[protocol.integrator]
    opt.solver = _SOLVERS[protocol.solver]
    opt.cone = _CONES[protocol.cone]
    opt.jacobian = _JACOBIANS[protocol.jacobian]
    opt.impratio = protocol.impratio
    opt.noslip_iterations = protocol.noslip_iterations
    opt.disableflags = 0 if protocol.gravity else int(mujoco.mjtDisableBit.mjDSBL_GRAVITY)
    for geom in spec.geoms:
        geom.friction[:2] = protocol.friction
        geom.condim = protocol.condim


def _add_object(spec: mujoco.MjSpec, obj: CollisionObject, density: float) -> None:
    body = spec.worldbody.add_body(name=OBJECT_BODY)
    body.add_freejoint(name=OBJECT_JOINT)
    for i, piece in enumerate(obj.pieces):
        mesh_name = f"object_piece_{i}"
        kwargs = {"uservert": piece.vertices.ravel().tolist()}
        if piece.faces is not None:
            kwargs["userface"] = piece.faces.ravel().tolist()
        spec.add_mesh(name=mesh_name, **kwargs)
        body.add_geom(
            name=f"object_collision_{i}",
            type=mujoco.mjtGeom.mjGEOM_MESH,
            meshname=mesh_name,
            density=density,
        )


def build_scene(hand: HandAdapter, obj: CollisionObject, protocol: Protocol) -> Scene:
    """Compile hand + object: hand geoms stiff (protocol solimp/solref), mass by density."""
    spec = hand.spec_factory()
    for geom in spec.geoms:  # only the hand's geoms exist yet
        geom.solimp[:3] = protocol.hand_solimp
        geom.solref[:2] = protocol.hand_solref
    for eq in spec.equalities:
        if eq.name == WELD:
            # Anchor 0 and relpose from qpos0 (MuJoCo's XML defaults; MjSpec's API default
            # anchor is (0, 1, 0)), and the protocol's weld impedance.
            eq.data[:] = WELD_DATA
            eq.solimp[:] = protocol.weld_solimp
    volume = obj.mass_volume()
    if not volume > 0:
        from models.errors import ObjectError

        raise ObjectError(f"object {obj.name!r} has zero volume; cannot set its mass")
    _add_object(spec, obj, protocol.object_mass / volume)
    _configure(spec, protocol)
    spec.memory = max(spec.memory, ARENA_BYTES)
    try:
        model = spec.compile()
    except ValueError as err:
        raise HandError(
            f"cannot compile hand {hand.name!r} with object {obj.name!r}: {err}"
        ) from None

    def joint_id(name: str) -> int:
        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
        if jid < 0:
            raise HandError(f"hand {hand.name!r} has no joint {name!r} in its MuJoCo model")
        return jid

    joints = [joint_id(n) for n in hand.spec_joint_names]
    wrist = joint_id(FREE_JOINT)
    obj_joint = joint_id(OBJECT_JOINT)
    mocap_body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, MOCAP_BODY)
    if mocap_body < 0 or model.body_mocapid[mocap_body] < 0:
        raise HandError(f"hand {hand.name!r} has no mocap body {MOCAP_BODY!r}")
    object_body = int(model.jnt_bodyid[obj_joint])
    hand_root = int(model.jnt_bodyid[wrist])
    hand_body = np.zeros(model.nbody, dtype=bool)
    for b in range(model.nbody):  # bodies in the subtree of the hand root
        a = b
        while a > 0 and a != hand_root:
            a = int(model.body_parentid[a])
        hand_body[b] = a == hand_root
    return Scene(
        model=model,
        data=mujoco.MjData(model),
        scratch=mujoco.MjData(model),
        joint_qpos=np.array([model.jnt_qposadr[j] for j in joints], dtype=int),
        joint_dof=np.array([model.jnt_dofadr[j] for j in joints], dtype=int),
        wrist_qpos=int(model.jnt_qposadr[wrist]),
        mocap=int(model.body_mocapid[mocap_body]),
        object_body=object_body,
        object_qpos=int(model.jnt_qposadr[obj_joint]),
        object_dof=int(model.jnt_dofadr[obj_joint]),
        object_geoms=np.flatnonzero(model.geom_bodyid == object_body),
        hand_body=hand_body,
        object_mass=float(model.body_subtreemass[object_body]),
    )


_CACHE: OrderedDict[tuple, Scene] = OrderedDict()
_CACHE_SIZE = 32


def get_scene(hand: HandAdapter, obj: CollisionObject, protocol: Protocol) -> Scene:
    """The cached scene for (hand, object, physics settings), compiled on first use."""
    key = (hand.key or hand.name, obj.key or obj.name, protocol.physics_key())
    scene = _CACHE.get(key)
    if scene is None:
        scene = build_scene(hand, obj, protocol)
        _CACHE[key] = scene
        while len(_CACHE) > _CACHE_SIZE:
            _CACHE.popitem(last=False)
    else:
        _CACHE.move_to_end(key)
    return scene
