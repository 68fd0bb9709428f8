"""The Drake grasp program: coarse interaction elements -> exact, collision-free joint values.

A MultibodyPlant holds the hand (floating wrist; only the hand.json ignore pairs filtered, so
fingers cannot pass through each other) and the object as anchored convex pieces. One
nonlinear program (Drake InverseKinematics, solved by SNOPT) takes weighted costs (anchor
fingertips to anchor points, the palm to a palm target, hand surface points to target
positions, a wrist prior) subject to minimum hand-object and hand-hand signed distances (two
constraints) and joint limits.
SNOPT often reports failure at the optimum with many convex pieces, so every answer is checked
directly (penetration, anchor error) and the flag is only recorded.

Built diagrams are cached per (hand, object): building one costs about 0.3 s; a solve on a
procedural object takes a median 0.1-0.4 s here (eval/planner_benchmark.py).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.geometry import CollisionFilterDeclaration, Convex, GeometrySet, SceneGraph
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.inverse_kinematics import (
    InverseKinematics,
    MinimumDistanceLowerBoundConstraint,
)
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, CoulombFriction
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.solvers import SnoptSolver, SolverOptions
from pydrake.systems.framework import DiagramBuilder

from models.errors import PlanningError
from models.hands import HandModel
from models.reproducible import rounded, rounded_within
from planner.point_costs import pooled
from planner.squeeze import balanced_forces
from planner.validation.objects import CollisionObject, as_collision_object


@dataclass(frozen=True)
class ProgramSettings:
    """Weights and solver caps. Defaults follow the measurements in DESIGN.md."""

    anchor_weight: float = 100.0
    palm_weight: float = 20.0
    point_weight: float = 10.0
    wrist_position_weight: float = 1.0
    wrist_rotation_weight: float = 0.01
    joint_prior_weight: float = 1e-4
    # hand-object and hand-hand signed distance lower bound (m): about touching
    min_distance: float = 0.0005
    influence_distance: float = 0.01
    # Hand-object and hand-hand signed distances as two constraints instead of one. Drake folds
    # every pair into one smoothed penalty, so fingers lying side by side used up the budget
    # of the hand-object pairs; on 48 fixed proposals per hand, two constraints gave 25 vs 21
    # held for LEAP and 31 vs 27 for Shadow (Allegro 18 vs 21). See docs/planner_log.md, "Two
    # distance constraints".
    separate_hand_hand: bool = True
    penetration_tolerance: float = 0.002  # accepted penetration when checking an answer (m)
    # accepted fingertip-surface to anchor distance (m). Validation judges the grasp; this only
    # keeps answers that went elsewhere from using validations. On small parts (caps, rims, pump
    # and spray heads) LEAP's wide fingers cannot all reach anchors bunched on the part, and
    # answers 25-40 mm off still hold on it: 40 vs 25 mm gave returned success 89/95/95% vs
    # 89/91/95% on the test split and 88/97/95% vs 85/95/95% on the validation split.
    anchor_tolerance: float = 0.04
    # deepest hand-object penetration left at the pregrasp (m); shallower ones are not worth
    # weakening the squeeze for (GraspProgram.clear_of_object)
    pregrasp_penetration: float = 0.001
    # deepest hand-hand penetration left at the pregrasp (m): half DexGraspBench's 1 cm limit.
    # The balanced back-off swings neighbouring fingers together (Shadow's little and ring
    # distals); a 1 mm bound shrank Shadow's back-off to a third on the mug-handle test
    pregrasp_self_penetration: float = 0.005
    # interior points of the closing's joint path (pregrasp -> grasp, evenly spaced) that must
    # be as clear of the object as the pregrasp: MuJoCo interpolates the joint targets, and a
    # finger both ends of whose path are clear can sweep through the part between them
    # (ShadowHand's little finger knocking a pan handle away). 0: the pregrasp only, as before.
    # docs/planner_log.md "Coupled fingers"
    pregrasp_path_checks: int = 3
    # A pregrasp whose anchor offsets clear_of_object shrank (to keep the closing out of the
    # object) still gets the squeeze of the unshrunk offsets, depth / scale times its own
    # (Shadow's validation records: 11 of 120 candidates whose back-off had shrunk under 4 mm
    # held, 358 of 681 at 8-10 mm). False: depth x the shrunk offsets, as before.
    # docs/planner_log.md "Coupled fingers"
    full_squeeze: bool = True
    major_optimality: float = 1e-3
    major_feasibility: float = 1e-5
    major_iterations: int = 150
    # SNOPT's variable scaling (MathematicalProgram.SetVariableScaling): the size of a typical
    # step of the wrist's position (m) and of its quaternion's components. Unscaled (1 m and 1)
    # the wrist's position is hundreds of times stiffer than a finger joint, and most solves
    # ran out of major iterations 5-40% above the cost they reach at 1000; scaled, they end
    # converged in half the time (Shadow 0.134 -> 0.068 s median on 30 oracle solves) at a
    # cost 2% lower (docs/planner_log.md, "Scaled wrist variables"). 1 and 1: unscaled.
    wrist_position_scale: float = 0.02
    wrist_quaternion_scale: float = 0.1
    # How the pregrasp backs off, which sets the squeeze forces: "balanced" (fingertip forces
    # chosen to cancel, planner.squeeze) or "normal" (each fingertip straight back along its
    # normal), either by the pregrasp clearance
    pregrasp_rule: str = "balanced"
    # The closing validated once more, from a pregrasp by this rule at the hand's own squeeze
    # depth, when a grasp still slips after the squeeze retries (finish_grasp); "none": no
    # such retry, nor where it is the pregrasp rule itself. On the learned pipeline's first
    # candidates (test split, two sample seeds) it held 5/3/2 more of 100 per hand after the
    # depth retries (docs/planner_log.md, "A shallower squeeze retried")
    retry_pregrasp_rule: str = "normal"
    # squeeze = grasp + depth x (grasp - pregrasp); None: the hand's hand.json `squeeze_depth`
    # (default 1, BODex's rule)
    squeeze_depth: float | None = None
    # how far (m) the anchor fingertips back off at the pregrasp, on average: the closing travel
    # before contact, and with the depth the squeeze offset past it; None: the hand's hand.json
    # `pregrasp_clearance` (default 1 cm)
    pregrasp_clearance: float | None = None
    # other squeeze depths validated in turn when a grasp slips at `squeeze_depth`
    # (finish_grasp); None: the hand's hand.json `retry_squeeze_depths` (default none); ():
    # no retry. A depth equal to the squeeze's is skipped (the same verdict again)
    retry_squeeze_depths: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        retry = self.retry_squeeze_depths
        if retry is not None and not (
            isinstance(retry, tuple) and all(map(_positive_number, retry))
        ):
            raise PlanningError(
                "retry_squeeze_depths must be a tuple of positive numbers like (0.5, 2.0), () "
                f"for no retry, or None for the hand's own; got {retry!r}"
            )
        if self.pregrasp_rule not in PREGRASP_RULES:
            raise PlanningError(
                f"unknown pregrasp_rule {self.pregrasp_rule!r}; use one of {PREGRASP_RULES}"
            )
        if self.retry_pregrasp_rule not in (*PREGRASP_RULES, "none"):
            raise PlanningError(
                f"unknown retry_pregrasp_rule {self.retry_pregrasp_rule!r}; use one of "
                f"{(*PREGRASP_RULES, 'none')}"
            )


PREGRASP_RULES = ("balanced", "normal")


def first_closing(settings: ProgramSettings, hand: HandModel) -> tuple[float, str]:
    """The closing validated first, as (squeeze depth, pregrasp rule): the settings' squeeze
    depth, else the hand's (hand.json); a grasp recording another held only at a retry."""
    depth = settings.squeeze_depth
    return (hand.meta.squeeze_depth if depth is None else depth), settings.pregrasp_rule


