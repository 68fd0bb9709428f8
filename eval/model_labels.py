"""How well the interaction model's part labels (planner.model_labels) match the true ones.

For every Use and Handover instruction of the split's objects (the intents checked on them),
each hand's samples seed the parts and the labels are spread over a bare cloud of the object;
scored against the procedural object's own labels (never an input): the share of points given
their true part, by the random walk and, in the same run, by the nearest seed (the baseline),
and how often no labels were made (a part the definition measures was not found).

    python -m eval.model_labels --split val [--hands allegro] [--objects-per-category 1]
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
from models.objects.library import CATEGORIES
from models.objects.splits import seeds as split_seeds
from planner.model_labels import labels_from_seeds, part_seeds

CLOUD_POINTS = 4096  # as eval.benchmark's and drograsp demo's clouds
SPREADS = ("walk", "nearest")


def run(split: str, hands: list[str], per_category: int, samples: int) -> list[dict]:
    """One row per (hand, object, instruction, spread)."""
    model = load_model(None)
    jobs = [
        (hand, cat, seed, ins)
        for cat in CATEGORIES
        for seed in split_seeds(cat, split, per_category)
        for ins in instructions(cat)
        if ins.intent in ("Use", "Handover")
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
        masks = part_seeds(cloud, ins, hand, anchors)  # once: both spreads share the seeds
        sought = time.perf_counter() - t0
        for spread in SPREADS:
            t0 = time.perf_counter()
            found = labels_from_seeds(cloud, ins, masks, spread)
            seconds = sought + time.perf_counter() - t0
            agree = None if found is None else float((found.obj.point_labels == true).mean())
            rows.append(
                {
                    "hand": hand_name,
                    "category": cat,
                    "seed": seed,
                    "instruction": ins.text,
                    "spread": spread,
                    "agreement": agree,
                    "seconds": seconds,
                }
            )
    return rows


def table(rows: list[dict], hands: list[str]) -> str:
    """Per hand and spread: mean agreement where labels were made, the worst category, how
    many instructions got none, median seconds."""
    groups = defaultdict(list)
    for r in rows:
        groups[(r["hand"], r["spread"])].append(r)
    out = [
        "| hand | spread | points on their true part (mean) | worst category | no labels | median s |",
        "|---|---|---|---|---|---|",
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
                f"{worst} {100 * np.mean(per_cat[worst]):.0f}% | {len(rs) - len(made)} of "
                f"{len(rs)} | {np.median([r['seconds'] for r in rs]):.2f} |"
            )
    return "\n".join(out)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--split", default="val", choices=["train", "val", "test", "heldout"])
    ap.add_argument("--hands", nargs="+", default=None, help="default: every built-in hand")
    ap.add_argument("--objects-per-category", type=int, default=1)
    ap.add_argument("--samples", type=int, default=16, help="samples for the instruction")
    ap.add_argument("--out", type=Path, default=None, help="write the rows as JSON lines")
    args = ap.parse_args(argv)
    hands = args.hands or available_hands()
    rows = run(args.split, hands, args.objects_per_category, args.samples)
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text("".join(json.dumps(r) + "\n" for r in rows))
    print(f"{args.split} split, {args.objects_per_category} object(s) per category")
    print(table(rows, hands))


if __name__ == "__main__":
    main()
