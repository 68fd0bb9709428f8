"""The Grasp record: validation, JSON/NPZ round trips without pickle, DexGraspBench layout."""

from __future__ import annotations

import json

import numpy as np
import pytest

from models.errors import GraspError
from models.grasp import Grasp, from_dexgraspbench, to_dexgraspbench

NAMES = ("j0", "j1", "j2", "j3")


def make_grasp(**kwargs) -> Grasp:
    base = dict(
        hand="toy",
        wrist_pos=[0.1, 0.2, 0.3],
        wrist_quat=[1.0, 0.0, 0.0, 0.0],
        grasp=[0.1, 0.2, 0.3, 0.4],
        pregrasp=[0.0, 0.1, 0.2, 0.3],
        squeeze=[0.2, 0.3, 0.4, 0.5],
        pregrasp_wrist_pos=[0.1, 0.2, 0.35],
        pregrasp_wrist_quat=[0.0, 1.0, 0.0, 0.0],
        joint_names=NAMES,
        anchors=np.arange(12.0).reshape(4, 3) / 100,
        instruction="Use a mug by handle",
        metrics={"success": True, "translation": 0.01},
    )
    base.update(kwargs)
    return Grasp(**base)


def assert_same(a: Grasp, b: Grasp) -> None:
    da, db = a.to_dict(), b.to_dict()
    assert da.keys() == db.keys()
    for key in da:
        if isinstance(da[key], list) and da[key] and isinstance(da[key][0], float | list):
            np.testing.assert_allclose(da[key], db[key])
        else:
            assert da[key] == db[key], key


@pytest.mark.parametrize("suffix", [".json", ".npz"])
def test_round_trip(tmp_path, suffix):
    g = make_grasp()
    path = g.save(tmp_path / f"g{suffix}")
    assert_same(g, Grasp.load(path))


def test_npz_needs_no_pickle(tmp_path):
    path = make_grasp().save(tmp_path / "g.npz")
    with np.load(path, allow_pickle=False) as npz:
        assert all(npz[k].dtype != object for k in npz.files)


def test_wrist_defaults_and_bodex_squeeze():
    g = Grasp.with_bodex_squeeze("toy", [0, 0, 0], [1, 0, 0, 0], [0.5, 0.5], [0.3, 0.4])
    np.testing.assert_allclose(g.squeeze, [0.7, 0.6])
    np.testing.assert_allclose(g.wrist_pose("squeeze"), g.wrist_pose("grasp"))
    np.testing.assert_allclose(g.wrist_pose("pregrasp"), [0, 0, 0, 1, 0, 0, 0])


def test_quaternion_is_normalized_and_moved_translates_every_phase():
    g = make_grasp(wrist_quat=[2.0, 0.0, 0.0, 0.0])
    np.testing.assert_allclose(g.wrist_quat, [1, 0, 0, 0])
    moved = g.moved([0.05, 0, 0])
    for phase in ("pregrasp", "grasp", "squeeze"):
        delta = moved.wrist_pose(phase)[:3] - g.wrist_pose(phase)[:3]
        np.testing.assert_allclose(delta, [0.05, 0, 0])


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"grasp": [0.1, np.nan, 0.3, 0.4]}, "NaN"),
        ({"squeeze": [0.1, 0.2]}, "squeeze joints: 2 values"),
        ({"wrist_pos": [0.0, 0.0]}, "wrist_pos: expected 3"),
        ({"wrist_quat": [0, 0, 0, 0]}, "zero quaternion"),
        ({"anchors": np.zeros((4, 2))}, "anchors"),
        ({"joint_names": ("a", "b")}, "joint_names"),
        ({"hand": ""}, "hand"),
    ],
)
def test_malformed_records_raise_clear_errors(kwargs, message):
    with pytest.raises(GraspError, match=message):
        make_grasp(**kwargs)


def test_check_hand_reports_joint_count():
    with pytest.raises(GraspError, match="4 joint values but hand"):
        make_grasp().check_hand(["a", "b", "c"])


def test_unknown_fields_and_bad_files(tmp_path):
    d = make_grasp().to_dict() | {"colour": "red"}
    with pytest.raises(GraspError, match="unknown grasp fields"):
        Grasp.from_dict(d)
    with pytest.raises(GraspError, match="no such grasp file"):
        Grasp.load(tmp_path / "missing.json")
    (tmp_path / "bad.json").write_text("{")
    with pytest.raises(GraspError, match="not a JSON"):
        Grasp.load(tmp_path / "bad.json")
    with pytest.raises(GraspError, match=".json or .npz"):
        make_grasp().save(tmp_path / "g.txt")


IDENTITY = np.eye(4)
# a toy hand file whose root frame is 3 cm along the root link's z axis and turned 90 degrees
# about its x axis
OFFSET = np.array([0.0, 0.0, 0.03, np.sqrt(0.5), np.sqrt(0.5), 0.0, 0.0])


def test_dexgraspbench_layout_round_trip_with_joint_map():
    xml = ("x_j2", "x_j0", "x_j3", "x_j1", "x_extra")
    joint_map = {n: f"x_{n}" for n in NAMES}
    g = make_grasp()
    rows = to_dexgraspbench(g, root_offset=IDENTITY, xml_joint_names=xml, joint_map=joint_map)
    assert rows["grasp_qpos"].shape == (7 + len(xml),)
    np.testing.assert_array_equal(rows["grasp_qpos"][:7], g.wrist_pose("grasp"))
    np.testing.assert_allclose(rows["grasp_qpos"][7:], [0.3, 0.1, 0.4, 0.2, 0.0])
    back = from_dexgraspbench(
        rows["pregrasp_qpos"],
        rows["grasp_qpos"],
        rows["squeeze_qpos"],
        root_offset=IDENTITY,
        hand="toy",
        joint_names=NAMES,
        xml_joint_names=xml,
        joint_map=joint_map,
    )
    for phase in ("pregrasp", "grasp", "squeeze"):
        np.testing.assert_allclose(back.joints(phase), g.joints(phase))
        np.testing.assert_array_equal(back.wrist_pose(phase), g.wrist_pose(phase))


