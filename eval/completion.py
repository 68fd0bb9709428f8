"""How much of an object a single depth view shows, and how much completion adds.

    python -m eval.completion --split test --objects-per-category 3

Per category, on its objects of the split: the camera of models.objects.views (320 x 240 rays,
1 mm depth noise) sees the object; models.objects.completion completes the view. Reported:
coverage (the share of the object's dense surface samples within 5 mm of the cloud) of the
view and of the completed cloud; the completed cloud's error (distance of its points to the
surface, median, 90th and 99th percentile, mm); how many views were swept about a vertical axis
(and which share of their points); which mirror plane the points not swept are reflected
through (the vertical one through the axis along them, "axial"; else the view's own: the
vertical one facing the camera, another vertical one, the horizontal one below, or none); the
completion's time.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from collections import Counter
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from models.objects import make_object
from models.objects.completion import complete_view, find_completion, smooth
from models.objects.names import CATEGORY_NAMES
from models.objects.splits import seeds
from models.objects.views import single_view_object

NEAR = 0.005  # m: a surface sample this close to the cloud counts as covered


@dataclass
class Row:
    category: str
    seed: int
    points: int
    view_coverage: float
    completed_coverage: float
    error_median_mm: float
    error_p90_mm: float
    error_p99_mm: float  # phantom surfaces (a part mirrored to where it is not) show here
    plane: str
    swept: float  # share of the seen points swept about a vertical axis (0: no revolution)
    seconds: float


def plane_kind(normal: np.ndarray | None, view: np.ndarray) -> str:
    if normal is None:
        return "none"
    if abs(normal[2]) > 0.9:
        return "below"
    flat = np.array([view[0], view[1], 0.0])
    facing = abs(normal @ flat) / max(np.linalg.norm(flat), 1e-9) > 0.99
    return "facing" if facing else "turned"


def measure(category: str, seed: int) -> Row:
    obj = make_object(category, seed)
    view = single_view_object(obj, seed=seed)
    start = time.perf_counter()
    done = complete_view(view)
    seconds = time.perf_counter() - start
    plan = find_completion(smooth(view.points), np.asarray(view.viewpoint, dtype=float))
    turn, mirror = plan.revolution, plan.mirror
    surface = obj.points

    def coverage(points: np.ndarray) -> float:
        return float((cKDTree(points).query(surface)[0] < NEAR).mean())

    error = cKDTree(surface).query(done.points)[0] * 1000
    look = surface.mean(axis=0) - view.viewpoint
    return Row(
        category,
        seed,
        len(view.points),
        coverage(view.points),
        coverage(done.points),
        float(np.median(error)),
        float(np.percentile(error, 90)),
        float(np.percentile(error, 99)),
        "axial" if plan.axial else plane_kind(None if mirror is None else mirror.normal, look),
        0.0 if turn is None else float(turn.swept.mean()),
        seconds,
    )


def table(rows: list[Row]) -> str:
    lines = [
        "| category | objects | view coverage | completed coverage | error median / p90 / p99 (mm) "
        "| swept about an axis | mirror planes | s |",
        "|---|---|---|---|---|---|---|---|",
    ]
    groups = [(c, [r for r in rows if r.category == c]) for c in CATEGORY_NAMES]
    groups.append(("all", rows))
    for name, group in groups:
        if not group:
            continue
        planes = Counter(r.plane for r in group)
        swept = [r.swept for r in group if r.swept > 0]
        share = f" ({100 * np.mean(swept):.0f}% of points)" if swept else ""
        lines.append(
            f"| {name} | {len(group)} | {100 * np.mean([r.view_coverage for r in group]):.0f}% "
            f"| {100 * np.mean([r.completed_coverage for r in group]):.0f}% "
            f"| {statistics.median(r.error_median_mm for r in group):.1f} / "
            f"{statistics.median(r.error_p90_mm for r in group):.1f} / "
            f"{statistics.median(r.error_p99_mm for r in group):.1f} "
            f"| {len(swept)}{share} "
            f"| {', '.join(f'{k} {v}' for k, v in sorted(planes.items()))} "
            f"| {statistics.median(r.seconds for r in group):.2f} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m eval.completion", description=__doc__)
    p.add_argument("--split", default="test", choices=("train", "val", "test", "heldout"))
    p.add_argument("--objects-per-category", type=int, default=3)
    p.add_argument("--out", default="runs/eval_completion.json")
    args = p.parse_args(argv)
    rows = [
        measure(category, seed)
        for category in CATEGORY_NAMES
        for seed in seeds(category, args.split, args.objects_per_category)
    ]
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps([asdict(r) for r in rows], indent=1))
    print(table(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
