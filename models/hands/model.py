"""HandModel: one hand described once (URDF + hand.json), used by PyTorch, Drake and MuJoCo."""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np
import torch

from models.errors import HandError
from models.hands.kinematics import Kinematics, transform_points
from models.hands.meta import HandMeta, _show, read_meta
from models.hands.surface import surface_points
from models.hands.urdf import KinematicTree, read_urdf

BUILTIN_DIR = Path(__file__).resolve().parent
N_SURFACE_POINTS = 512
# A wrist quaternion's norm may differ from 1 by this much (rounding, interpolation); it is
# normalised. Further off, or zero, it is refused: it is not a rotation the caller meant.
QUAT_NORM_TOLERANCE = 1e-2
# A 4x4 wrist's rotation block: |R^T R - I| at most this, det(R) > 0, last row 0 0 0 1.
ROTATION_TOLERANCE = 1e-3
# A user's hand is checked against MuJoCo and Drake when it loads: every link at the same pose
# in both and in the PyTorch kinematics, to this many metres (and this much in each rotation
# matrix entry).
AGREEMENT_TOLERANCE = 1e-5
MAX_HAND_SIZE = 1.0  # m across at the open pose; more is a URDF in millimetres
WRIST_LAYOUT = (
    "(7,) or (B, 7) [x, y, z, qw, qx, qy, qz] with a unit quaternion, or (4, 4) or (B, 4, 4) "
    "rigid transforms"
)


def available_hands() -> list[str]:
    """Names of the built-in hands (folders holding hand.json)."""
    return sorted(p.parent.name for p in BUILTIN_DIR.glob("*/hand.json"))


