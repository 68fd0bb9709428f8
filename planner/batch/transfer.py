"""Cross-hand transfer (the paper's data workflow): a validated grasp of one hand seeds another's.

The source hand's anchor fingertips are scaled about their centroid by the ratio of the two
hands' sizes (thumb-to-fingers distance at the open pose, read from the hands' own kinematics,
so any URDF hand works), snapped to the object's surface, and given to the target hand's Drake
program as anchors. The wrist is kept: the target starts with its palm frame (hand.json) on the
source's palm frame, since hands' root frames differ, and the source palm centre is the palm
target. The answer then gets a pregrasp and squeeze and is validated like any plan.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from functools import cache
from typing import Any

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from models.grasp import Grasp
from models.hands import HandModel, load_hand
from models.objects import ObjectModel
from planner.batch.jobs import Job
from planner.functional import HandGeometry, finish_grasp
from planner.grasp_program import GraspProgram, GraspTargets, ProgramSettings, SolveResult
from planner.grasp_program import grasp_program as build_program


@cache
def hand_size(hand_folder: str) -> float:
    """Mean distance from the thumb tip to the other anchor fingertips at the open pose (m)."""
    hand = load_hand(hand_folder)
    identity = torch.tensor([[0, 0, 0, 1.0, 0, 0, 0]], dtype=torch.float64)
    q = torch.tensor(hand.open_pose[None], dtype=torch.float64)
    tips = hand.fingertip_positions(identity, q, list(hand.meta.anchor_fingers))[0].numpy()
    return float(np.linalg.norm(tips[1:] - tips[0], axis=1).mean())


def scale_between(source: HandModel, target: HandModel) -> float:
    """How much larger the target hand is than the source (ratio of `hand_size`)."""
    return hand_size(str(target.folder)) / hand_size(str(source.folder))


def anchor_tips(hand: HandModel, wrist: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(4, 3) world positions of the anchor fingertips (sphere centres), thumb first."""
    w = torch.as_tensor(np.asarray(wrist, dtype=float)[None])
    qq = torch.as_tensor(np.asarray(q, dtype=float)[None])
    return hand.fingertip_positions(w, qq, list(hand.meta.anchor_fingers))[0].numpy()


@dataclass
class Completed:
    """A solved program turned into a validated, labelled grasp (or why it was not)."""

    solve: SolveResult
    grasp: Grasp | None = None
    success: bool = False
    part: str | None = None
    validation: dict[str, Any] | None = None
    times: dict[str, float] = field(default_factory=dict)


def complete_grasp(
    program: GraspProgram,
    obj: ObjectModel,
    solved: SolveResult,
    instruction: str,
    protocol: str = "paper",
) -> Completed:
    """Pregrasp (back along the surface normals at the anchor tips), BODex squeeze, MuJoCo
    validation and the part vote: the same steps the functional planner takes per candidate."""
    out = Completed(solved, times={"solve": solved.solve_time})
    if not solved.ok:
        return out
    done = finish_grasp(program, obj, solved, instruction, protocol)
    out.grasp, out.success, out.part = done.grasp, done.success, done.part
    out.validation = done.validation
    out.times.update(done.times)
    return out


def palm_aligned_wrist(wrist: np.ndarray, source: HandModel, target: HandModel) -> np.ndarray:
    """The target's wrist pose that puts its palm frame (centre, normal, finger axis, from
    hand.json) where the source's palm is: "wrist kept" across hands whose root frames differ."""
    rot = Rotation.from_quat(wrist[3:7], scalar_first=True)
    sp, tp = source.meta.palm, target.meta.palm
    normal, fingers = rot.apply(sp.normal), rot.apply(sp.finger_axis)
    centre = rot.apply(sp.center) + wrist[:3]
    aligned, _ = Rotation.align_vectors(
        [normal, fingers], [tp.normal, tp.finger_axis], weights=[10, 1]
    )
    position = centre - aligned.apply(tp.center)
    return np.concatenate([position, aligned.as_quat(scalar_first=True)])


def transfer_targets(
    grasp: Grasp, source: HandModel, target: HandModel, obj: ObjectModel
) -> GraspTargets:
    """The target hand's program inputs from a source grasp (see the module docstring)."""
    wrist = grasp.wrist_pose("grasp")
    tips = anchor_tips(source, wrist, grasp.grasp)
    centre = tips.mean(axis=0)
    scaled = centre + (tips - centre) * scale_between(source, target)
    index = np.argmin(np.linalg.norm(obj.points[None] - scaled[:, None], axis=2), axis=1)
    rot = Rotation.from_quat(wrist[3:7], scalar_first=True)
    palm = rot.apply(source.meta.palm.center) + wrist[:3]
    return GraspTargets(
        wrist=palm_aligned_wrist(wrist, source, target),
        q=HandGeometry(target).q_half.copy(),
        anchors=obj.points[index],
        anchor_normals=obj.normals[index],
        palm_target=palm,
    )


def transfer_grasp(
    grasp: Grasp,
    target: HandModel | str,
    obj: ObjectModel,
    *,
    source: HandModel | str | None = None,
    protocol: str = "paper",
    settings: ProgramSettings | None = None,
) -> Completed:
    """Solve, complete and validate `grasp` (of hand `source`, default the hand it names, on
    `obj`) for hand `target`."""
    source = source if isinstance(source, HandModel) else load_hand(source or grasp.hand)
    target = target if isinstance(target, HandModel) else load_hand(target)
    program = build_program(target, obj.collision_pieces(), settings)
    solved = program.solve(transfer_targets(grasp, source, target, obj))
    return complete_grasp(program, obj, solved, grasp.instruction or "", protocol)


def transfer_jobs(
    records: Iterable[dict[str, Any]], hands: Sequence[str], per_pair: int | None = None
) -> list[Job]:
    """Transfer jobs: every valid planned grasp (every holding grasp of a validate_all job, at
    most `per_pair` per object, instruction and source hand, lowest variants first) seeds each
    other hand in `hands`."""
    taken: dict[tuple[str, str, str], int] = {}
    jobs = []
    for record in records:
        job = record.get("job") or {}
        if not record.get("valid") or "source" in job or record.get("grasp") is None:
            continue
        key = (json.dumps(job["object"], sort_keys=True), job["instruction"], job["hand"])
        grasps = [h["grasp"] for h in record.get("holding") or []] or [record["grasp"]]
        for k, grasp in enumerate(grasps):  # the returned grasp comes first
            if per_pair is not None and taken.get(key, 0) >= per_pair:
                break
            taken[key] = taken.get(key, 0) + 1
            source_id = record["id"] if k == 0 else f"{record['id']}/h{k}"
            source = {"id": source_id, "hand": job["hand"], "grasp": grasp}
            for hand in hands:
                if hand != job["hand"]:
                    jobs.append(
                        Job(job["object"], job["instruction"], hand, 0, 1, job["protocol"], source)
                    )
    return jobs
