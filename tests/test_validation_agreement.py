"""Acceptance: verdicts agree with DexGraspBench's on >= 95% of the 200 reference grasps."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from models.grasp import from_dexgraspbench
from planner.validation import find_object, mjcf_hand
from planner.validation.batch import validate_many
from planner.validation.hands import mjcf_joint_names

BENCH = Path(__file__).resolve().parents[1].parent / "shared" / "reference" / "dexgraspbench"
HAND_XML = BENCH / "hand" / "shadow_right_hand.xml"


@pytest.mark.slow
def test_agreement_with_dexgraspbench():
    if not (BENCH / "grasps.npz").is_file() or not HAND_XML.is_file():
        pytest.skip(f"DexGraspBench reference data not found under {BENCH}")
    with np.load(BENCH / "grasps.npz", allow_pickle=False) as npz:
        rows = {k: npz[k] for k in npz.files}
    hand = mjcf_hand(HAND_XML)
    xml = mjcf_joint_names(str(HAND_XML.resolve()))
    n = len(rows["grasp_qpos"])
    grasps = [
        from_dexgraspbench(
            rows["pregrasp_qpos"][i],
            rows["grasp_qpos"][i],
            rows["squeeze_qpos"][i],
            hand=hand.name,
            joint_names=hand.joint_names,
            xml_joint_names=xml,
        )
        for i in range(n)
    ]
    objects = [
        find_object(BENCH / "objects", str(rows["object"][i]), float(rows["scale"][i]))
        for i in range(n)
    ]
    results = validate_many(
        grasps, objects, hand, "dexgraspbench", object_poses=list(rows["obj_pose"])
    )
    ours = np.array([r.success for r in results])
    agreement = float((ours == rows["reference_success"]).mean())
    print(f"agreement {agreement:.1%} on {n} grasps; success {ours.mean():.1%}")
    assert agreement >= 0.95