@pytest.mark.parametrize("as_matrix", [False, True])
def test_dexgraspbench_root_offset_moves_every_phase_and_round_trips(as_matrix):
    """Rows hold the hand file's root frame: wrist pose composed with the offset, per phase."""
    from scipy.spatial.transform import Rotation

    offset = OFFSET
    if as_matrix:
        offset = np.eye(4)
        offset[:3, :3] = Rotation.from_quat(OFFSET[3:], scalar_first=True).as_matrix()
        offset[:3, 3] = OFFSET[:3]
    g = make_grasp(wrist_quat=[0.0, 0.0, 1.0, 0.0])  # wrist turned 180 degrees about y
    rows = to_dexgraspbench(g, root_offset=offset, xml_joint_names=NAMES)
    # grasp: root 3 cm along the wrist's z, which is the world's -z
    np.testing.assert_allclose(rows["grasp_qpos"][:3], [0.1, 0.2, 0.27], atol=1e-12)
    # pregrasp wrist turned 180 degrees about x: its z is the world's -z as well
    np.testing.assert_allclose(rows["pregrasp_qpos"][:3], [0.1, 0.2, 0.32], atol=1e-12)
    for phase in ("pregrasp", "grasp", "squeeze"):
        wrist = g.wrist_pose(phase)
        root = rows[f"{phase}_qpos"][:7]
        expected = Rotation.from_quat(wrist[3:], scalar_first=True) * Rotation.from_quat(
            OFFSET[3:], scalar_first=True
        )
        assert (Rotation.from_quat(root[3:], scalar_first=True).inv() * expected).magnitude() < 1e-9
    back = from_dexgraspbench(
        rows["pregrasp_qpos"],
        rows["grasp_qpos"],
        rows["squeeze_qpos"],
        root_offset=offset,
        hand="toy",
        joint_names=NAMES,
        xml_joint_names=NAMES,
    )
    for phase in ("pregrasp", "grasp", "squeeze"):
        np.testing.assert_allclose(back.joints(phase), g.joints(phase))
        np.testing.assert_allclose(back.wrist_pose(phase), g.wrist_pose(phase), atol=1e-12)


def test_dexgraspbench_layout_errors():
    with pytest.raises(GraspError, match="not in the XML's joints"):
        to_dexgraspbench(make_grasp(), root_offset=IDENTITY, xml_joint_names=("a", "b", "c", "d"))
    with pytest.raises(GraspError, match="expected 11 values"):
        from_dexgraspbench(
            np.zeros(10),
            np.zeros(11),
            np.zeros(11),
            root_offset=IDENTITY,
            hand="toy",
            joint_names=NAMES,
            xml_joint_names=NAMES,
        )
    with pytest.raises(GraspError, match="zero root quaternion"):
        from_dexgraspbench(
            np.zeros(11),
            np.zeros(11),
            np.zeros(11),
            root_offset=IDENTITY,
            hand="toy",
            joint_names=NAMES,
            xml_joint_names=NAMES,
        )
    skew = np.eye(4)
    skew[0, 1] = 0.5
    for bad, match in ((skew, "not a rigid transform"), (np.zeros(6), "4x4 transform or 7")):
        with pytest.raises(GraspError, match=match):
            to_dexgraspbench(make_grasp(), root_offset=bad, xml_joint_names=NAMES)


def test_damaged_files_are_named_and_saving_makes_folders(tmp_path):
    """A truncated NPZ raised BadZipFile, an empty file EOFError, invalid UTF-8
    UnicodeDecodeError, and saving into a missing folder FileNotFoundError."""
    grasp = make_grasp(metrics={"epsilon": np.float64(0.2), "votes": np.array([1, 2])})
    npz = grasp.save(tmp_path / "new" / "deeper" / "g.npz")  # folders made, numpy metrics kept
    assert Grasp.load(npz).metrics == {"epsilon": 0.2, "votes": [1, 2]}
    data = npz.read_bytes()
    (tmp_path / "cut.npz").write_bytes(data[: len(data) // 2])
    (tmp_path / "empty.json").write_bytes(b"")
    (tmp_path / "latin.json").write_bytes(b'{"hand": "\xff"}')
    (tmp_path / "names.json").write_text(
        json.dumps(json.loads(grasp.to_json()) | {"joint_names": 5})
    )
    for name, message in (
        ("cut.npz", "cut.npz: unreadable grasp NPZ .*is the file complete"),
        ("empty.json", "empty.json is empty"),
        ("latin.json", "latin.json is not UTF-8"),
        ("names.json", "names.json: joint_names: expected a list"),
    ):
        with pytest.raises(GraspError, match=message):
            Grasp.load(tmp_path / name)
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    with pytest.raises(GraspError, match="in the way"):
        grasp.save(blocker / "g.json")
    with pytest.raises(GraspError, match="cannot be saved"):
        make_grasp(metrics={"thing": object()}).save(tmp_path / "m.json")
    assert not list(tmp_path.glob(".*.tmp*"))  # no half-written file left behind
    with pytest.raises(GraspError, match="expected numbers, got booleans"):
        make_grasp(grasp=[True, False, True, False])