@dataclass
class HandModel:
    """A robot hand: joints, limits, batched FK, fixed surface points, simulator builders."""

    folder: Path
    meta: HandMeta
    tree: KinematicTree
    _kin: Kinematics = field(init=False, repr=False)

    def __post_init__(self) -> None:
        """hand.json against the URDF: the same joints, links that exist, an open pose within
        the limits; HandError naming hand.json, the field and the fix."""
        meta = self.folder / "hand.json"
        urdf_joints = {j.name for j in self.tree.moving_joints}
        order = set(self.meta.joint_order)
        fixed = sorted(order & {j.name for j in self.tree.joints.values() if not j.moves})
        if fixed:
            raise HandError(
                f"{meta}: joint_order names fixed joints {fixed}; list only the revolute joints"
            )
        if urdf_joints != order:
            raise HandError(
                f"{meta}: joint_order does not match the revolute joints of {self.meta.urdf}: "
                f"missing {sorted(urdf_joints - order)}, unknown {sorted(order - urdf_joints)}"
            )
        links = set(self.tree.links)
        for tip in self.meta.fingertips:
            if tip.link not in links:
                raise HandError(
                    f"{meta}: fingertip {tip.name} names unknown link {tip.link!r}; use a link "
                    f"of {self.meta.urdf}"
                )
        for a, b in self.meta.ignore_collision_pairs:
            if a not in links or b not in links:
                raise HandError(
                    f"{meta}: ignore_collision_pairs names unknown link {a}/{b}; use links of "
                    f"{self.meta.urdf}"
                )
            if a == b:
                raise HandError(
                    f"{meta}: ignore_collision_pairs pairs link {a} with itself; name two "
                    "different links"
                )
        by_name = {j.name: j for j in self.tree.moving_joints}
        outside = [
            f"{n} {self.meta.open_pose[n]:g} not in [{by_name[n].lower:g}, {by_name[n].upper:g}]"
            for n in self.meta.joint_order
            if not by_name[n].lower <= self.meta.open_pose[n] <= by_name[n].upper
        ]
        if outside:
            raise HandError(
                f"{meta}: open_pose is outside the joint limits of {self.meta.urdf}: "
                f"{'; '.join(outside)}"
            )
        for c in self.meta.couplings:
            lows = np.array([by_name[n].lower for n in c.joints]) / c.plan_ratio
            highs = np.array([by_name[n].upper for n in c.joints]) / c.plan_ratio
            if np.ptp(np.minimum(lows, highs)) > 1e-9 or np.ptp(np.maximum(lows, highs)) > 1e-9:
                raise HandError(
                    f"{meta}: coupling {c.name}: the limits of {list(c.joints)} must be "
                    "in the plan ratio, so that clipping to them keeps the coupling"
                )
        for link in self.meta.program_hull_links:
            boxes = sum(g.kind == "box" for g in self.tree.geoms.get(link, []))
            if boxes < 2:
                raise HandError(
                    f"{meta}: program_hull_links names {link!r} with {boxes} collision "
                    "boxes; list only links that have several boxes"
                )
        self._kin = Kinematics(self.tree, list(self.meta.joint_order))

    # ---- facts --------------------------------------------------------------------------
    @property
    def name(self) -> str:
        return self.meta.name

    @property
    def urdf_path(self) -> Path:
        return self.folder / self.meta.urdf

    @property
    def joint_names(self) -> list[str]:
        return list(self.meta.joint_order)

    @property
    def dof(self) -> int:
        return len(self.meta.joint_order)

    @property
    def link_names(self) -> list[str]:
        return list(self.tree.links)

    @property
    def root_link(self) -> str:
        return self.tree.root

    @cached_property
    def lower(self) -> np.ndarray:
        by_name = {j.name: j for j in self.tree.moving_joints}
        return np.array([by_name[n].lower for n in self.joint_names])

    @cached_property
    def upper(self) -> np.ndarray:
        by_name = {j.name: j for j in self.tree.moving_joints}
        return np.array([by_name[n].upper for n in self.joint_names])

    @cached_property
    def open_pose(self) -> np.ndarray:
        return np.array([self.meta.open_pose[n] for n in self.joint_names])

    @cached_property
    def closing_direction(self) -> np.ndarray:
        return np.array([self.meta.closing_direction[n] for n in self.joint_names], dtype=float)

    def closed_pose(self, fraction: float) -> np.ndarray:
        """The open pose with every joint moved `fraction` of its range (upper - lower) along
        its closing direction, within the limits: where the grasp program starts the fingers
        (0.35 for the model-based proposals, hand.json `learned_start_closure` for the learned
        samples), so they start around a part rather than flat against it."""
        span = self.upper - self.lower
        return np.clip(
            self.open_pose + fraction * self.closing_direction * span, self.lower, self.upper
        )

    @cached_property
    def coupling_basis(self) -> np.ndarray:
        """(dof, m): every joint configuration the planner may use is basis @ s. One column per
        free joint and one per coupling (its plan ratios), so J1 = J2 for a ShadowHand finger."""
        index = {n: i for i, n in enumerate(self.joint_names)}
        coupled = {n for c in self.meta.couplings for n in c.joints}
        columns = []
        for name in self.joint_names:
            if name not in coupled:
                col = np.zeros(self.dof)
                col[index[name]] = 1.0
                columns.append(col)
        for coupling in self.meta.couplings:
            col = np.zeros(self.dof)
            col[[index[n] for n in coupling.joints]] = coupling.plan_ratio
            columns.append(col)
        return np.stack(columns, axis=1)

    @cached_property
    def coupling_equalities(self) -> np.ndarray:
        """(k, dof) A with A @ q = 0 exactly when q keeps every coupling's plan ratio."""
        index = {n: i for i, n in enumerate(self.joint_names)}
        rows = []
        for c in self.meta.couplings:
            first = index[c.joints[0]]
            for name, ratio in zip(c.joints[1:], c.plan_ratio[1:], strict=True):
                row = np.zeros(self.dof)
                row[first], row[index[name]] = ratio, -c.plan_ratio[0]
                rows.append(row)
        return np.array(rows).reshape(len(rows), self.dof)

    def couple(self, q: np.ndarray) -> np.ndarray:
        """q (..., dof) moved to the nearest configuration that keeps the couplings (least
        squares), within the joint limits; q itself for a hand without couplings."""
        q = np.asarray(q, dtype=float)
        if not self.meta.couplings:
            return q
        basis = self.coupling_basis
        coupled = q @ np.linalg.pinv(basis).T @ basis.T
        return np.clip(coupled, self.lower, self.upper)

    def coupling_violation(self, q: np.ndarray) -> float:
        """Largest |A @ q| (rad): 0 for a configuration the hand's actuators can hold."""
        if not self.meta.couplings:
            return 0.0
        return float(np.max(np.abs(np.asarray(q, dtype=float) @ self.coupling_equalities.T)))

    def check_joints(self, q, what: str = "joint vector") -> None:
        """Raise HandError unless q (a torch tensor, numpy array or list) holds numbers of shape
        (..., dof) that are all finite."""
        what = f"{what} for hand {self.name}"
        # no torch for arrays: the grasp program checks here in forked processes, where torch
        # may hang after the parent's OpenMP threads (planner.parallel)
        values = _numeric(q, what).detach() if isinstance(q, torch.Tensor) else _real_array(q, what)
        shape = tuple(values.shape)
        if not shape or shape[-1] != self.dof:
            raise HandError(
                f"{what} has length {shape[-1] if shape else 0}; "
                f"expected {self.dof} values in this order: {', '.join(self.joint_names)}"
            )
        finite = torch.isfinite(values) if isinstance(values, torch.Tensor) else np.isfinite(values)
        if not bool(finite.all()):
            raise HandError(f"{what} contains NaN or infinite values")

    def batch(self, wrist, q) -> tuple[torch.Tensor, torch.Tensor]:
        """`wrist` and `q` checked and as tensors of one batch: (B, 7) or (B, 4, 4) and (B, dof).

        q: (dof,) or (B, dof), a torch tensor (kept as it is: dtype, device, gradient), numpy
        array or list of numbers. wrist: (7,) or (B, 7) [x, y, z, qw, qx, qy, qz], or (4, 4) or
        (B, 4, 4). An unbatched input counts as a batch of one, and a batch of one is repeated
        to the other's size. HandError for anything else, naming the shape expected."""
        q = _numeric(q, f"joint vector for hand {self.name}")
        if q.ndim not in (1, 2):
            raise HandError(
                f"joint vector for hand {self.name} has shape {tuple(q.shape)}; expected "
                f"({self.dof},) or (B, {self.dof}): joints {', '.join(self.joint_names)}"
            )
        self.check_joints(q)
        q = q[None] if q.ndim == 1 else q
        wrist = _numeric(wrist, f"wrist pose for hand {self.name}")
        if not q.is_floating_point():
            q = q.to(wrist.dtype if wrist.is_floating_point() else torch.float64)
        if wrist.device != q.device:
            wrist = wrist.to(q.device)
        shape = tuple(wrist.shape)
        if shape in ((7,), (4, 4)):
            wrist = wrist[None]
        elif not (len(shape) == 2 and shape[1] == 7) and not (
            len(shape) == 3 and shape[1:] == (4, 4)
        ):
            raise HandError(
                f"wrist pose for hand {self.name} has shape {shape}; expected {WRIST_LAYOUT}"
            )
        _check_wrist(wrist, self.name)
        if wrist.shape[0] != q.shape[0]:
            if wrist.shape[0] == 1:
                wrist = wrist.expand(q.shape[0], *wrist.shape[1:])
            elif q.shape[0] == 1:
                q = q.expand(wrist.shape[0], -1)
            else:
                raise HandError(
                    f"hand {self.name}: {wrist.shape[0]} wrist poses for {q.shape[0]} joint "
                    "vectors; give as many of each, or one of either"
                )
        return wrist, q

    # ---- kinematics ---------------------------------------------------------------------
    def link_poses(self, wrist, q) -> torch.Tensor:
        """(B, L, 4, 4) world poses of `link_names`, in q's dtype and on its device. wrist:
        (7,) or (B, 7) [xyz, wxyz], or (4, 4) or (B, 4, 4); q: (dof,) or (B, dof), a tensor,
        array or list (see `batch`). Always batched: unbatched inputs give B = 1."""
        wrist, q = self.batch(wrist, q)
        return self._kin.link_poses(wrist, q)

    def link_index(self, link: str) -> int:
        return self.tree.links.index(link)

    def fingertip_positions(self, wrist, q, names: list[str] | None = None) -> torch.Tensor:
        """(B, F, 3) world tip points (centres of the fingertip spheres), in `names` order
        (default: every fingertip in hand.json order); wrist and q as for `link_poses`."""
        if names is not None and (
            not isinstance(names, (list, tuple)) or not all(isinstance(n, str) for n in names)
        ):
            raise HandError(
                f"fingertip names for hand {self.name} must be a list of names from "
                f"{[t.name for t in self.meta.fingertips]}, got {names!r}"
            )
        tips = [self.meta.fingertip(n) for n in names] if names else list(self.meta.fingertips)
        idx = np.array([self.link_index(t.link) for t in tips])
        wrist, q = self.batch(wrist, q)
        local = torch.as_tensor(np.stack([t.point for t in tips]), dtype=q.dtype, device=q.device)
        return transform_points(self._kin.link_poses(wrist, q), idx, local)

    @cached_property
    def surface(self) -> tuple[np.ndarray, np.ndarray]:
        """(link index (512,), link-frame points (512, 3)): the fixed hand surface points."""
        eye = torch.zeros(1, 7, dtype=torch.float64)
        eye[0, 3] = 1
        q = torch.as_tensor(self.open_pose[None], dtype=torch.float64)
        poses = self._kin.link_poses(eye, q)[0].numpy()
        geoms = [self.tree.geoms[link] for link in self.tree.links]
        rigid = [self.link_index(self.tree.rigid_link(link)) for link in self.tree.links]
        return surface_points(geoms, poses, n=N_SURFACE_POINTS, rigid_groups=rigid)

    def surface_points(self, wrist, q) -> torch.Tensor:
        """(B, 512, 3) world positions of the fixed surface points; wrist and q as for
        `link_poses`."""
        idx, local = self.surface
        wrist, q = self.batch(wrist, q)
        return transform_points(
            self._kin.link_poses(wrist, q),
            idx,
            torch.as_tensor(local, dtype=q.dtype, device=q.device),
        )

    # ---- the load check -----------------------------------------------------------------
    def check(self) -> None:
        """Build the hand as every part of the project does: its surface points, MuJoCo's model
        (as validation simulates it) and Drake's plants (as parsed, and the grasp program's
        simplified hand), and compare every link's pose in PyTorch, MuJoCo and Drake at the open
        pose and at a seeded configuration within the limits. A HandError naming the URDF for
        anything that fails or disagrees, so a hand that loads never fails later inside a
        simulator. `load_hand` runs it for a user's hand (tests run it for the built-in ones)."""
        urdf = self.urdf_path
        try:
            idx, local = self.surface
        except HandError:
            raise
        except Exception as err:  # noqa: BLE001 - any failure here is the hand's geometry
            raise HandError(f"{urdf}: cannot sample the hand's surface points: {err}") from None
        rng = np.random.default_rng(0)
        configs = np.stack([self.open_pose, rng.uniform(self.lower, self.upper)])
        eye = torch.tensor([[0, 0, 0, 1.0, 0, 0, 0]], dtype=torch.float64).repeat(2, 1)
        ours = self._kin.link_poses(eye, torch.as_tensor(configs)).numpy()
        points = np.einsum("pij,pj->pi", ours[0, idx, :3, :3], local) + ours[0, idx, :3, 3]
        size = float(np.linalg.norm(np.ptp(points, axis=0)))
        if not size <= MAX_HAND_SIZE:
            raise HandError(
                f"{urdf}: the hand is {size:.3g} m across at its open pose; URDF lengths are "
                "metres (is the file in millimetres?)"
            )
        for simulator in ("MuJoCo", "Drake"):
            try:
                if simulator == "MuJoCo":
                    from models.hands.mujoco_spec import mujoco_link_poses as poses_in
                else:
                    from models.hands.drake import drake_link_poses as poses_in
                theirs = poses_in(self, configs)
            except Exception as err:  # noqa: BLE001 - whatever the simulator raises
                message = " ".join(str(err).split())
                hint = ""
                if "mass and inertia" in message:
                    hint = (
                        "; give every link that a joint moves an <inertial> with a mass > 0 and "
                        "a positive inertia"
                    )
                elif "inertia must satisfy" in message:
                    hint = (
                        "; a link's principal moments of inertia A, B, C must satisfy "
                        "A + B >= C (the inertia of a physical body)"
                    )
                raise HandError(
                    f"{urdf}: {simulator} cannot build this hand: {message[:400]}{hint}"
                ) from None
            diff = np.abs(theirs - ours)
            worst = np.unravel_index(int(np.argmax(diff)), diff.shape)
            if not diff.max() <= AGREEMENT_TOLERANCE:
                raise HandError(
                    f"{urdf}: {simulator} puts link {self.link_names[worst[1]]} elsewhere than "
                    f"the project's URDF reader does (by {diff.max():.3g}), so the planner and "
                    "the simulators would see different hands; use only revolute, continuous "
                    "and fixed joints, explicit axes and limits"
                )

    # ---- simulators ---------------------------------------------------------------------
    def add_to_plant(
        self,
        plant,
        scene_graph=None,
        *,
        filter_self_collisions: bool = True,
        merge_hull_links: bool = False,
    ):
        """Add the hand (floating wrist) to a Drake MultibodyPlant; see models.hands.drake."""
        from models.hands.drake import add_hand_to_plant

        return add_hand_to_plant(self, plant, scene_graph, filter_self_collisions, merge_hull_links)

    def mujoco_spec(self):
        """A fresh mujoco.MjSpec of the hand; see models.hands.mujoco_spec."""
        from models.hands.mujoco_spec import hand_spec

        return hand_spec(self)

    def actuators(self) -> list[dict]:
        """The position actuators MuJoCo gets: one per uncoupled joint, one per coupling
        (driving its tendon). {"name", "joints", "tendon" coefficients}."""
        coupled = {n for c in self.meta.couplings for n in c.joints}
        out = [
            {"name": n, "joints": [n], "tendon": [1.0]}
            for n in self.joint_names
            if n not in coupled
        ]
        out += [
            {"name": c.name, "joints": list(c.joints), "tendon": c.tendon.tolist()}
            for c in self.meta.couplings
        ]
        return out

    def describe(self) -> dict:
        """Plain-data summary (what `drograsp hands --json` prints)."""
        return {
            "name": self.name,
            "dof": self.dof,
            "joints": [
                {"name": n, "lower": float(lo), "upper": float(hi), "closing": int(c)}
                for n, lo, hi, c in zip(
                    self.joint_names, self.lower, self.upper, self.closing_direction, strict=True
                )
            ],
            "fingertips": [{"name": t.name, "link": t.link} for t in self.meta.fingertips],
            "anchor_fingers": list(self.meta.anchor_fingers),
            "links": len(self.link_names),
            "kp": self.meta.kp,
            "actuators": self.actuators(),
            "couplings": [
                {
                    "name": c.name,
                    "joints": list(c.joints),
                    "tendon": c.tendon.tolist(),
                    "plan_ratio": c.plan_ratio.tolist(),
                }
                for c in self.meta.couplings
            ],
            # how the planner closes this hand in validation, and its extra proposals
            "pregrasp_clearance": self.meta.pregrasp_clearance,
            "squeeze_depth": self.meta.squeeze_depth,
            "retry_squeeze_depths": list(self.meta.retry_squeeze_depths),
            "pinch_proposals": self.meta.pinch_proposals,
            "source": self.meta.source,
            "folder": str(self.folder),
        }


