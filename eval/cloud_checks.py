"""Do the planner's cloud checks tell the grasps that hold on the real object from those that slip?

    python -m eval.cloud_checks --split test --variants 3 --out cloud_checks.jsonl

Each test object as a 4096-point cloud (eval.benchmark's `--view cloud`), planned on by the
learned pipeline with the checks off and every candidate validated (up to 8). Every candidate
that held on the cloud's own pieces is validated again on `--variants` piece variants
(ObjectModel.piece_variants: pieces from random 70% subsets of the cloud) and on the real
object. The table says, per number of checks k, how many such grasps the first k variants
accept and how many of those hold on the real object, beside the grasps with no check: what
`PlannerSettings.cloud_checks = k` keeps and what it throws away. Resumes from `--out`.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from tqdm import tqdm

from eval.benchmark import CLOUD_POINTS, full_object, sampled_cloud_object
from eval.planner_benchmark import pairs
from models.hands import available_hands
from planner.functional import FunctionalPlanner
from planner.settings import PlannerSettings, with_overrides
from planner.validation.validator import validate


def measure(hand: str, category: str, seed: int, instruction: str, variants: int) -> list[dict]:
    """One row per candidate that held on the cloud's pieces: held on each variant, and on
    the real object."""
    planner = _planner(hand)
    obj = full_object(category, seed, False)
    cloud = sampled_cloud_object(obj, CLOUD_POINTS, seed=seed)
    result = planner.plan(cloud, instruction)
    protocol, rows = planner.settings.protocol, []
    for cand in result.candidates:
        if cand.order is None or not cand.success:
            continue
        real = validate(cand.grasp, obj.collision_pieces(), planner.hand, protocol).success
        checks = [
            bool(validate(cand.grasp, pieces, planner.hand, protocol).success)
            for pieces in cloud.piece_variants(variants)
        ]
        row = {"rank": cand.rank, "checks": checks, "real": bool(real)}
        rows.append(pair_key(hand, category, seed, instruction) | row)
    return rows


# the fields of a row that name its pair (what a resumed run skips)
PAIR_FIELDS = ("hand", "category", "seed", "instruction")


def pair_key(*pair: object) -> dict:
    """A row's pair fields, from (hand, category, seed, instruction)."""
    return dict(zip(PAIR_FIELDS, pair, strict=True))


# the checks off and every candidate validated, so each can be judged afterwards
_OVERRIDES = {"cloud_checks": 0, "schedule.validate_all": True, "schedule.max_candidates": 8}
_PLANNERS: dict[str, FunctionalPlanner] = {}


def _planner(hand: str) -> FunctionalPlanner:
    if hand not in _PLANNERS:
        _PLANNERS[hand] = FunctionalPlanner(hand, with_overrides(PlannerSettings(), _OVERRIDES))
    return _PLANNERS[hand]


def table(rows: list[dict], variants: int) -> str:
    """Per hand and number of checks: grasps accepted, and of those held on the real object."""
    lines = [
        "| hand | checks | held on the cloud's pieces | accepted | accepted that hold on the "
        "object | rejected that hold on the object |",
        "|---|---|---|---|---|---|",
    ]
    for hand in sorted({r["hand"] for r in rows}):
        mine = [r for r in rows if r["hand"] == hand]
        for k in range(variants + 1):
            kept = [r for r in mine if all(r["checks"][:k])]
            dropped = [r for r in mine if not all(r["checks"][:k])]
            good = sum(r["real"] for r in kept)
            share = f"{good} ({good / len(kept):.0%})" if kept else "0"
            lines.append(
                f"| {hand} | {k} | {len(mine)} | {len(kept)} | {share} | "
                f"{sum(r['real'] for r in dropped)} of {len(dropped)} |"
            )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--split", default="test")
    parser.add_argument("--hands", nargs="+", default=available_hands())
    parser.add_argument("--objects-per-category", type=int, default=1)
    parser.add_argument("--variants", type=int, default=3)
    parser.add_argument("--out", type=Path, default=Path("cloud_checks.jsonl"))
    args = parser.parse_args()
    import torch

    torch.set_num_threads(1)
    done: set[tuple] = set()
    rows: list[dict] = []
    if args.out.exists():
        for line in args.out.read_text().splitlines():
            row = json.loads(line)
            done.add(tuple(row[k] for k in PAIR_FIELDS))
            if row.get("rank") is not None:
                rows.append(row)
    chosen = pairs(args.split, args.objects_per_category, args.hands)
    todo = [tuple(p) for p in chosen if tuple(p) not in done]
    with args.out.open("a") as out:
        for hand, category, seed, instruction in tqdm(todo, desc="cloud checks"):
            found = measure(hand, category, seed, instruction, args.variants)
            # a pair without a held candidate still gets a line, so a resumed run skips it
            for row in found or [pair_key(hand, category, seed, instruction) | {"rank": None}]:
                out.write(json.dumps(row) + "\n")
            out.flush()
            rows += found
    print(table(rows, args.variants))


if __name__ == "__main__":
    main()
