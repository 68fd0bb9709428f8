"""Wall time per grasp of the MuJoCo validator on one core, on DexGraspBench's reference grasps.

Prints the median over a sample of grasps for: the shared closing phase (simulated once, copied
per direction, sparse Jacobian, early rest exit) and DexGraspBench's way (closing re-simulated
per direction, MuJoCo's default Jacobian, full holds), and their ratio.
Scenes are compiled before timing (a real run compiles each (hand, object) once).

    /work/venv/bin/python benchmarks/bench_validation.py [--grasps 40] [--preset dexgraspbench]
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

from planner.validation import get_protocol, mjcf_hand, validate
from planner.validation.hands import mjcf_joint_names
from planner.validation.layout import read_rows, row_case

BENCH = Path(__file__).resolve().parents[1].parent / "shared" / "reference" / "dexgraspbench"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grasps", type=int, default=40, help="grasps sampled evenly from 200")
    parser.add_argument("--preset", default="dexgraspbench")
    args = parser.parse_args()
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # one core

    xml = BENCH / "hand" / "shadow_right_hand.xml"
    hand = mjcf_hand(xml)
    xml_joints = mjcf_joint_names(str(xml.resolve()))
    rows = read_rows(BENCH / "grasps.npz")
    idx = np.linspace(0, len(rows["grasp_qpos"]) - 1, args.grasps).round().astype(int)
    cases = [
        (*row_case(rows, i, hand, xml_joints, BENCH / "objects"), rows["obj_pose"][i]) for i in idx
    ]

    shared = get_protocol(args.preset)
    # DexGraspBench's way: the closing re-simulated per direction, every hold run to the end,
    # MuJoCo's default (dense) constraint Jacobian
    separate = shared.replace(share_closing=False, rest_speed=0.0, jacobian="auto")
    for grasp, obj, pose in cases:  # compile every scene first
        validate(grasp, obj, hand, get_protocol(args.preset, hold_time=0.2), object_pose=pose)

    timings = {}
    verdicts = {}
    for label, proto in (("shared closing", shared), ("DexGraspBench way", separate)):
        times, ok = [], []
        for grasp, obj, pose in cases:
            start = time.perf_counter()
            result = validate(grasp, obj, hand, proto, object_pose=pose)
            times.append(time.perf_counter() - start)
            ok.append(result.success)
        timings[label], verdicts[label] = np.array(times), ok
        print(
            f"{label:18s}: median {np.median(times):.3f} s/grasp, mean {np.mean(times):.3f} s "
            f"({len(cases)} grasps, {np.mean(ok):.0%} held, preset {args.preset}, one core)"
        )
    assert verdicts["shared closing"] == verdicts["DexGraspBench way"]
    ratio = np.median(timings["DexGraspBench way"]) / np.median(timings["shared closing"])
    total = timings["DexGraspBench way"].sum() / timings["shared closing"].sum()
    print(f"speed-up (DexGraspBench way / shared closing): median {ratio:.2f}x, total {total:.2f}x")


if __name__ == "__main__":
    main()
