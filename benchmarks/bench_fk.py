"""Batched forward-kinematics time per hand (PyTorch, CPU): median of repeated runs.

python benchmarks/bench_fk.py [--repeats 20]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
import torch

from models.hands import available_hands, load_hand


def median_ms(fn, repeats: int) -> float:
    fn()  # warm-up
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return 1000 * statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=20)
    args = parser.parse_args()
    torch.set_num_threads(1)
    print(f"torch {torch.__version__}, 1 thread, float32; median of {args.repeats} runs")
    print(
        f"{'hand':<8} {'batch':>6} {'link poses ms':>14} {'512 surface pts ms':>19} {'per item us':>12}"
    )
    for name in available_hands():
        hand = load_hand(name)
        for batch in (1, 1024):
            rng = np.random.default_rng(0)
            q = torch.tensor(
                rng.uniform(hand.lower, hand.upper, (batch, hand.dof)), dtype=torch.float32
            )
            wrist = torch.zeros(batch, 7)
            wrist[:, 3] = 1
            with torch.no_grad():
                t_links = median_ms(lambda h=hand, w=wrist, x=q: h.link_poses(w, x), args.repeats)
                t_pts = median_ms(lambda h=hand, w=wrist, x=q: h.surface_points(w, x), args.repeats)
            print(
                f"{name:<8} {batch:>6} {t_links:>14.3f} {t_pts:>19.3f} {1000 * t_pts / batch:>12.2f}"
            )


if __name__ == "__main__":
    main()