def _positive_number(value: object) -> bool:
    """A finite number above 0 (not a boolean, which Python counts as an int)."""
    return isinstance(value, int | float) and not isinstance(value, bool) and 0 < value < np.inf


# (anchor-finger offset scale, other joints' scale), tried in order by clear_of_object
PREGRASP_SCALES = ((1.0, 1.0), (1.0, 0.0), (0.7, 0.0), (0.5, 0.0), (0.35, 0.0), (0.25, 0.0))


@dataclass
class SolveResult:
    """One solve, checked directly: `ok` means no penetration beyond the tolerance and every
    anchor reached; `solver_success` is SNOPT's own flag, recorded but not trusted."""

    wrist: np.ndarray  # [x, y, z, qw, qx, qy, qz]
    q: np.ndarray
    ok: bool
    min_distance: float  # smallest hand-object signed distance (negative: penetration)
    anchor_error: float  # worst |fingertip surface - anchor| (m); 0 without anchors
    solver_success: bool
    solver_status: str
    solve_time: float
    message: str = ""


@dataclass
class GraspTargets:
    """What the program should achieve. Any part may be absent.

    anchors: (4, 3) object surface points for the hand's anchor fingers (hand.json order); a
    row of NaN leaves that finger free (a pinch's fourth finger);
    anchor_normals: (4, 3) outward normals there, so the fingertip sphere rests on the point;
    point_targets: (P, 3) world targets for hand surface points `point_index` (indices into
    the 512 fixed points), e.g. from multilateration of a predicted D(R,O);
    point_weights: (P,) relative weights of those targets (x settings.point_weight), the
    distance-matching cost of D(R,O): its predicted closeness, so the points it says touch
    the object pull hardest and far points (guessed positions) barely at all. Absent: every
    target weighs 1."""

    wrist: np.ndarray
    q: np.ndarray
    anchors: np.ndarray | None = None
    anchor_normals: np.ndarray | None = None
    point_index: np.ndarray | None = None
    point_targets: np.ndarray | None = None
    point_weights: np.ndarray | None = None
    palm_target: np.ndarray | None = None  # where the palm centre should rest (enclosing grasps)
    fix_wrist: bool = False


