"""Acceptance: verdicts agree with DexGraspBench's on >= 95% of the 200 reference grasps."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from planner.validation import mjcf_hand
from planner.validation.batch import validate_many
from planner.validation.hands import mjcf_joint_names
from planner.validation.layout import read_rows, row_case

BENCH = Path(__file__).resolve().parents[1].parent / "shared" / "reference" / "dexgraspbench"
HAND_XML = BENCH / "hand" / "shadow_right_hand.xml"


@pytest.mark.slow
def test_agreement_with_dexgraspbench():
    if not (BENCH / "grasps.npz").is_file() or not HAND_XML.is_file():
        pytest.skip(f"DexGraspBench reference data not found under {BENCH}")
    rows = read_rows(BENCH / "grasps.npz")
    hand = mjcf_hand(HAND_XML)
    xml = mjcf_joint_names(str(HAND_XML.resolve()))
    n = len(rows["grasp_qpos"])
    cases = [row_case(rows, i, hand, xml, BENCH / "objects") for i in range(n)]
    grasps = [grasp for grasp, _ in cases]
    objects = [obj for _, obj in cases]
    results = validate_many(
        grasps, objects, hand, "dexgraspbench", object_poses=list(rows["obj_pose"])
    )
    ours = np.array([r.success for r in results])
    agreement = float((ours == rows["reference_success"]).mean())
    print(f"agreement {agreement:.1%} on {n} grasps; success {ours.mean():.1%}")
    assert agreement >= 0.95
