"""DexGraspBench export: the root frame between a project hand and an MJCF hand file, rows that
put the file's hand where the project's hand is, and `drograsp export dexgraspbench`.

The hand files are DexGraspBench's, under ../shared/reference (skipped where absent); the
frame solver's own checks use the project's MuJoCo model of each hand, which needs nothing.
"""

from __future__ import annotations

import json
from pathlib import Path

import mujoco
import numpy as np
import pytest
import torch

from models.errors import HandError
from models.grasp import PHASES, Grasp, from_dexgraspbench, to_dexgraspbench
from models.hands import load_hand
from models.hands.mjcf_frame import POSITION_TOLERANCE, mjcf_root_offset
from planner.cli import main
from planner.validation.hands import FREE_JOINT, MJCF_PREFIX, mjcf_hand, mjcf_joint_names

BENCH = Path(__file__).resolve().parents[1].parent / "shared" / "reference" / "dexgraspbench"
BENCH_HANDS = ("shadow", "allegro", "leap")


def bench_xml(hand: str) -> Path:
    path = BENCH / "hand" / f"{hand}_right_hand.xml"
    if not path.is_file():
        pytest.skip(f"DexGraspBench hand file not found at {path}")
    return path


def random_grasp(hand_name: str, seed: int, **kwargs) -> Grasp:
    """Random wrist poses and joint values within the limits, a different one per phase."""
    hand = load_hand(hand_name)
    rng = np.random.default_rng(seed)

    def q():
        return rng.uniform(hand.lower, hand.upper)

    def quat():
        v = rng.normal(size=4)
        return v / np.linalg.norm(v)

    return Grasp(
        hand=hand_name,
        wrist_pos=rng.uniform(-0.2, 0.2, 3),
        wrist_quat=quat(),
        grasp=q(),
        pregrasp=q(),
        squeeze=q(),
        pregrasp_wrist_pos=rng.uniform(-0.2, 0.2, 3),
        pregrasp_wrist_quat=quat(),
        squeeze_wrist_pos=rng.uniform(-0.2, 0.2, 3),
        squeeze_wrist_quat=quat(),
        joint_names=tuple(hand.joint_names),
        **kwargs,
    )


# ---------------------------------------------------------------------- the frame solver
def _project_mjcf(hand_name: str, tmp_path: Path, edit=None) -> Path:
    """The project's own MuJoCo model of the hand as an MJCF file (`edit` changes its spec)."""
    spec = load_hand(hand_name).mujoco_spec()
    if edit is not None:
        edit(spec)
    path = tmp_path / f"{hand_name}.xml"
    path.write_text(spec.to_xml())
    return path


def test_root_offset_of_the_projects_own_mjcf_is_the_identity(hand_name, tmp_path):
    offset = mjcf_root_offset(hand_name, _project_mjcf(hand_name, tmp_path))
    np.testing.assert_array_equal(offset.pose, [0, 0, 0, 1, 0, 0, 0])
    assert offset.residual < 1e-9
    assert set(offset.bodies) == set(load_hand(hand_name).link_names)


def test_root_offset_refuses_files_of_another_hand(tmp_path):
    hand = load_hand("allegro")
    last = hand.link_names[-1]

    def move(spec):  # a body 0.1 mm off: not the same hand
        spec.body(last).pos = spec.body(last).pos + np.array([1e-4, 0.0, 0.0])

    with pytest.raises(HandError, match=rf"body '{last}' is 0\.\d+ mm off"):
        mjcf_root_offset("allegro", _project_mjcf("allegro", tmp_path, move))
    with pytest.raises(HandError, match="share 0 body names"):
        mjcf_root_offset("shadow", _project_mjcf("allegro", tmp_path))
    with pytest.raises(HandError, match="no such MJCF"):
        mjcf_root_offset("allegro", tmp_path / "missing.xml")