def anchored(anchors: np.ndarray) -> np.ndarray:
    """Mask of the anchor rows that bind a finger: a row of NaN leaves that finger free (the
    last finger of a pinch proposal)."""
    return np.all(np.isfinite(anchors), axis=1)


def _normalize_wrist(wrist: np.ndarray) -> np.ndarray:
    wrist = np.asarray(wrist, dtype=float).copy()
    wrist[3:7] /= np.linalg.norm(wrist[3:7])
    return wrist


def _pose(wrist: np.ndarray) -> RigidTransform:
    return RigidTransform(Quaternion(wrist[3:7] / np.linalg.norm(wrist[3:7])), wrist[:3])


@dataclass
class GraspProgram:
    """The built diagram for one (hand, object); `solve` runs one program."""

    hand: HandModel
    obj: CollisionObject
    settings: ProgramSettings = field(default_factory=ProgramSettings)

    def __post_init__(self) -> None:
        builder = DiagramBuilder()
        plant, scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
        self.handle = self.hand.add_to_plant(
            plant, scene_graph, filter_self_collisions=False, merge_hull_links=True
        )
        world = plant.world_body()
        self._piece_index = {}  # geometry id -> its piece's index in `obj.pieces`
        for i, piece in enumerate(self.obj.pieces):
            geometry = plant.RegisterCollisionGeometry(
                world,
                RigidTransform(),
                Convex(np.asarray(piece.vertices, dtype=float).T, f"{self.obj.name}_{i}"),
                f"object_piece_{i}",
                CoulombFriction(0.6, 0.6),
            )
            self._piece_index[geometry] = i
        plant.Finalize()
        self.plant: object = plant
        self.scene_graph: SceneGraph = scene_graph
        self.diagram = builder.Build()
        self.context = self.diagram.CreateDefaultContext()
        self.plant_context = plant.GetMyMutableContextFromRoot(self.context)
        self.tips = [self.hand.meta.fingertip(n) for n in self.hand.meta.anchor_fingers]
        self.tip_frames = [
            plant.GetBodyByName(t.link, self.handle.instance).body_frame() for t in self.tips
        ]
        self.root_frame = plant.GetBodyByName(
            self.hand.root_link, self.handle.instance
        ).body_frame()
        link_idx, local = self.hand.surface
        self.point_frames = [
            plant.GetBodyByName(self.hand.link_names[i], self.handle.instance).body_frame()
            for i in link_idx
        ]
        self.point_local = local
        self.point_link = np.asarray(link_idx)
        inspector = scene_graph.model_inspector()
        root_body = plant.GetBodyByName(self.hand.root_link, self.handle.instance)
        self._palm_geoms = set(plant.GetCollisionGeometriesForBody(root_body))
        self._hand_geoms = set(self.handle.geometry_ids)
        self._inspector = inspector
        self._self_context = None
        if self.settings.separate_hand_hand:
            self._separate_hand_hand()
        self._solver = SnoptSolver()
        if not self._solver.available():
            raise PlanningError(
                "SNOPT is not available in this Drake build; install drake from PyPI"
            )

    @property
    def squeeze_depth(self) -> float:
        """The settings' squeeze depth, else the hand's (hand.json)."""
        return first_closing(self.settings, self.hand)[0]

    @property
    def retry_squeeze_depths(self) -> tuple[float, ...]:
        """The squeezes tried in turn after a slip: the settings', else the hand's, less the
        squeeze's own depth and repeats (validating the same squeeze again gives the same
        verdict)."""
        depths = self.settings.retry_squeeze_depths
        if depths is None:
            depths = self.hand.meta.retry_squeeze_depths
        return tuple(dict.fromkeys(float(d) for d in depths if d != self.squeeze_depth))

    def retry_closings(self) -> list[tuple[float, str]]:
        """The closings validated in turn after a slip, as (squeeze depth, pregrasp rule): the
        retry squeeze depths with the program's pregrasp, then the hand's own depth from a
        pregrasp by `settings.retry_pregrasp_rule` (unless "none" or the rule itself)."""
        rule = self.settings.pregrasp_rule
        closings = [(depth, rule) for depth in self.retry_squeeze_depths]
        if self.settings.retry_pregrasp_rule not in ("none", rule):
            closings.append((self.squeeze_depth, self.settings.retry_pregrasp_rule))
        return closings

    @property
    def pregrasp_clearance(self) -> float:
        """The settings' pregrasp clearance (m), else the hand's (hand.json)."""
        clearance = self.settings.pregrasp_clearance
        return self.hand.meta.pregrasp_clearance if clearance is None else clearance

    def _separate_hand_hand(self) -> None:
        """Filter hand-hand pairs out of the main context (its queries then see only hand-object
        pairs) and keep a second context of the same diagram that sees only hand-hand pairs,
        for the second distance constraint."""
        hand = GeometrySet(list(self._hand_geoms))
        objects = GeometrySet(
            [g for g in self._inspector.GetAllGeometryIds() if g not in self._hand_geoms]
        )
        main = self.scene_graph.GetMyMutableContextFromRoot(self.context)
        self.scene_graph.collision_filter_manager(main).Apply(
            CollisionFilterDeclaration().ExcludeWithin(hand)
        )
        # kept on self: the plant context below lives inside this diagram context
        self._self_diagram_context = self.diagram.CreateDefaultContext()
        other = self.scene_graph.GetMyMutableContextFromRoot(self._self_diagram_context)
        self.scene_graph.collision_filter_manager(other).Apply(
            CollisionFilterDeclaration().ExcludeBetween(hand, objects)
        )
        self._self_context = self.plant.GetMyMutableContextFromRoot(self._self_diagram_context)

    # ---- evaluation -----------------------------------------------------------------------
    def set_configuration(self, wrist: np.ndarray, q: np.ndarray) -> None:
        self.handle.set_state(self.plant, self.plant_context, _normalize_wrist(wrist), q)

    def _closest_pairs(self, context, wrist: np.ndarray, q: np.ndarray, horizon: float) -> list:
        """Signed-distance pairs within `horizon` at (wrist, q), as `context`'s filter allows."""
        self.handle.set_state(self.plant, context, _normalize_wrist(wrist), q)
        query = self.plant.get_geometry_query_input_port().Eval(context)
        return query.ComputeSignedDistancePairwiseClosestPoints(horizon)

    def hand_object_distance(
        self, wrist: np.ndarray, q: np.ndarray, fingers_only: bool = False, horizon: float = 0.1
    ) -> float:
        """Smallest signed distance between the hand (or its non-palm links) and the object."""
        best = horizon
        for pair in self._closest_pairs(self.plant_context, wrist, q, horizon):
            a, b = pair.id_A, pair.id_B
            hand_geom = a if a in self._hand_geoms else b
            if (a in self._hand_geoms) == (b in self._hand_geoms):
                continue
            if fingers_only and hand_geom in self._palm_geoms:
                continue
            best = min(best, pair.distance)
        return float(best)

    def hand_hand_distance(self, wrist: np.ndarray, q: np.ndarray, horizon: float = 0.1) -> float:
        """Smallest signed distance between two of the hand's own links (the hand.json ignore
        pairs excluded): negative where fingers are inside each other."""
        context = self.plant_context if self._self_context is None else self._self_context
        distances = [
            pair.distance
            for pair in self._closest_pairs(context, wrist, q, horizon)
            if pair.id_A in self._hand_geoms and pair.id_B in self._hand_geoms
        ]
        return float(min(distances, default=horizon))

    def contacts(
        self, wrist: np.ndarray, q: np.ndarray, threshold: float = 0.003, pieces: int | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Object-side points where the hand is within `threshold`, with the normals pointing
        into the object (the direction the hand can push): one per touching hand geometry.
        `pieces`: only the first that many pieces are the object (the rest, a table or a
        keep-out an intent adds, are no contact); None: every piece."""
        points, normals = [], []
        for pair in self._closest_pairs(self.plant_context, wrist, q, threshold):
            a_hand, b_hand = pair.id_A in self._hand_geoms, pair.id_B in self._hand_geoms
            if a_hand == b_hand:
                continue
            # nhat_BA_W points from B toward A; world-anchored object pieces have identity pose
            obj_id, p_obj, n_into = (
                (pair.id_B, pair.p_BCb, -pair.nhat_BA_W)
                if a_hand
                else (pair.id_A, pair.p_ACa, pair.nhat_BA_W)
            )
            if pieces is not None and self._piece_index[obj_id] >= pieces:
                continue
            if not np.all(np.isfinite(n_into)):  # Drake's normal is undefined at exact touch
                continue
            pose = self._inspector.GetPoseInFrame(obj_id)
            points.append(pose.multiply(p_obj))
            normals.append(n_into)
        return np.asarray(points).reshape(-1, 3), np.asarray(normals).reshape(-1, 3)

    def tip_centres(self, wrist: np.ndarray, q: np.ndarray) -> np.ndarray:
        """(4, 3) world centres of the anchor fingertip spheres, in anchor-finger order."""
        self.set_configuration(wrist, q)
        world = self.plant.world_frame()
        return np.array(
            [
                self.plant.CalcPointsPositions(
                    self.plant_context, frame, tip.point[:, None], world
                )[:, 0]
                for tip, frame in zip(self.tips, self.tip_frames, strict=True)
            ]
        )

    def anchor_error(self, wrist: np.ndarray, q: np.ndarray, anchors: np.ndarray) -> float:
        """Worst fingertip-surface to anchor distance over the anchored fingers (rows of NaN
        are free fingers)."""
        centres = self.tip_centres(wrist, q)
        radii = np.array([t.radius for t in self.tips])
        used = anchored(anchors)
        gaps = np.abs(np.linalg.norm(centres[used] - anchors[used], axis=1) - radii[used])
        return float(np.max(gaps, initial=0.0))

    # ---- the program ----------------------------------------------------------------------
    def solve(self, targets: GraspTargets) -> SolveResult:
        s = self.settings
        start = time.perf_counter()
        wrist0 = rounded(_normalize_wrist(targets.wrist))
        # every input rounded (models.reproducible), whoever built the targets
        self.hand.check_joints(np.asarray(targets.q), "initial joints")
        q0 = rounded_within(self.hand.couple(targets.q), self.hand.lower, self.hand.upper)
        plant, world = self.plant, self.plant.world_frame()
        ik = InverseKinematics(plant, self.plant_context, with_joint_limits=True)
        prog, qvar = ik.prog(), ik.q()
        x0 = rounded(self.handle.positions(plant, wrist0, q0))
        joints = self.handle.joint_position_index
        if targets.anchors is not None:
            anchors = rounded(targets.anchors)
            centres = anchors.copy()
            if targets.anchor_normals is not None:
                normals = np.asarray(targets.anchor_normals, dtype=float)
                normals = normals / np.linalg.norm(normals, axis=1, keepdims=True)
                radii = np.array([t.radius for t in self.tips])[:, None]
                centres = rounded(anchors + normals * (radii + s.min_distance))
            for tip, frame, centre, bound in zip(
                self.tips, self.tip_frames, centres, anchored(centres), strict=True
            ):
                if bound:
                    ik.AddPositionCost(world, centre, frame, tip.point, s.anchor_weight * np.eye(3))
        if targets.palm_target is not None:
            ik.AddPositionCost(
                world,
                rounded(targets.palm_target),
                self.root_frame,
                self.hand.meta.palm.center,
                s.palm_weight * np.eye(3),
            )
        if targets.point_targets is not None:
            weights = np.ones(len(targets.point_index))
            if targets.point_weights is not None:
                weights = rounded(np.asarray(targets.point_weights, dtype=float))
                if weights.shape != (len(targets.point_index),) or not np.all(weights >= 0):
                    raise PlanningError(
                        f"point_weights of shape {weights.shape} (or negative): expected "
                        f"{len(targets.point_index)} weights >= 0, one per point target"
                    )
            costs = pooled(
                self.point_link,
                self.point_local,
                targets.point_index,
                rounded(targets.point_targets),
                weights,
            )
            for i, local, target, w in zip(
                costs.point, costs.local, costs.targets, costs.weights, strict=True
            ):
                ik.AddPositionCost(
                    world, target, self.point_frames[i], local, s.point_weight * w * np.eye(3)
                )
        start_wrist = self.handle.root_body.floating_positions_start()
        wrist_vars = qvar[start_wrist : start_wrist + 7]  # qw qx qy qz x y z
        for i, var in enumerate(wrist_vars):
            scale = s.wrist_quaternion_scale if i < 4 else s.wrist_position_scale
            prog.SetVariableScaling(var, scale)
        if targets.fix_wrist:
            prog.AddBoundingBoxConstraint(
                x0[start_wrist : start_wrist + 7], x0[start_wrist : start_wrist + 7], wrist_vars
            )
        else:
            ik.AddPositionCost(
                world, wrist0[:3], self.root_frame, np.zeros(3), s.wrist_position_weight * np.eye(3)
            )
            ik.AddOrientationCost(
                world,
                RotationMatrix(Quaternion(wrist0[3:7])),
                self.root_frame,
                RotationMatrix(),
                s.wrist_rotation_weight,
            )
        prog.AddQuadraticErrorCost(s.joint_prior_weight * np.eye(len(joints)), q0, qvar[joints])
        couplings = self.hand.coupling_equalities  # joints one actuator drives (hand.json)
        if len(couplings):
            prog.AddLinearEqualityConstraint(couplings, np.zeros(len(couplings)), qvar[joints])
        ik.AddMinimumDistanceLowerBoundConstraint(s.min_distance, s.influence_distance)
        if self._self_context is not None:
            prog.AddConstraint(
                MinimumDistanceLowerBoundConstraint(
                    plant, s.min_distance, self._self_context, None, s.influence_distance
                ),
                qvar,
            )
        options = SolverOptions()
        sid = self._solver.solver_id()
        options.SetOption(sid, "Major optimality tolerance", s.major_optimality)
        options.SetOption(sid, "Major feasibility tolerance", s.major_feasibility)
        options.SetOption(sid, "Major iterations limit", s.major_iterations)
        result = self._solver.Solve(prog, x0, options)
        x = result.GetSolution(qvar)
        wrist = np.concatenate(
            [x[start_wrist + 4 : start_wrist + 7], x[start_wrist : start_wrist + 4]]
        )
        wrist = rounded(_normalize_wrist(wrist))
        # exactly on the couplings (the solver meets the equalities to its tolerance only)
        q = rounded_within(self.hand.couple(x[joints]), self.hand.lower, self.hand.upper)
        distance = self.hand_object_distance(wrist, q)
        anchor_err = (
            0.0
            if targets.anchors is None
            else self.anchor_error(wrist, q, np.asarray(targets.anchors))
        )
        problems = []
        if distance < -s.penetration_tolerance:
            problems.append(f"penetration {-distance * 1000:.1f} mm")
        if anchor_err > s.anchor_tolerance:
            problems.append(f"anchor error {anchor_err * 1000:.1f} mm")
        return SolveResult(
            wrist=wrist,
            q=q,
            ok=not problems,
            min_distance=distance,
            anchor_error=anchor_err,
            solver_success=result.is_success(),
            solver_status=str(result.get_solution_result()).split(".")[-1],
            solve_time=time.perf_counter() - start,
            message="; ".join(problems),
        )

    # ---- pregrasp and squeeze -------------------------------------------------------------
    def pregrasp(
        self,
        wrist: np.ndarray,
        q: np.ndarray,
        tip_normals: np.ndarray | None = None,
        clearance: float | None = None,
    ) -> np.ndarray:
        """The pregrasp of `closing`, without its scale."""
        return self.closing(wrist, q, tip_normals, clearance)[0]

    def closing(
        self,
        wrist: np.ndarray,
        q: np.ndarray,
        tip_normals: np.ndarray | None = None,
        clearance: float | None = None,
        rule: str | None = None,
    ) -> tuple[np.ndarray, float]:
        """BODex's pregrasp: the grasp with contacts about `clearance` (default: the
        `pregrasp_clearance` property) off the surface, same wrist, so that the squeeze (grasp
        + depth x (grasp - pregrasp)) presses. With the object's outward
        normals at the anchor fingertips, each finger's joints move by the offset that sets its
        squeeze force (`rule`, default `settings.pregrasp_rule`, see planner.squeeze), scaled so
        the fingertips back off `clearance` along their normals on average; the other joints
        move toward the open pose by 0.3 of the way. Where that puts a link inside the object,
        or the closing through it, the offsets shrink (clear_of_object).

        Returns the pregrasp and the scale of its anchor offsets (1 unless they shrank), for
        `squeeze(..., scale=scale)`."""
        q = np.asarray(q, dtype=float)
        if clearance is None:
            clearance = self.pregrasp_clearance
        if tip_normals is None:
            pre, scale = self._pregrasp_toward_open(wrist, q, clearance), 1.0
        else:
            pre, scale = self._balanced_or_normal_pregrasp(
                wrist, q, np.asarray(tip_normals), clearance, rule or self.settings.pregrasp_rule
            )
        return rounded_within(pre, self.hand.lower, self.hand.upper), scale  # reproducible

    def _balanced_or_normal_pregrasp(
        self,
        wrist: np.ndarray,
        q: np.ndarray,
        tip_normals: np.ndarray,
        clearance: float,
        rule: str,
    ) -> tuple[np.ndarray, float]:
        """The pregrasp from the fingertips' normals, by `rule` (PREGRASP_RULES), and the
        scale clear_of_object left its anchor offsets at."""
        centres = self.tip_centres(wrist, q)  # also sets the configuration
        plant, world = self.plant, self.plant.world_frame()
        joints = self.handle.joint_velocity_index
        normals = np.asarray(tip_normals, dtype=float)
        normals = normals / np.linalg.norm(normals, axis=1, keepdims=True)
        jacobians = [
            plant.CalcJacobianTranslationalVelocity(
                self.plant_context, JacobianWrtVariable.kV, frame, tip.point, world, world
            )[:, joints]
            for tip, frame in zip(self.tips, self.tip_frames, strict=True)
        ]
        if rule == "balanced":
            radii = np.array([t.radius for t in self.tips])[:, None]
            forces, _ = balanced_forces(centres - radii * normals, -normals)
        delta = np.zeros(self.hand.dof)
        moved = np.zeros(self.hand.dof, dtype=bool)
        backoff = []  # each fingertip's motion along its outward normal, pregrasp - grasp
        for i, jac in enumerate(jacobians):
            cols = np.flatnonzero(np.abs(jac).sum(axis=0) > 1e-9)
            cols = cols[~moved[cols]]  # joints shared with an earlier finger stay put
            j = jac[:, cols]
            if rule == "balanced":
                # position control: torque = kp x (squeeze - q) = kp x (q - pregrasp), and a
                # fingertip force f needs torque J^T f, so the offset is proportional to J^T f
                step = -(j.T @ forces[i])
            else:  # the fingertip straight back along its normal (damped least squares)
                step = j.T @ np.linalg.solve(j @ j.T + 1e-4 * np.eye(3), normals[i])
            full = np.zeros(self.hand.dof)
            full[cols] = step
            full = self._coupled_step(full)  # joints one actuator drives move together
            delta += full
            moved[cols] = True
            backoff.append(float(normals[i] @ (jac @ full)))
        delta *= clearance / max(float(np.mean(backoff)), 1e-9)
        rest = ~moved
        delta[rest] = 0.3 * (self.hand.open_pose[rest] - q[rest])
        return self._clear_of_object(wrist, q, delta, moved)

    def _coupled_step(self, step: np.ndarray) -> np.ndarray:
        """A joint offset moved onto the hand's couplings (least squares): the step a tendon
        shared by two joints can make (models.hands.HandModel.coupling_basis)."""
        if not self.hand.meta.couplings:
            return step
        basis = self.hand.coupling_basis
        return basis @ (np.linalg.pinv(basis) @ step)

    def clear_of_object(
        self, wrist: np.ndarray, q: np.ndarray, delta: np.ndarray, anchor_joints: np.ndarray
    ) -> np.ndarray:
        """The pregrasp of `_clear_of_object`, without its scale."""
        return self._clear_of_object(wrist, q, delta, anchor_joints)[0]

    def _clear_of_object(
        self, wrist: np.ndarray, q: np.ndarray, delta: np.ndarray, anchor_joints: np.ndarray
    ) -> tuple[np.ndarray, float]:
        """The pregrasp q + delta, shrunk until no link is deeper in the object, nor in another
        link, than `settings.pregrasp_penetration` (or than at the grasp, if deeper there).

        MuJoCo starts the closing from the pregrasp, so a link inside the object kicks it away
        before any finger closes: on the 300 test pairs 107 of Shadow's 228 validated candidates
        (30 of Allegro's 261) had a pregrasp over 1 mm deep, and 3 of them held. The offsets
        that back the fingertips off can swing a middle or distal link into the part (mug
        handles), and opening a non-anchor finger can push it in (Shadow's little finger). The
        other joints are kept at the grasp first, then the anchor offsets are scaled down
        together, which keeps the squeeze forces' balance and only weakens them.

        The closing passes through configurations between the pregrasp and the grasp too (the
        validator interpolates the joint targets): `settings.pregrasp_path_checks` evenly
        spaced ones must keep the same bound on the object. On all-validated Shadow records of
        the validation and train splits 59 of the 60 candidates whose path went more than 2 mm
        deeper than its ends slipped, against 57% of the others (docs/planner_log.md "Coupled
        fingers").

        Returns the pregrasp and the anchor offsets' scale in it."""
        bound = min(-self.settings.pregrasp_penetration, self.hand_object_distance(wrist, q))
        path = np.arange(1, self.settings.pregrasp_path_checks + 1)
        path = path / (self.settings.pregrasp_path_checks + 1)
        # DexGraspBench also fails a pregrasp whose fingers are inside each other (> 1 cm)
        self_bound = min(
            -self.settings.pregrasp_self_penetration, self.hand_hand_distance(wrist, q)
        )
        best, best_margin, tried = None, -np.inf, None
        for anchor_scale, rest_scale in PREGRASP_SCALES:
            pre = np.clip(
                q + np.where(anchor_joints, anchor_scale, rest_scale) * delta,
                self.hand.lower,
                self.hand.upper,
            )
            if tried is not None and np.array_equal(pre, tried):
                continue  # e.g. no joints outside the anchor fingers (Allegro, LEAP)
            tried = pre
            margin = min(
                self.hand_object_distance(wrist, pre) - bound,
                self.hand_hand_distance(wrist, pre) - self_bound,
            )
            if margin >= 0 and len(path):  # the way from there to the grasp
                margin = min(self.hand_object_distance(wrist, pre + a * (q - pre)) for a in path)
                margin -= bound
            if margin >= 0:
                return pre, anchor_scale
            if margin > best_margin:
                best, best_margin = (pre, anchor_scale), margin
        return best

    def _pregrasp_toward_open(
        self, wrist: np.ndarray, q: np.ndarray, clearance: float
    ) -> np.ndarray:
        """Joints on the way to the open pose where the fingers first clear the object."""
        open_q = self.hand.open_pose
        for alpha in np.linspace(0, 1, 21)[1:]:
            candidate = q + alpha * (open_q - q)
            if self.hand_object_distance(wrist, candidate, fingers_only=True) >= clearance:
                return candidate
        return open_q.copy()

    def squeeze(
        self,
        q: np.ndarray,
        pregrasp: np.ndarray,
        depth: float | None = None,
        scale: float = 1.0,
    ) -> np.ndarray:
        """squeeze = grasp + depth x (grasp - pregrasp) (BODex's rule at depth 1), within limits:
        the position targets past the contacts are what make the fingers press. `depth`: the
        program's squeeze depth unless given (the retry's). `scale`: the pregrasp's anchor
        offset scale (`closing`); with `settings.full_squeeze` a pregrasp shrunk to clear the
        object is squeezed depth / scale times its offsets, as deep as unshrunk."""
        depth = self.squeeze_depth if depth is None else depth
        if self.settings.full_squeeze:
            depth = depth / scale
        return np.clip((1 + depth) * q - depth * pregrasp, self.hand.lower, self.hand.upper)


_PROGRAMS: dict[tuple, GraspProgram] = {}
_MAX_PROGRAMS = 16


def forget_programs() -> None:
    """Drop the cached programs: for timings in which every plan builds its own
    (eval.plan_time), as a plan on a new object does."""
    _PROGRAMS.clear()


def grasp_program(hand: HandModel, obj, settings: ProgramSettings | None = None) -> GraspProgram:
    """The cached program for (hand, object, settings): built once, reused by every solve."""
    obj = as_collision_object(obj)
    settings = settings or ProgramSettings()
    key = (str(hand.folder), obj.key, settings)
    if key not in _PROGRAMS:
        if len(_PROGRAMS) >= _MAX_PROGRAMS:
            _PROGRAMS.pop(next(iter(_PROGRAMS)))
        _PROGRAMS[key] = GraspProgram(hand, obj, settings)
    return _PROGRAMS[key]
