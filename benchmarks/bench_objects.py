"""Benchmark the object library: generation time per category, and collision pieces from clouds.

    /work/venv/bin/python benchmarks/bench_objects.py [--runs 5] [--coacd]

Prints medians over `--runs` runs. `--coacd` also times one uncached CoACD run on a generated mug
(seconds; a cache in a temporary folder, so the user's cache is untouched).
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time

from models.objects import categories, cloud_pieces, load_object, make_object
from models.objects.surface import estimate_normals


def _median(fn, runs: int) -> tuple[float, object]:
    times, out = [], None
    for _ in range(runs):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times), out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--coacd", action="store_true")
    args = ap.parse_args()

    print(f"generation (median of {args.runs}, seeds 0..{args.runs - 1} cycled):")
    print(f"  {'category':14s} {'ms':>7s} {'faces':>6s} {'pieces':>6s}")
    total = []
    for name in categories():
        seed = iter(range(10**6))
        t, obj = _median(lambda n=name, s=seed: make_object(n, next(s)), args.runs)
        total.append(t)
        print(
            f"  {name:14s} {1000 * t:7.1f} {len(obj.mesh.faces):6d} {len(obj.construction_pieces):6d}"
        )
    print(f"  {'median':14s} {1000 * statistics.median(total):7.1f}")

    print("collision pieces from a 20k-point cloud (median of runs):")
    for name in ("mug", "teapot", "bowl", "knife"):
        pts = make_object(name, 0).sample_cloud(20000, seed=0)
        tn, normals = _median(lambda p=pts: estimate_normals(p.points), args.runs)
        tp, pieces = _median(lambda p=pts, n=normals: cloud_pieces(p.points, n), args.runs)
        tl, _ = _median(lambda p=pts: load_object(p.points).collision_pieces(), 1)
        print(
            f"  {name:8s} normals {1000 * tn:6.0f} ms  pieces {1000 * tp:6.0f} ms"
            f" ({len(pieces)} pieces)  load_object+pieces {1000 * tl:6.0f} ms"
        )

    if args.coacd:
        with tempfile.TemporaryDirectory() as tmp:
            os.environ["DROGRASP_CACHE"] = tmp
            mug = make_object("mug", 0)
            tc, pieces = _median(lambda: mug.collision_pieces("coacd"), 1)
            t2, _ = _median(lambda: make_object("mug", 0).collision_pieces("coacd"), 1)
            print(
                f"CoACD on a generated mug: {tc:.1f} s ({len(pieces)} pieces), cached {1000 * t2:.0f} ms"
            )


if __name__ == "__main__":
    main()