def _numeric(value, what: str) -> torch.Tensor:
    """`value` (torch tensor, numpy array, list or number) as a real-valued tensor: a tensor is
    returned as it is (ints included), anything else converted once (numpy's float dtype kept,
    whole numbers as float64). HandError for booleans, text, ragged lists and other objects."""
    if isinstance(value, torch.Tensor):
        if value.dtype == torch.bool or value.is_complex():
            raise HandError(f"{what} must hold real numbers, got a {value.dtype} tensor")
        return value
    return torch.tensor(_real_array(value, what))


def _real_array(value, what: str) -> np.ndarray:
    """`value` (numpy array, list or number) as a real numpy array (float dtype kept, whole
    numbers as float64); HandError for booleans, text, ragged lists and other objects."""
    if value is None:
        raise HandError(f"{what} must be numbers (a torch tensor, numpy array or list), got None")
    try:
        arr = np.asarray(value)
        if arr.dtype.kind == "O":
            arr = arr.astype(np.float64)
    except (ValueError, TypeError):
        raise HandError(
            f"{what} must be numbers (a torch tensor, numpy array or list of equal-length rows), "
            f"got {_show(value)}"
        ) from None
    if arr.dtype.kind in "iu":
        arr = arr.astype(np.float64)
    if arr.dtype.kind != "f":
        kind = "booleans" if arr.dtype.kind == "b" else f"{arr.dtype} values"
        raise HandError(f"{what} must hold real numbers, got {kind}: {_show(value)}")
    return arr


