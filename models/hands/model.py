"""HandModel: one hand described once (URDF + hand.json), used by PyTorch, Drake and MuJoCo."""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np
import torch

from models.errors import HandError
from models.hands.kinematics import Kinematics, transform_points
from models.hands.meta import HandMeta, read_meta
from models.hands.surface import surface_points
from models.hands.urdf import KinematicTree, read_urdf

BUILTIN_DIR = Path(__file__).resolve().parent
N_SURFACE_POINTS = 512


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
        urdf_joints = {j.name for j in self.tree.moving_joints}
        order = set(self.meta.joint_order)
        fixed = sorted(order & {j.name for j in self.tree.joints.values() if not j.moves})
        if fixed:
            raise HandError(
                f"{self.folder}: hand.json joint_order names fixed joints {fixed}; list only "
                "the revolute joints"
            )
        if urdf_joints != order:
            raise HandError(
                f"{self.folder}: hand.json joint_order does not match the URDF joints: "
                f"missing {sorted(urdf_joints - order)}, unknown {sorted(order - urdf_joints)}"
            )
        links = set(self.tree.links)
        for tip in self.meta.fingertips:
            if tip.link not in links:
                raise HandError(
                    f"{self.folder}: fingertip {tip.name} names unknown link {tip.link}"
                )
        for a, b in self.meta.ignore_collision_pairs:
            if a not in links or b not in links:
                raise HandError(f"{self.folder}: ignore_collision_pairs names unknown link {a}/{b}")
        by_name = {j.name: j for j in self.tree.moving_joints}
        for c in self.meta.couplings:
            lows = np.array([by_name[n].lower for n in c.joints]) / c.plan_ratio
            highs = np.array([by_name[n].upper for n in c.joints]) / c.plan_ratio
            if np.ptp(np.minimum(lows, highs)) > 1e-9 or np.ptp(np.maximum(lows, highs)) > 1e-9:
                raise HandError(
                    f"{self.folder}: coupling {c.name}: the limits of {list(c.joints)} must be "
                    "in the plan ratio, so that clipping to them keeps the coupling"
                )
        for link in self.meta.program_hull_links:
            boxes = sum(g.kind == "box" for g in self.tree.geoms.get(link, []))
            if boxes < 2:
                raise HandError(
                    f"{self.folder}: program_hull_links names {link!r} with {boxes} collision "
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

    def check_joints(self, q: np.ndarray | torch.Tensor, what: str = "joint vector") -> None:
        """Raise HandError unless q has shape (..., dof) and finite values."""
        shape = tuple(q.shape)
        if not shape or shape[-1] != self.dof:
            raise HandError(
                f"{what} for hand {self.name} has length {shape[-1] if shape else 0}; "
                f"expected {self.dof} values in this order: {', '.join(self.joint_names)}"
            )
        values = q.detach().cpu().numpy() if isinstance(q, torch.Tensor) else np.asarray(q)
        if not np.all(np.isfinite(values)):
            raise HandError(f"{what} for hand {self.name} contains NaN or infinite values")

    # ---- kinematics ---------------------------------------------------------------------
    def link_poses(self, wrist: torch.Tensor, q: torch.Tensor) -> torch.Tensor:
        """(B, L, 4, 4) world poses of `link_names`; wrist (B, 7) [xyz, wxyz] or (B, 4, 4)."""
        self.check_joints(q)
        return self._kin.link_poses(wrist, q)

    def link_index(self, link: str) -> int:
        return self.tree.links.index(link)

    def fingertip_positions(
        self, wrist: torch.Tensor, q: torch.Tensor, names: list[str] | None = None
    ) -> torch.Tensor:
        """(B, F, 3) world tip points (centres of the fingertip spheres), in `names` order
        (default: every fingertip in hand.json order)."""
        tips = [self.meta.fingertip(n) for n in names] if names else list(self.meta.fingertips)
        idx = np.array([self.link_index(t.link) for t in tips])
        local = torch.as_tensor(np.stack([t.point for t in tips]), dtype=q.dtype, device=q.device)
        return transform_points(self.link_poses(wrist, q), idx, local)

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

    def surface_points(self, wrist: torch.Tensor, q: torch.Tensor) -> torch.Tensor:
        """(B, 512, 3) world positions of the fixed surface points."""
        idx, local = self.surface
        return transform_points(
            self.link_poses(wrist, q), idx, torch.as_tensor(local, dtype=q.dtype, device=q.device)
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
            "retry_squeeze_depth": self.meta.retry_squeeze_depth,
            "pinch_proposals": self.meta.pinch_proposals,
            "source": self.meta.source,
            "folder": str(self.folder),
        }


_CACHE: dict[Path, HandModel] = {}


def load_hand(name_or_path: str | Path) -> HandModel:
    """Load a built-in hand by name ("shadow", "allegro", "leap") or a user's hand from a
    folder holding hand.urdf + hand.json (or the path of either file). Cached per folder."""
    text = str(name_or_path)
    candidate = Path(text).expanduser()
    if (BUILTIN_DIR / text / "hand.json").is_file() and "/" not in text:
        folder = BUILTIN_DIR / text
    elif candidate.is_dir():
        folder = candidate
    elif candidate.is_file():
        folder = candidate.parent
    else:
        raise HandError(
            f"unknown hand {text!r}: built-in hands are {', '.join(available_hands())}; "
            "or give a folder holding hand.urdf and hand.json"
        )
    folder = folder.resolve()
    if folder not in _CACHE:
        meta = read_meta(folder / "hand.json")
        _CACHE[folder] = HandModel(folder, meta, read_urdf(folder / meta.urdf))
    return _CACHE[folder]