def test_root_offset_pairs_joints_through_a_joint_map(tmp_path):
    names = load_hand("leap").joint_names

    def rename(spec):
        for name in names:
            spec.joint(name).name = f"x_{name}"
        for actuator in spec.actuators:
            if actuator.target in names:
                actuator.target = f"x_{actuator.target}"

    xml = _project_mjcf("leap", tmp_path, rename)
    with pytest.raises(HandError, match="pass a joint map"):
        mjcf_root_offset("leap", xml)
    offset = mjcf_root_offset("leap", xml, {n: f"x_{n}" for n in names})
    np.testing.assert_array_equal(offset.pose, [0, 0, 0, 1, 0, 0, 0])
    # a map that swaps two joints moves the fingers apart: refused
    swapped = {n: f"x_{n}" for n in names} | {names[0]: f"x_{names[1]}", names[1]: f"x_{names[0]}"}
    with pytest.raises(HandError, match="mm off"):
        mjcf_root_offset("leap", xml, swapped)


# ---------------------------------------------------------------------- DexGraspBench's files
@pytest.mark.parametrize("hand_name", BENCH_HANDS)
def test_exported_rows_put_the_hand_file_where_the_project_hand_is(hand_name):
    """Forward kinematics of a row in DexGraspBench's hand file (as `drograsp validate
    --hand-xml` builds it: the row as qpos of a free root) equals the project's, per phase."""
    xml = bench_xml(hand_name)
    hand = load_hand(hand_name)
    offset = mjcf_root_offset(hand_name, xml)
    assert offset.residual < POSITION_TOLERANCE and len(offset.bodies) >= 16
    xml_joints = mjcf_joint_names(str(xml.resolve()))
    adapter = mjcf_hand(xml)
    model = adapter.spec_factory().compile()
    data = mujoco.MjData(model)
    free = model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, FREE_JOINT)]
    qadr = [
        model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, MJCF_PREFIX + n)]
        for n in xml_joints
    ]
    bodies = [
        mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, MJCF_PREFIX + b) for b in offset.bodies
    ]
    links = [hand.link_index(b) for b in offset.bodies]
    for seed in range(3):
        grasp = random_grasp(hand_name, seed)
        rows = to_dexgraspbench(grasp, root_offset=offset.pose, xml_joint_names=xml_joints)
        for phase in PHASES:
            row = rows[f"{phase}_qpos"]
            data.qpos[:] = model.qpos0
            data.qpos[free : free + 7] = row[:7]
            data.qpos[qadr] = row[7:]
            mujoco.mj_kinematics(model, data)
            wrist = torch.as_tensor(grasp.wrist_pose(phase)[None])
            q = torch.as_tensor(grasp.joints(phase)[None])
            poses = hand.link_poses(wrist, q)[0].numpy()[links]
            np.testing.assert_allclose(data.xpos[bodies], poses[:, :3, 3], atol=1e-6)
            rot = data.xmat[bodies].reshape(-1, 3, 3)
            np.testing.assert_allclose(rot, poses[:, :3, :3], atol=1e-6)


@pytest.mark.parametrize("hand_name", BENCH_HANDS)
def test_dexgraspbench_rows_round_trip(hand_name):
    xml = bench_xml(hand_name)
    offset = mjcf_root_offset(hand_name, xml)
    xml_joints = mjcf_joint_names(str(xml.resolve()))
    grasp = random_grasp(hand_name, 7, metrics={"success": True})
    rows = to_dexgraspbench(grasp, root_offset=offset.matrix, xml_joint_names=xml_joints)
    back = from_dexgraspbench(
        rows["pregrasp_qpos"],
        rows["grasp_qpos"],
        rows["squeeze_qpos"],
        root_offset=offset.pose,
        hand=hand_name,
        joint_names=grasp.joint_names,
        xml_joint_names=xml_joints,
        metrics={"success": True},
    )
    for phase in PHASES:
        np.testing.assert_allclose(back.wrist_pose(phase), grasp.wrist_pose(phase), atol=1e-12)
        np.testing.assert_array_equal(back.joints(phase), grasp.joints(phase))
    assert back.joint_names == grasp.joint_names and back.metrics == grasp.metrics