def _check_wrist(wrist: torch.Tensor, hand: str) -> None:
    """(B, 7) or (B, 4, 4) wrist poses: finite, unit quaternions or rigid transforms."""
    values = wrist.detach().to(device="cpu", dtype=torch.float64)
    if not bool(torch.isfinite(values).all()):
        raise HandError(f"wrist pose for hand {hand} contains NaN or infinite values")
    if values.shape[-1] == 7:
        norms = values[:, 3:7].norm(dim=-1)
        worst = int((norms - 1).abs().argmax()) if len(norms) else 0
        if len(norms) and not abs(float(norms[worst]) - 1) <= QUAT_NORM_TOLERANCE:
            what = (
                "a zero"
                if float(norms[worst]) < 1e-12
                else f"a non-unit (norm {float(norms[worst]):.4g})"
            )
            raise HandError(
                f"wrist pose {worst} for hand {hand} has {what} quaternion "
                f"{values[worst, 3:7].tolist()}; give [x, y, z, qw, qx, qy, qz] with "
                "qw^2 + qx^2 + qy^2 + qz^2 = 1"
            )
        return
    rot = values[:, :3, :3]
    gram = rot.transpose(1, 2) @ rot - torch.eye(3, dtype=torch.float64)
    last = values[:, 3] - torch.tensor([0, 0, 0, 1.0], dtype=torch.float64)
    bad = (
        (gram.abs().amax(dim=(1, 2)) > ROTATION_TOLERANCE)
        | (torch.linalg.det(rot) <= 0)
        | (last.abs().amax(dim=1) > 1e-9)
    )
    if bool(bad.any()):
        raise HandError(
            f"wrist pose {int(bad.nonzero()[0, 0])} for hand {hand} is not a rigid transform: a "
            "4x4 wrist needs a rotation block (orthonormal, det +1) and a last row 0 0 0 1"
        )


