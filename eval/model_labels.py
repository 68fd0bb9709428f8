"""How well the interaction model's part labels (planner.model_labels) match the true ones.

For every instruction of the split's objects whose intent planning checks on the labels (every
intent not measured without parts: Use, Handover, Hold), each hand's samples seed the parts and
the labels are spread over a bare cloud of the object; scored against the procedural object's
own labels (never an input): the share of points given their true part, the share of the other
parts' points (those Use and Handover keep the hand clear of) within COVER_DISTANCE of points
labelled with their part (a hand near an uncovered point is near that part unseen), the share of
the points labelled as the instructed part that truly are, by the random walk and, in the same
run, by the nearest seed (the baseline), and how often no labels were made (a part the
definition measures was not found).

    python -m eval.model_labels --split val [--hands allegro] [--objects-per-category 1]
        [--label-samples 16] [--held-reach 0.03]
"""

from __future__ import annotations

import argparse
import json
import time
from collections import defaultdict
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree
from tqdm import tqdm

from learned.interaction import load_model
from models.hands import available_hands, load_hand
from models.objects import instructions, load_object, make_object
from models.objects.intents import label_free
from models.objects.library import CATEGORIES
from models.objects.names import INTENTS as ALL_INTENTS
from models.objects.splits import seeds as split_seeds
from planner.model_labels import labels_from_seeds, part_seeds
from planner.settings import LearnedSettings

CLOUD_POINTS = 4096  # as eval.benchmark's and drograsp demo's clouds
COVER_DISTANCE = 0.005  # m
# the intents planned on the model's labels (planner.functional, learned.labels_over_region)
INTENTS = tuple(i for i in ALL_INTENTS if not label_free(i))
SPREADS = ("walk", "nearest")


def covered(points: np.ndarray, found: np.ndarray, true: np.ndarray, held: int) -> float | None:
    """The share of the points of the parts other than `held` (true labels) that lie within
    COVER_DISTANCE of a point labelled (`found`) with their part; None: no other part."""
    near, total = 0, 0
    for k in np.unique(true):
        if k == held:
            continue
        mine = true == k
        total += int(mine.sum())
        if (found == k).any():
            gap = cKDTree(points[found == k]).query(points[mine])[0]
            near += int((gap <= COVER_DISTANCE).sum())
    return near / total if total else None


def run(
    split: str,
    hands: list[str],
    per_category: int,
    samples: int,
    label_samples: int,
    held_reach: float,
) -> list[dict]:
    """One row per (hand, object, instruction, spread)."""
    model = load_model(None)
    jobs = [
        (hand, cat, seed, ins)
        for cat in CATEGORIES
        for seed in split_seeds(cat, split, per_category)
        for ins in instructions(cat)
        if ins.intent in INTENTS
        for hand in hands
    ]
    rows = []
    for hand_name, cat, seed, ins in tqdm(jobs, desc="model labels", unit="job"):
        obj = make_object(cat, seed)
        cloud = load_object(obj.sample_cloud(CLOUD_POINTS, seed=1).points)
        true = obj.point_labels[cKDTree(obj.points).query(cloud.points)[1]]
        hand = load_hand(hand_name)
        _, anchors = model.sample(cloud.points, ins.text, hand, samples, seed=0)
        t0 = time.perf_counter()
        # once: both spreads share the seeds
        masks = part_seeds(cloud, ins, hand, anchors, samples=label_samples)
        sought = time.perf_counter() - t0
        for spread in SPREADS:
            t0 = time.perf_counter()
            found = labels_from_seeds(cloud, ins, masks, spread, held_reach)
            seconds = sought + time.perf_counter() - t0
            agree = cover = precision = None
            if found is not None:
                labels = found.obj.point_labels
                agree = float((labels == true).mean())
                held = CATEGORIES[cat].parts.index(ins.part)
                cover = covered(cloud.points, labels, true, held)
                precision = float((true[labels == held] == held).mean())
            rows.append(
                {
                    "hand": hand_name,
                    "category": cat,
                    "seed": seed,
                    "instruction": ins.text,
                    "spread": spread,
                    "agreement": agree,
                    "other_parts_covered": cover,
                    "held_precision": precision,
                    "seconds": seconds,
                }
            )
    return rows


def table(rows: list[dict], hands: list[str]) -> str:
    """Per hand and spread: mean agreement where labels were made, the worst category, the
    other parts covered, the instructed part's precision, how many instructions got none,
    median seconds."""
    groups = defaultdict(list)
    for r in rows:
        groups[(r["hand"], r["spread"])].append(r)
    out = [
        "| hand | spread | points on their true part (mean) | worst category "
        f"| other parts within {COVER_DISTANCE * 1000:.0f} mm of their label (mean) "
        "| labelled instructed part truly it (mean) | no labels | median s |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for hand in hands:
        for spread in SPREADS:
            rs = groups[(hand, spread)]
            made = [r for r in rs if r["agreement"] is not None]
            per_cat = defaultdict(list)
            for r in made:
                per_cat[r["category"]].append(r["agreement"])
            worst = min(per_cat, key=lambda c: np.mean(per_cat[c]))
            label = "random walk" if spread == "walk" else "nearest seed (baseline)"
            out.append(
                f"| {hand} | {label} | {100 * np.mean([r['agreement'] for r in made]):.1f}% | "
                f"{worst} {100 * np.mean(per_cat[worst]):.0f}% | "
                f"{100 * np.mean([r['other_parts_covered'] for r in made]):.1f}% | "
                f"{100 * np.mean([r['held_precision'] for r in made]):.1f}% | "
                f"{len(rs) - len(made)} of "
                f"{len(rs)} | {np.median([r['seconds'] for r in rs]):.2f} |"
            )
    return "\n".join(out)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--split", default="val", choices=["train", "val", "test", "heldout"])
    ap.add_argument("--hands", nargs="+", default=None, help="default: every built-in hand")
    ap.add_argument("--objects-per-category", type=int, default=1)
    ap.add_argument("--samples", type=int, default=16, help="samples for the instruction")
    ap.add_argument(
        "--label-samples",
        type=int,
        default=LearnedSettings().label_samples,
        help="samples for each other part (learned.label_samples)",
    )
    ap.add_argument(
        "--held-reach",
        type=float,
        default=LearnedSettings().held_reach,
        help="m: the instructed part only this near its seed (learned.held_reach; 0: off)",
    )
    ap.add_argument("--out", type=Path, default=None, help="write the rows as JSON lines")
    args = ap.parse_args(argv)
    hands = args.hands or available_hands()
    rows = run(
        args.split,
        hands,
        args.objects_per_category,
        args.samples,
        args.label_samples,
        args.held_reach,
    )
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text("".join(json.dumps(r) + "\n" for r in rows))
    print(
        f"{args.split} split, {args.objects_per_category} object(s) per category, "
        f"{args.label_samples} samples per other part, held reach {args.held_reach} m"
    )
    print(table(rows, hands))


if __name__ == "__main__":
    main()
