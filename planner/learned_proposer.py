"""Proposals from the learned stages: no part labels needed, any sentence.

The interaction model (learned.interaction) draws wrist poses and four contact anchors for the
cloud, sentence and hand; the D(R,O) network (learned.dro) turns each wrist and its anchors into
targets for the hand's surface points (multilateration + per-body Kabsch, weighted by how near
contact each point is predicted). Both go to the same grasp program as the model-based proposals
(planner.functional): anchors with their surface normals, the hand's start for samples as the
starting configuration (`sample_start`), and the point targets the program pulls toward
(`point_weights`: closeness, so far points weigh little). The samples are solved best anchor
closure first, as the model-based ones. `fitted` is the ablation without Drake
(`PlannerSettings.learned.solver` "fit"): the joints fitted to the targets with no collision
constraints. `direct_proposals` and `as_drawn` are the ablation of direct diffusion
(`PlannerSettings.proposer` "direct"): wrist and joints drawn by one model and validated as drawn.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from models.hands import HandModel
from models.objects import ObjectModel
from models.reproducible import rounded, rounded_within
from planner.grasp_program import GraspProgram, SolveResult
from planner.quality import contact_quality
from planner.results import Proposal

# D(R,O) targets of hand points predicted at least this close to contact (closeness, e^-1 at
# 1 cm: about 3 cm) enter the program; the rest are guesswork (learned.dro.closeness)
MIN_CLOSENESS = 0.05

# The region the samples point at (`pointed_region`): the samples whose anchor centres lie
# within REGION_SPREAD of the densest one (kernel width REGION_BANDWIDTH), and the object points
# within REGION_RADIUS of the anchors of REGION_VOTES of them. On the 150 validation pairs'
# samples (16 each) the region's points lay on the instructed part for 89% on average at 6 mm
# and 2 votes, against 81% at 12 mm and 1 vote (where a handle's region took in the body
# beside it; counted once from eval.benchmark's records, docs/learned_log.md); smaller or
# with more votes, no better. REGION_PART: what the model-based proposer is told the part is
# called.
REGION_BANDWIDTH = 0.02  # m
REGION_SPREAD = 0.05  # m
REGION_RADIUS = 0.006  # m
REGION_VOTES = 2
REGION_PART = "pointed"


@dataclass
class LearnedTargets:
    """D(R,O)'s hand point targets for one sample: which of the hand's surface points, where,
    and how much each counts."""

    index: np.ndarray  # (K,) into the hand's fixed surface points
    targets: np.ndarray  # (K, 3) m, object frame
    weights: np.ndarray  # (K,)


@dataclass
class LearnedProposals:
    """The samples as drawn, and the time drawing them took."""

    wrists: np.ndarray  # (n, 7)
    anchors: np.ndarray  # (n, 4, 3)
    normals: np.ndarray  # (n, 4, 3)
    times: dict[str, float]
    q: np.ndarray | None = None  # (n, dof): direct diffusion's joints (None: `sample_start`)


def learned_proposals(
    obj: ObjectModel,
    text: str,
    hand: HandModel,
    samples: int,
    seed: int = 0,
    guidance: float | None = None,
    weights: str | None = None,
    steps: int | None = None,
) -> LearnedProposals:
    """`samples` interaction samples for the object's cloud, the sentence and the hand, each
    with its anchors' surface normals. D(R,O)'s targets are made per sample when it is solved
    (`dro_targets`): most plans end after a few solves, and D(R,O) costs 0.1-0.6 s a sample.
    `weights`: a folder of interaction weights (None: the shipped model); `steps`: DDIM steps
    (None: the model's own)."""
    from learned.interaction import load_model

    t0 = time.perf_counter()
    model = load_model(weights)
    wrists, anchors = model.sample(obj.points, text, hand, samples, guidance, steps, seed=seed)
    times = {"interaction": time.perf_counter() - t0}
    _, normals = surface_at(obj, anchors)
    return LearnedProposals(wrists, anchors, normals, times)


def sample_start(hand: HandModel) -> np.ndarray:
    """Where the grasp program starts a learned sample's fingers: the open pose closed by the
    hand's `learned_start_closure` (hand.json; 0: the open pose itself). With the dataset's wrist
    and anchors on 120-150 validation rows per hand, starting closed held more grasps at the
    first try for Allegro and Shadow and fewer for LEAP (docs/learned_log.md, "Where the solve
    starts")."""
    fraction = hand.meta.learned_start_closure
    if fraction == 0:
        return hand.open_pose.astype(np.float64).copy()
    return rounded_within(hand.closed_pose(fraction), hand.lower, hand.upper)


def surface_at(obj: ObjectModel, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The object's cloud points nearest `points` (..., 3) and their normals, same shape."""
    nearest = cKDTree(obj.points).query(points.reshape(-1, 3))[1]
    return obj.points[nearest].reshape(points.shape), obj.normals[nearest].reshape(points.shape)


def pointed_region(
    points: np.ndarray,
    anchors: np.ndarray,
    radius: float = REGION_RADIUS,
    votes: int = REGION_VOTES,
) -> np.ndarray:
    """Mask of `points` (N, 3) on the part most samples' anchors (n, 4, 3) point at.

    A tenth of the samples land on another part (eval.interaction, part accuracy), so the
    region follows the majority: the sample whose anchor centre has the most others near it,
    the samples near that one, and the points near the anchors of at least two of them (one
    sample's stray finger does not widen it onto the next part). `radius` and `votes`: how
    near the anchors of how many of them."""
    finite = np.all(np.isfinite(anchors), axis=2)
    centres = np.array([a[f].mean(axis=0) for a, f in zip(anchors, finite, strict=True)])
    gap = np.linalg.norm(centres[:, None] - centres[None], axis=2)
    density = np.exp(-((gap / REGION_BANDWIDTH) ** 2)).sum(axis=1)
    members = np.flatnonzero(gap[int(np.argmax(density))] <= REGION_SPREAD)
    count = np.zeros(len(points), dtype=int)
    for m in members:
        near, _ = cKDTree(anchors[m][finite[m]]).query(points)
        count += near <= radius
    return count >= min(votes, len(members))


def region_object(
    obj: ObjectModel,
    anchors: np.ndarray,
    radius: float = REGION_RADIUS,
    votes: int = REGION_VOTES,
) -> ObjectModel | None:
    """The object's surface points labelled REGION_PART where the samples point
    (`pointed_region`) and "rest" elsewhere: what the model-based proposer plans on after the
    samples (`LearnedSettings.region_proposals`). None where the region is too small to place
    anchors on (8 points)."""
    mask = pointed_region(obj.points, anchors, radius, votes)
    if mask.sum() < 8:
        return None
    return ObjectModel(
        name=obj.name,
        cloud=obj.points,
        cloud_normals=obj.normals,
        cloud_labels=np.where(mask, 0, 1),
        part_names=(REGION_PART, "rest"),
        category=obj.category,
        seed=obj.seed,
    )


def direct_proposals(
    obj: ObjectModel,
    text: str,
    hand: HandModel,
    samples: int,
    seed: int = 0,
    guidance: float | None = None,
    steps: int | None = None,
) -> LearnedProposals:
    """`samples` [wrist, joints] drawn by the direct-diffusion model for the cloud, sentence and
    hand. Its anchors are the object points nearest the anchor fingertips, so the samples are
    ordered and recorded as the pipeline's are."""
    import torch

    from learned.interaction import DIRECT_NAME, load_model

    t0 = time.perf_counter()
    model = load_model(name=DIRECT_NAME)
    wrists, q = model.sample_configurations(
        obj.points, text, hand, samples, guidance, steps, seed=seed
    )
    times = {"direct": time.perf_counter() - t0}
    tips = hand.fingertip_positions(
        torch.tensor(wrists), torch.tensor(q), list(hand.meta.anchor_fingers)
    ).numpy()
    anchors, normals = surface_at(obj, tips)
    return LearnedProposals(wrists, anchors, normals, times, q=q)


def as_drawn(program: GraspProgram, proposal: Proposal) -> SolveResult:
    """A direct-diffusion sample as its configuration: nothing solved, distance and anchor
    error measured; every sample goes on to MuJoCo, as in the paper's Scene-Diffuser baseline."""
    note = "direct diffusion sample, not solved"
    return unsolved(program, proposal.wrist, proposal.q, proposal.anchors, "as drawn", 0.0, note)


def dro_targets(
    obj: ObjectModel,
    text: str,
    hand: HandModel,
    wrist: np.ndarray,
    anchors: np.ndarray,
    seed: tuple[int, int],
    weights: str | None = None,
) -> LearnedTargets:
    """D(R,O)'s hand point targets for one sample; `seed` (plan seed, sample index) seeds its
    object input, so a sample's targets do not depend on which samples were solved before.
    `weights`: the D(R,O) network's file or name (None: the shipped one); a network
    trained without anchors gets its object input without them."""
    from learned.contact_map import object_input
    from learned.dro import predict
    from learned.text import encode

    net = _dro_net(weights)
    given = anchors if net.cfg.anchors else None
    features = object_input(obj.points, given, np.random.default_rng(list(seed))).features
    pred = predict(net, hand, wrist, features, encode([text])[0])
    keep = np.flatnonzero(pred.closeness > MIN_CLOSENESS)
    return LearnedTargets(keep, pred.targets[keep], pred.closeness[keep])


_NETS: dict = {}


def _dro_net(weights: str | None = None):
    """A D(R,O) network (None: the shipped one), loaded once per process."""
    from learned.dro import load_weights

    if weights not in _NETS:
        _NETS[weights] = load_weights(weights).net
    return _NETS[weights]


def anchor_closure(anchors: np.ndarray, normals: np.ndarray, obj: ObjectModel) -> float:
    """Epsilon of the anchors pushing along their inward normals about the object's centre:
    the solve order, as for the model-based proposals."""
    return float(contact_quality(anchors, -normals, obj.points.mean(axis=0)).epsilon)


def fitted(program: GraspProgram, proposal: Proposal) -> SolveResult:
    """D(R,O) Grasp's configuration for a learned proposal, the ablation without Drake: the
    wrist and joints fitted to D(R,O)'s point targets (learned.joint_fit), no collision
    constraints. The targets and their closeness weights are the ones the grasp program gets:
    D(R,O) Grasp fits every point, but this network learns distances clipped at a few
    centimetres, so far points' targets are guesses (all 512 unweighted: 3-4 cm rms misfit on
    a mug). Penetration and anchor error are measured, not constrained: every fit goes on to
    MuJoCo, as in D(R,O) Grasp."""
    from learned.joint_fit import fit_configuration

    fit = fit_configuration(
        program.hand,
        proposal.wrist,
        proposal.q,
        proposal.point_index,
        proposal.point_targets,
        proposal.point_weights,
    )
    note = (
        f"points {fit.rms_error * 1000:.1f} mm rms from D(R,O)'s targets; no collision constraints"
    )
    return unsolved(program, fit.wrist, fit.q, proposal.anchors, "joint fit", fit.fit_time, note)


def unsolved(
    program: GraspProgram,
    wrist: np.ndarray,
    q: np.ndarray,
    anchors: np.ndarray,
    status: str,
    seconds: float,
    note: str,
) -> SolveResult:
    """A configuration the grasp program did not solve, as a SolveResult that goes on to
    validation: within the joint limits, its distance to the object and anchor error measured."""
    hand = program.hand
    wrist = rounded(wrist)
    q = rounded_within(q, hand.lower, hand.upper)
    distance = program.hand_object_distance(wrist, q)
    return SolveResult(
        wrist=wrist,
        q=q,
        ok=True,
        min_distance=distance,
        anchor_error=program.anchor_error(wrist, q, anchors),
        solver_success=True,
        solver_status=status,
        solve_time=seconds,
        message=f"{note} (distance {distance * 1000:.1f} mm)",
    )