_CACHE: dict[Path, HandModel] = {}


def _hand_folder(text: str) -> Path | None:
    """The folder a hand argument names (resolved), or None."""
    candidate = Path(text).expanduser()
    if "/" not in text and (BUILTIN_DIR / text / "hand.json").is_file():
        return (BUILTIN_DIR / text).resolve()
    if candidate.is_dir():
        return candidate.resolve()
    if candidate.is_file():
        return candidate.parent.resolve()
    return None


def load_hand(name_or_path: str | Path) -> HandModel:
    """Load a built-in hand by name ("shadow", "allegro", "leap") or a user's hand from a
    folder holding hand.urdf + hand.json (or the path of either file). Cached per folder.

    A user's hand is checked as it loads (`HandModel.check`: MuJoCo and Drake build it and
    agree with the PyTorch kinematics); every problem with its files is a HandError that names
    the file, the field and what it must be."""
    if isinstance(name_or_path, Path):
        text = str(name_or_path)
    elif isinstance(name_or_path, str) and name_or_path.strip():
        text = name_or_path
    else:
        raise HandError(
            f"a hand is a built-in name ({', '.join(available_hands())}) or a folder holding "
            f"hand.urdf and hand.json, got {_show(name_or_path)}"
        )
    unknown = HandError(
        f"unknown hand {_show(text)}: built-in hands are {', '.join(available_hands())}; "
        "or give a folder holding hand.urdf and hand.json"
    )
    try:
        folder = _hand_folder(text)
    except (OSError, ValueError, RuntimeError):  # NUL bytes, names too long, ~nosuchuser
        folder = None
    if folder is None:
        raise unknown
    if folder not in _CACHE:
        meta = read_meta(folder / "hand.json")
        urdf = folder / meta.urdf
        try:
            found = urdf.is_file()
        except (OSError, ValueError):
            found = False
        if not found:
            raise HandError(
                f"{folder / 'hand.json'}: urdf names {meta.urdf!r}, which is not a file in "
                f"{folder}; give the URDF's file name (hand.urdf)"
            )
        hand = HandModel(folder, meta, read_urdf(urdf))
        if folder.parent != BUILTIN_DIR:
            hand.check()
        _CACHE[folder] = hand
    return _CACHE[folder]