# ---------------------------------------------------------------------- the command
def test_export_command_writes_what_validate_reads(tmp_path, capsys):
    """One planned grasp: export, the object read back where it was, and `drograsp validate`
    with the hand file giving the project's verdict."""
    from models.objects import make_object
    from planner import plan_grasp
    from planner.objectref import object_ref
    from planner.validation import find_object

    xml = bench_xml("allegro")
    obj = make_object("bottle", 1)
    result = plan_grasp(obj, "Hold a bottle by body", "allegro")
    assert result.grasp is not None, "the planner found no grasp to export"
    grasp = result.grasp
    grasp.metrics["object"] = object_ref(obj)
    grasp_file = grasp.save(tmp_path / "g.json")
    out = tmp_path / "out"
    assert main(["export", "dexgraspbench", str(out), str(grasp_file), "--hand-xml", str(xml)]) == 0
    assert "wrote" in capsys.readouterr().out

    with np.load(out / "grasps.npz", allow_pickle=False) as npz:
        rows = {k: npz[k] for k in npz.files}
    assert set(rows) == {"object", "scale", "obj_pose"} | {f"{p}_qpos" for p in PHASES}
    n_xml = len(mjcf_joint_names(str(xml.resolve())))
    assert rows["grasp_qpos"].shape == (1, 7 + n_xml) and rows["object"].tolist() == ["bottle_1"]
    folder = out / "objects" / "bottle_1"
    pieces = obj.collision_pieces()
    assert len(list((folder / "convex_pieces").glob("convex_piece_*.obj"))) == len(pieces)
    assert (folder / "convex_pieces" / "convex_piece_000.obj").is_file()
    import trimesh

    simplified = trimesh.load(folder / "simplified.obj", force="mesh", process=False)
    lo, hi = simplified.bounds
    np.testing.assert_allclose((lo + hi) / 2, 0.0, atol=1e-12)
    assert np.linalg.norm(hi - lo) / 2 == pytest.approx(1.0)
    info = json.loads((folder / "info.json").read_text())
    assert set(info) == {"gravity_center", "obb", "scale", "density", "mass"}
    # the object as validate loads it (scaled, placed at obj_pose) is the planner's object
    scale, pose = float(rows["scale"][0]), rows["obj_pose"][0]
    np.testing.assert_array_equal(pose[3:], [1, 0, 0, 0])
    loaded = find_object(out / "objects", "bottle_1", scale)
    for mine, theirs in zip(pieces, loaded.pieces, strict=True):
        np.testing.assert_allclose(theirs.vertices + pose[:3], mine.vertices, atol=1e-12)
    assert loaded.mass_volume() == pytest.approx(sum(p.volume for p in pieces), rel=1e-9)

    report = tmp_path / "validated.json"
    args = ["validate", str(out / "grasps.npz"), "--hand-xml", str(xml)]
    args += ["--objects", str(out / "objects"), "--workers", "1", "--out", str(report)]
    assert main(args) == 0
    (validated,) = json.loads(report.read_text())["grasps"]
    assert validated["success"] == grasp.metrics["success"], validated


def test_export_command_refuses_bad_input(tmp_path, capsys):
    xml = bench_xml("allegro")
    grasp_file = random_grasp("allegro", 0).save(tmp_path / "g.json")  # names no object
    blocker = tmp_path / "file"
    blocker.write_text("")
    cases = [
        ([str(blocker / "out"), str(grasp_file)], "is not a folder"),
        ([str(blocker), str(grasp_file)], "not a folder"),
        ([str(tmp_path / "a"), str(tmp_path / "missing.json")], "no such grasp file"),
        ([str(tmp_path / "b"), str(grasp_file)], "names no object"),
    ]
    for argv, message in cases:
        code = main(["export", "dexgraspbench", *argv, "--hand-xml", str(xml)])
        assert code == 2 and message in capsys.readouterr().err, argv
    assert not (blocker.parent / "a").exists()
    other = random_grasp("leap", 0).save(tmp_path / "leap.json")
    code = main(
        ["export", "dexgraspbench", str(tmp_path / "c"), str(grasp_file), str(other)]
        + ["--hand-xml", str(xml), "--object", "bottle"]
    )
    assert code == 2 and "several hands" in capsys.readouterr().err
    code = main(
        ["export", "dexgraspbench", str(tmp_path / "d"), str(grasp_file)]
        + ["--hand-xml", str(tmp_path / "none.xml")]
    )
    assert code == 2 and "no such hand file" in capsys.readouterr().err
    bad_map = tmp_path / "map.json"
    bad_map.write_text("[1, 2]")
    code = main(
        ["export", "dexgraspbench", str(tmp_path / "e"), str(grasp_file)]
        + ["--hand-xml", str(xml), "--joint-map", str(bad_map), "--object", "bottle"]
    )
    assert code == 2 and "joint map" in capsys.readouterr().err
