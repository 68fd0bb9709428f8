"""Time per plan with a plan's solves shared over processes, against one process, interleaved.

    python -m eval.plan_time --split test --pairs-per-hand 16 --processes 1 2

One plan at a time (torch on one thread, as in eval.benchmark's workers): every pair is planned
once per process count (`schedule.solve_processes`), the counts taken in turn pair by pair so
that a machine slowing down over the run weighs on all of them alike (this VM's speed drifts
by 10-20% between runs of the same work). Prints per hand the median wall time per plan for
each count, the median of the per-pair ratios to the first count, and how many pairs planned
the very same candidates (a plan's solves do not depend on where they run). The learned
proposer on each test object without its part labels, as in eval.benchmark; every plan starts
from a fresh object and builds its own programs, as a plan on a new object does.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from eval.benchmark import full_object, unlabelled
from eval.planner_benchmark import pairs
from models.hands import available_hands
from planner.functional import FunctionalPlanner
from planner.grasp_program import forget_programs
from planner.results import PlanResult
from planner.settings import LearnedSettings, PlannerSettings, ScheduleSettings


def signature(result: PlanResult) -> list[tuple]:
    """What must not depend on the process count: every candidate's solve and verdict."""
    return [
        (c.rank, c.solve.ok, c.quality, c.order, c.success, np.round(c.solve.wrist, 9).tolist())
        for c in result.candidates
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--split", default="test")
    parser.add_argument("--hands", nargs="+", default=available_hands())
    parser.add_argument("--pairs-per-hand", type=int, default=16)
    parser.add_argument("--processes", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--seed", type=int, default=0, help="sample seed of the learned stages")
    args = parser.parse_args()
    import torch

    torch.set_num_threads(1)
    print(
        f"{'hand':<8} {'pairs':>5} "
        + " ".join(f"{f'{p} proc s':>9}" for p in args.processes)
        + " "
        + " ".join(f"{f'{p}/{args.processes[0]}':>7}" for p in args.processes[1:])
        + "  same candidates"
    )
    for hand in args.hands:
        chosen = pairs(args.split, 1, [hand])
        step = max(1, len(chosen) // args.pairs_per_hand)
        chosen = chosen[::step][: args.pairs_per_hand]
        planners = {
            p: FunctionalPlanner(
                hand,
                PlannerSettings(
                    proposer="learned",
                    schedule=ScheduleSettings(solve_processes=p),
                    learned=LearnedSettings(seed=args.seed),
                ),
            )
            for p in args.processes
        }
        warm = unlabelled(full_object(chosen[0][1], chosen[0][2], False))
        for planner in planners.values():  # models loaded before anything is timed
            planner.plan(warm, chosen[0][3])
        times = {p: [] for p in args.processes}
        same = 0
        for k, (_, cat, seed, text) in enumerate(chosen):
            order = args.processes if k % 2 == 0 else args.processes[::-1]
            signatures = {}
            for p in order:
                # each plan on a fresh object with nothing built: as the first plan on it
                obj = unlabelled(full_object(cat, seed, False))
                forget_programs()
                start = time.perf_counter()
                result = planners[p].plan(obj, text)
                times[p].append(time.perf_counter() - start)
                signatures[p] = signature(result)
            same += all(s == signatures[args.processes[0]] for s in signatures.values())
        base = np.array(times[args.processes[0]])
        medians = " ".join(f"{statistics.median(times[p]):>9.2f}" for p in args.processes)
        ratios = " ".join(
            f"{float(np.median(np.array(times[p]) / base)):>7.2f}" for p in args.processes[1:]
        )
        print(f"{hand:<8} {len(chosen):>5} {medians} {ratios}  {same}/{len(chosen)}", flush=True)


if __name__ == "__main__":
    main()
