"""Measure the D(R,O) stage with the first stage as an oracle (the dataset's wrist and anchors).

    python -m eval.dro --split test [--weights FILE] [--rows-per-hand 40] [--validate 20]

Per hand, on rows of the split (a fixed random sample per hand):
- D error: mean |D_hat - D| (mm) over the pairs with D < 5 cm, D the distances from the hand's
  surface points at the dataset grasp to the object input points;
- hand point error of the targets (median mm; `--placement`: "multilateration" + per-body
  Kabsch, the planner's, or "surface", learned.dro.surface_targets), over the hand points
  within 5 cm of the object at the dataset grasp (`near`) and over all 512, and the error the
  grasp program sees: the closeness-weighted mean over the points it gets (closeness above
  planner.learned_proposer.MIN_CLOSENESS);
- for the first `--validate` rows: the Drake grasp program with the dataset anchors (and the
  object's normals there), the dataset wrist as its prior and the targets weighted by
  predicted closeness (GraspTargets.point_weights), started where the planner starts a
  sample's fingers (planner.learned_proposer.sample_start);
  joint error vs the dataset grasp (mean |q - q_grasp| in degrees over the hand's joints) and
  first-try validated success (the first solve, pregrasp, squeeze and MuJoCo validation as
  the planner runs them, `--protocol`, default paper);
- the network's own guess of where each hand point goes (input + learned offset, the kernel's
  distance feature), median error over the `near` points, beside the targets';
- timings: network forward (one thread), the whole prediction, the solve.

Leave-one-hand-out: train with `--hands` on two hands (learned.train_dro) and evaluate its
weights here with `--weights`; the table says which hands the weights were trained on.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from learned.dro import PLACEMENTS, load_weights, predict
from learned.train_dro import prepare
from models.hands import load_hand
from models.objects import make_object
from planner.commands.validate import parse_overrides
from planner.functional import finish_grasp
from planner.grasp_program import GraspTargets, ProgramSettings, grasp_program
from planner.learned_proposer import MIN_CLOSENESS, sample_start
from planner.settings import PlannerSettings, with_overrides

NEAR = 0.05  # m


@dataclass
class HandRecord:
    hand: str
    rows: int = 0
    d_error_mm: list[float] = field(default_factory=list)  # per row
    point_error_near_mm: list[float] = field(default_factory=list)  # per point, pooled
    point_error_all_mm: list[float] = field(default_factory=list)
    kept_error_sum: float = 0.0  # closeness x error (mm) over the points the program gets
    kept_weight_sum: float = 0.0
    headed_error_near_mm: list[float] = field(default_factory=list)
    joint_error_deg: list[float] = field(default_factory=list)
    solved_ok: list[bool] = field(default_factory=list)
    first_try_success: list[bool] = field(default_factory=list)
    forward_s: list[float] = field(default_factory=list)
    predict_s: list[float] = field(default_factory=list)
    solve_s: list[float] = field(default_factory=list)

    def summary(self) -> dict:
        def med(x: list[float]) -> float:
            return float(statistics.median(x)) if x else float("nan")

        def mean(x: list) -> float:
            return float(np.mean(x)) if x else float("nan")

        return {
            "hand": self.hand,
            "rows": self.rows,
            "d_error_mm": mean(self.d_error_mm),
            "point_error_near_median_mm": med(self.point_error_near_mm),
            "point_error_all_median_mm": med(self.point_error_all_mm),
            "kept_error_mm": self.kept_error_sum / max(self.kept_weight_sum, 1e-12),
            "headed_error_near_median_mm": med(self.headed_error_near_mm),
            "validated_rows": len(self.first_try_success),
            "joint_error_deg": mean(self.joint_error_deg),
            "solve_ok": mean(self.solved_ok),
            "first_try_success": mean(self.first_try_success),
            "forward_median_s": med(self.forward_s),
            "predict_median_s": med(self.predict_s),
            "solve_median_s": med(self.solve_s),
        }


def evaluate(
    data_root: str,
    split: str,
    weights: str | None,
    rows_per_hand: int,
    validate: int,
    protocol: str,
    hands: list[str] | None,
    seed: int = 0,
    anchors_only: bool = False,
    placement: str = "multilateration",
    program: ProgramSettings | None = None,
) -> dict:
    torch.set_num_threads(1)
    ckpt = load_weights(weights)
    net = ckpt.net
    # a network trained without anchors gets its object input without them
    chosen = tuple(hands) if hands else None
    data = prepare(data_root, split, chosen, progress=False, use_anchors=net.cfg.anchors)
    rng = np.random.default_rng(seed)
    records: dict[str, HandRecord] = {}
    names = np.array(data.hands)
    for name in sorted(set(data.hands)):
        hand = load_hand(name)
        rec = records[name] = HandRecord(name)
        rows = rng.permutation(np.flatnonzero(names == name))[:rows_per_hand]
        rec.rows = len(rows)
        for n_done, r in enumerate(tqdm(rows, desc=name, leave=False)):
            truth = torch.from_numpy(data.grasp_points[r]).double()
            obj_xyz = torch.from_numpy(data.obj[r, :, :3]).double()
            pred = predict(
                net, hand, data.wrist[r], data.obj[r], data.text[r], data.normals[r], placement
            )
            rec.forward_s.append(pred.forward_time)
            rec.predict_s.append(pred.total_time)
            true_d = torch.cdist(truth, obj_xyz).numpy()
            close = true_d < NEAR
            rec.d_error_mm.append(float(np.abs(pred.distances - true_d)[close].mean() * 1000))
            err = np.linalg.norm(pred.targets - truth.numpy(), axis=1) * 1000
            rec.point_error_all_mm.extend(err.tolist())
            rec.point_error_near_mm.extend(err[close.any(axis=1)].tolist())
            kept = pred.closeness > MIN_CLOSENESS  # the points the grasp program gets
            rec.kept_error_sum += float((err[kept] * pred.closeness[kept]).sum())
            rec.kept_weight_sum += float(pred.closeness[kept].sum())
            headed = np.linalg.norm(pred.headed - truth.numpy(), axis=1) * 1000
            rec.headed_error_near_mm.extend(headed[close.any(axis=1)].tolist())
            if n_done < validate:
                _solve_and_validate(rec, hand, data, r, pred, protocol, anchors_only, program)
    meta = dict(ckpt.meta)
    return {
        "split": split,
        "weights": str(weights or "shipped"),
        "trained_on": meta.get("hands"),
        "weights_meta": meta,
        "anchors_only": anchors_only,
        "program": asdict(program or ProgramSettings()),
        "placement": placement,
        "hands": [records[h].summary() for h in sorted(records)],
        "config": asdict(net.cfg),
    }


def _solve_and_validate(
    rec: HandRecord,
    hand,
    data,
    r: int,
    pred,
    protocol: str,
    anchors_only: bool,
    program_settings: ProgramSettings | None = None,
) -> None:
    """Drake with the dataset anchors and the predicted point targets (none with
    `anchors_only`: the comparison without D(R,O)), then the planner's pregrasp, squeeze and
    MuJoCo validation on the first solve."""
    obj = make_object(data.categories[r], int(data.seeds[r]))
    program = grasp_program(hand, obj.collision_pieces(), program_settings)
    anchors = data.anchors[r]
    nearest = np.argmin(np.linalg.norm(obj.points[None] - anchors[:, None], axis=2), axis=1)
    keep = np.flatnonzero(pred.closeness > MIN_CLOSENESS)  # what D(R,O) says is near contact
    if anchors_only:
        keep = keep[:0]
    solved = program.solve(
        GraspTargets(
            data.wrist[r],
            sample_start(hand),
            anchors=anchors,
            anchor_normals=obj.normals[nearest],
            point_index=keep,
            point_targets=pred.targets[keep],
            point_weights=pred.closeness[keep],
        )
    )
    rec.solve_s.append(solved.solve_time)
    rec.solved_ok.append(bool(solved.ok))
    q_true = data.q_grasp[r, : hand.dof]
    rec.joint_error_deg.append(float(np.degrees(np.abs(solved.q - q_true).mean())))
    success = False
    if solved.ok:
        done = finish_grasp(program, obj, solved, data.instructions[r], protocol)
        success = bool(done.success)
    rec.first_try_success.append(success)


def _table(result: dict) -> str:
    cols = [
        ("hand", "hand", "{}"),
        ("rows", "rows", "{}"),
        ("D err mm", "d_error_mm", "{:.1f}"),
        ("pt err near mm", "point_error_near_median_mm", "{:.1f}"),
        ("pt err all mm", "point_error_all_median_mm", "{:.1f}"),
        ("kept err mm", "kept_error_mm", "{:.1f}"),
        ("headed err near mm", "headed_error_near_median_mm", "{:.1f}"),
        ("validated", "validated_rows", "{}"),
        ("joint err deg", "joint_error_deg", "{:.1f}"),
        ("solve ok", "solve_ok", "{:.0%}"),
        ("1st-try success", "first_try_success", "{:.0%}"),
        ("forward s", "forward_median_s", "{:.3f}"),
        ("predict s", "predict_median_s", "{:.3f}"),
        ("solve s", "solve_median_s", "{:.3f}"),
    ]
    lines = [" | ".join(c[0] for c in cols)]
    for row in result["hands"]:
        cells = []
        for _, key, fmt in cols:
            value = row[key]
            cells.append(
                "n/a" if isinstance(value, float) and np.isnan(value) else fmt.format(value)
            )
        lines.append(" | ".join(cells))
    head = (
        f"split {result['split']}, weights {result['weights']} (trained on "
        f"{result['trained_on']}), targets by {result['placement']}"
    )
    if result["anchors_only"]:
        head += "; Drake WITHOUT the D(R,O) targets (anchors and wrist only)"
    return head + "\n" + "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m eval.dro", description=__doc__)
    parser.add_argument("--data", default="data/grasps_v2")
    parser.add_argument("--split", default="test")
    parser.add_argument("--weights", default=None, help="default: the shipped weights")
    parser.add_argument("--rows-per-hand", type=int, default=40)
    parser.add_argument("--validate", type=int, default=20, help="rows per hand through Drake")
    parser.add_argument("--protocol", default="paper")
    parser.add_argument("--hands", nargs="+", default=None)
    parser.add_argument("--json", default=None, help="write the figures here")
    parser.add_argument(
        "--anchors-only",
        action="store_true",
        help="solve without the D(R,O) point targets (the comparison)",
    )
    parser.add_argument(
        "--placement",
        choices=PLACEMENTS,
        default="multilateration",
        help="how distances become targets (learned.dro.predict; default: the planner's)",
    )
    parser.add_argument(
        "--set",
        nargs="*",
        default=[],
        metavar="program.KEY=VALUE",
        help="grasp program settings for the solves (planner.grasp_program.ProgramSettings), "
        "e.g. program.point_weight=5",
    )
    args = parser.parse_args(argv)
    overrides = parse_overrides(args.set)
    other = [k for k in overrides if not k.startswith("program.")]
    if other:
        parser.error(f"--set takes program.* settings only (the solve's), not {other}")
    program = with_overrides(PlannerSettings(), overrides).program
    start = time.perf_counter()
    result = evaluate(
        args.data,
        args.split,
        args.weights,
        args.rows_per_hand,
        args.validate,
        args.protocol,
        args.hands,
        anchors_only=args.anchors_only,
        placement=args.placement,
        program=program,
    )
    result["wall_s"] = round(time.perf_counter() - start, 1)
    print(_table(result))
    print(f"wall {result['wall_s']} s")
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
