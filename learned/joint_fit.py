"""From hand point targets to a hand configuration without collision constraints: D(R,O)
Grasp's last step, kept for the "without Drake" ablation (eval.benchmark `no_drake`).

D(R,O) Grasp places every hand surface point (multilateration + per-link Kabsch,
learned.multilateration) and then finds the wrist pose and joints whose points best match
those targets, within the joint limits and nothing else: no collision with the object, no
self-collision. This module does that fit by least squares on the hand's differentiable
forward kinematics (models.hands.HandModel.surface_points): the wrist translation and
quaternion (normalised inside the loss) and the joints through the hand's coupling basis
(so a ShadowHand finger keeps J1 = J2), held near the limits by a penalty and clipped to
them at the end, L-BFGS from the first stage's
wrist and the open pose.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import torch

from learned.threads import one_thread
from models.errors import DrograspError
from models.hands import HandModel

# m^2 per rad^2: a joint beyond its limit costs as much as the points being this far off; the
# answer is clipped to the limits at the end, so the penalty only keeps it near them
LIMIT_WEIGHT = 1.0


class JointFitError(DrograspError, ValueError):
    """Targets of the wrong shape for the joint fit."""


@dataclass(frozen=True)
class JointFit:
    """The fitted configuration and how well its points reach the targets."""

    wrist: np.ndarray  # (7,) [x, y, z, qw, qx, qy, qz]
    q: np.ndarray  # (dof,) within the limits, on the couplings
    rms_error: float  # m: weighted root mean square distance of the points to their targets
    iterations: int
    fit_time: float


@one_thread
def fit_configuration(
    hand: HandModel,
    wrist: np.ndarray,
    q: np.ndarray,
    index: np.ndarray,
    targets: np.ndarray,
    weights: np.ndarray | None = None,
    iterations: int = 200,
) -> JointFit:
    """The wrist and joints whose surface points `index` (into the hand's 512 fixed points) come
    nearest (weighted least squares) to `targets` (P, 3), starting from `wrist` (7,) and `q`
    (dof,). Joint limits and couplings are kept; collisions are not looked at."""
    index = np.asarray(index, dtype=np.int64)
    targets = np.asarray(targets, dtype=np.float64)
    if targets.shape != (len(index), 3) or not np.isfinite(targets).all():
        raise JointFitError(
            f"targets of shape {targets.shape} for {len(index)} point indices: expected "
            f"({len(index)}, 3) finite positions in metres"
        )
    start = time.perf_counter()
    basis = torch.as_tensor(hand.coupling_basis, dtype=torch.float64)  # (dof, m)
    lower = torch.as_tensor(hand.lower, dtype=torch.float64)
    upper = torch.as_tensor(hand.upper, dtype=torch.float64)
    s0 = np.linalg.pinv(hand.coupling_basis) @ hand.couple(np.asarray(q, dtype=float))
    shape = torch.tensor(s0, dtype=torch.float64, requires_grad=True)
    pos = torch.tensor(np.asarray(wrist[:3], dtype=float), requires_grad=True)
    quat = torch.tensor(np.asarray(wrist[3:7], dtype=float), requires_grad=True)
    goal = torch.as_tensor(targets)
    w = torch.ones(len(index), dtype=torch.float64) if weights is None else torch.as_tensor(weights)
    w = w / w.sum().clamp_min(1e-12)
    idx = torch.as_tensor(index)

    def configuration() -> tuple[torch.Tensor, torch.Tensor]:
        return torch.cat([pos, quat / quat.norm()]), basis @ shape

    def loss(limits: float = LIMIT_WEIGHT) -> torch.Tensor:
        wr, joints = configuration()
        points = hand.surface_points(wr[None], joints[None])[0, idx]
        outside = torch.relu(lower - joints) + torch.relu(joints - upper)
        return (w * ((points - goal) ** 2).sum(-1)).sum() + limits * (outside**2).sum()

    optimiser = torch.optim.LBFGS(
        [pos, quat, shape], max_iter=iterations, line_search_fn="strong_wolfe"
    )

    def closure() -> torch.Tensor:
        optimiser.zero_grad()
        value = loss()
        value.backward()
        return value

    optimiser.step(closure)
    with torch.no_grad():
        wr, _ = configuration()
        joints = hand.couple((basis @ shape).numpy())  # clipped to the limits
        points = hand.surface_points(wr[None], torch.as_tensor(joints)[None])[0, idx]
        error = float((w * ((points - goal) ** 2).sum(-1)).sum().sqrt())
    steps = int(optimiser.state[optimiser._params[0]].get("n_iter", 0))
    return JointFit(
        wr.numpy().copy(),
        joints,
        error,
        steps,
        time.perf_counter() - start,
    )
