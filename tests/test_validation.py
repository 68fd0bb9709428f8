"""The MuJoCo validator against DexGraspBench's reference grasps (skipped where absent)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from models.errors import GraspError, HandError, ObjectError
from models.grasp import Grasp
from planner.validation import (
    as_collision_object,
    find_object,
    get_protocol,
    mjcf_hand,
    validate,
)
from planner.validation.batch import validate_many
from planner.validation.hands import mjcf_joint_names
from planner.validation.layout import read_rows, row_case
from planner.validation.protocol import ProtocolError

REFERENCE = Path(__file__).resolve().parents[1].parent / "shared" / "reference"
BENCH = REFERENCE / "dexgraspbench"
HAND_XML = BENCH / "hand" / "shadow_right_hand.xml"

needs_reference = pytest.mark.skipif(
    not (BENCH / "grasps.npz").is_file() or not HAND_XML.is_file(),
    reason=f"DexGraspBench reference data not found under {BENCH}",
)


@pytest.fixture(scope="module")
def rows():
    return read_rows(BENCH / "grasps.npz")


@pytest.fixture(scope="module")
def hand():
    return mjcf_hand(HAND_XML)


def reference_case(rows, hand, i):
    xml = mjcf_joint_names(str(HAND_XML.resolve()))
    grasp, obj = row_case(rows, i, hand, xml, BENCH / "objects")
    return grasp, obj, rows["obj_pose"][i]


def first(rows, success: bool) -> int:
    return int(np.flatnonzero(rows["reference_success"] == success)[0])


@needs_reference
def test_reference_success_and_failure(rows, hand):
    for i in (first(rows, True), first(rows, False)):
        grasp, obj, pose = reference_case(rows, hand, i)
        result = validate(grasp, obj, hand, "dexgraspbench", object_pose=pose)
        assert result.success == bool(rows["reference_success"][i])
        assert result.contact_count == int(rows["reference_contact_num"][i])
        assert result.grasp_penetration == pytest.approx(rows["reference_ho_pene"][i], abs=2e-4)
        assert 0.09 < result.object_mass < 0.11
        assert result.wall_time > 0 and result.simulated_time > 0
        if result.success:
            assert len(result.directions) == 6 and all(d.held for d in result.directions)
            # a resting object may end a hold early, after the rest window; never past 2 s
            rest = get_protocol("dexgraspbench").rest_window
            assert 0.8 + 6 * rest - 1e-9 <= result.simulated_time <= 0.8 + 6 * 2.0 + 1e-9
            assert result.simulated_time < 0.8 + 6 * 2.0  # this grasp's object does come to rest
            full = validate(
                grasp, obj, hand, get_protocol("dexgraspbench", rest_speed=0.0), object_pose=pose
            )
            assert full.success and full.simulated_time == pytest.approx(0.8 + 6 * 2.0)
        else:
            assert not result.directions[-1].held
            # failure is judged at the protocol's checks only (every 0.2 s), as DexGraspBench does
            checks = result.directions[-1].hold_time / 0.2
            assert checks == pytest.approx(round(checks))


@needs_reference
def test_moved_away_and_no_squeeze_fail(rows, hand):
    grasp, obj, pose = reference_case(rows, hand, first(rows, True))
    moved = validate(grasp.moved([0.05, 0.0, 0.0]), obj, hand, object_pose=pose)
    assert not moved.success
    no_squeeze = Grasp.from_dict(grasp.to_dict() | {"squeeze": grasp.grasp.tolist()})
    assert not validate(no_squeeze, obj, hand, object_pose=pose).success


@needs_reference
def test_shared_closing_equals_per_direction_closing(rows, hand):
    short = get_protocol("dexgraspbench", hold_time=0.4, all_directions=True)
    grasp, obj, pose = reference_case(rows, hand, first(rows, True))
    shared = validate(grasp, obj, hand, short, object_pose=pose)
    separate = validate(grasp, obj, hand, short.replace(share_closing=False), object_pose=pose)
    assert shared.success == separate.success
    for a, b in zip(shared.directions, separate.directions, strict=True):
        assert a.translation == pytest.approx(b.translation, abs=1e-9)
        assert a.rotation_deg == pytest.approx(b.rotation_deg, abs=1e-6)
    assert separate.simulated_time > shared.simulated_time


@needs_reference
def test_sparse_jacobian_matches_mujoco_default(rows, hand):
    # the speed setting stores the same equations differently: only round-off may differ
    short = get_protocol("dexgraspbench", hold_time=0.4, all_directions=True)
    grasp, obj, pose = reference_case(rows, hand, first(rows, True))
    sparse = validate(grasp, obj, hand, short, object_pose=pose)
    auto = validate(grasp, obj, hand, short.replace(jacobian="auto"), object_pose=pose)
    assert sparse.success == auto.success
    for a, b in zip(sparse.directions, auto.directions, strict=True):
        assert a.translation == pytest.approx(b.translation, abs=1e-5)
        assert a.rotation_deg == pytest.approx(b.rotation_deg, abs=0.01)


@needs_reference
def test_early_stop_and_all_directions(rows, hand):
    grasp, obj, pose = reference_case(rows, hand, first(rows, False))
    early = validate(grasp, obj, hand, object_pose=pose)
    full = validate(grasp, obj, hand, object_pose=pose, all_directions=True)
    assert early.success is False and full.success is False
    assert len(full.directions) == 6
    assert len(early.directions) <= len(full.directions)


@needs_reference
def test_validate_many_parallel_matches_serial(rows, hand):
    idx = [first(rows, False), first(rows, True)]
    cases = [reference_case(rows, hand, i) for i in idx]
    proto = get_protocol("dexgraspbench", hold_time=0.4)
    args = ([c[0] for c in cases], [c[1] for c in cases], hand, proto)
    poses = [c[2] for c in cases]
    serial = validate_many(*args, object_poses=poses, workers=1)
    parallel = validate_many(*args, object_poses=poses, workers=2)
    assert [r.success for r in serial] == [r.success for r in parallel]
    assert [r.translation for r in serial] == pytest.approx([r.translation for r in parallel])


@needs_reference
def test_errors_are_clear(rows, hand):
    grasp, obj, pose = reference_case(rows, hand, 0)
    with pytest.raises(GraspError, match="NaN"):
        Grasp.from_dict(grasp.to_dict() | {"grasp": [np.nan] * grasp.dof})
    short = Grasp.from_dict(
        grasp.to_dict()
        | {k: grasp.joints(k)[:-1].tolist() for k in ("pregrasp", "grasp", "squeeze")}
        | {"joint_names": None}
    )
    with pytest.raises(GraspError, match="21 joint values but hand"):
        validate(short, obj, hand)
    with pytest.raises(ObjectError, match="unknown object 'teapot'"):
        find_object(BENCH / "objects", "teapot")
    with pytest.raises(ObjectError, match="NaN"):
        validate(grasp, [np.full((8, 3), np.nan)], hand)
    with pytest.raises(ObjectError, match="object pose"):
        validate(grasp, obj, hand, object_pose=[0, 0, 0])
    with pytest.raises(HandError, match="no such MJCF"):
        mjcf_hand(BENCH / "missing.xml")
    with pytest.raises(HandError, match="not a joint"):
        mjcf_hand(HAND_XML, joint_map={"rh_FFJ4": "nope"})


def test_protocol_presets_and_overrides():
    assert get_protocol("dexgraspbench").hold_time == 2.0
    assert get_protocol("paper").hold_time == 3.0
    p = get_protocol("paper", max_translation=0.02, friction=(0.5, 0.01))
    assert (p.max_translation, p.friction, p.checks, p.steps_per_check) == (
        0.02,
        (0.5, 0.01),
        15,
        50,
    )
    with pytest.raises(ProtocolError, match="unknown protocol preset"):
        get_protocol("nope")
    with pytest.raises(ProtocolError, match="unknown protocol settings"):
        get_protocol("paper", hold=3)
    with pytest.raises(ProtocolError, match="positive"):
        get_protocol("paper", timestep=0)
    with pytest.raises(ProtocolError, match="unknown jacobian"):
        get_protocol("paper", jacobian="banded")
    with pytest.raises(ProtocolError, match="rest_window must be positive"):
        get_protocol("paper", rest_window=0.0)
    # rest checks every 10 steps over 6 checks; failure checks every 50 steps, as before
    rest = get_protocol("dexgraspbench")
    assert (rest.steps_per_rest_check, rest.rest_checks, rest.steps_per_check) == (10, 6, 50)
    with pytest.raises(ProtocolError, match="gravity must be a bool"):
        get_protocol("paper", gravity="maybe")  # e.g. --set gravity=maybe


def test_object_inputs_are_normalized():
    cube = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)

    class Model:
        name = "cube"

        def collision_pieces(self):
            return [cube]

    a = as_collision_object(Model(), scale=0.02)
    b = as_collision_object([cube * 0.02], name="cube")
    assert a.key == b.key and a.mass_volume() == pytest.approx(0.04**3)
    with pytest.raises(ObjectError, match="no collision pieces"):
        as_collision_object([])
    with pytest.raises(ObjectError, match="cannot use"):
        as_collision_object(42)


@needs_reference
def test_cli_reports_agreement(tmp_path, capsys):
    import planner.cli as cli

    out = tmp_path / "results.json"
    argv = [
        "validate",
        str(BENCH / "grasps.npz"),
        "--hand-xml",
        str(HAND_XML),
        "--objects",
        str(BENCH / "objects"),
        "--limit",
        "2",
        "--workers",
        "1",
        "--set",
        "hold_time=0.4",
        "--json",
        "--out",
        str(out),
    ]
    assert cli.main(argv) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["grasps"] == 2 and "agreement" in summary
    assert len(json.loads(out.read_text())["grasps"]) == 2
    assert sys.modules["planner.commands.validate"]
