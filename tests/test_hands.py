"""Hands: one description, identical kinematics in PyTorch, Drake and MuJoCo."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET

import mujoco
import numpy as np
import pytest
import torch
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.systems.framework import DiagramBuilder
from scipy.spatial.transform import Rotation

from models.errors import HandError
from models.hands import load_hand
from models.hands.mujoco_spec import WRIST_JOINT
from models.hands.primitives import signed_distance
from tests.conftest import reference_dir


def random_configs(hand, n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    q = rng.uniform(hand.lower, hand.upper, size=(n, hand.dof))
    quat = rng.normal(size=(n, 4))
    wrist = np.concatenate(
        [rng.uniform(-0.3, 0.3, (n, 3)), quat / np.linalg.norm(quat, axis=1)[:, None]], 1
    )
    return wrist, q


def drake_hand(hand, filter_self_collisions=True, merge_hull_links=False):
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
    handle = hand.add_to_plant(
        plant,
        scene_graph,
        filter_self_collisions=filter_self_collisions,
        merge_hull_links=merge_hull_links,
    )
    plant.Finalize()
    diagram = builder.Build()
    context = plant.GetMyContextFromRoot(diagram.CreateDefaultContext())
    return plant, handle, context


def mujoco_hand(hand):
    model = hand.mujoco_spec().compile()
    qadr = {
        mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j): model.jnt_qposadr[j]
        for j in range(model.njnt)
    }
    return model, mujoco.MjData(model), qadr


def set_mujoco(hand, model, data, qadr, wrist, q) -> None:
    data.qpos[qadr[WRIST_JOINT] : qadr[WRIST_JOINT] + 7] = wrist
    for name, value in zip(hand.joint_names, q, strict=True):
        data.qpos[qadr[name]] = value
    mujoco.mj_forward(model, data)


def test_fk_agrees_in_torch_drake_mujoco(hand_name):
    assert_fk_agrees(load_hand(hand_name))


def assert_fk_agrees(hand) -> None:
    """Every link's origin, PyTorch vs Drake vs MuJoCo, at 100 random configurations."""
    wrist, q = random_configs(hand, 100)
    torch_poses = hand.link_poses(torch.tensor(wrist), torch.tensor(q)).numpy()
    plant, handle, context = drake_hand(hand)
    model, data, qadr = mujoco_hand(hand)
    worst = 0.0
    for k in range(len(q)):
        handle.set_state(plant, context, wrist[k], q[k])
        set_mujoco(hand, model, data, qadr, wrist[k], q[k])
        for i, link in enumerate(hand.link_names):
            x_drake = plant.EvalBodyPoseInWorld(context, plant.GetBodyByName(link, handle.instance))
            x_mj = data.xpos[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, link)]
            worst = max(
                worst,
                np.abs(x_drake.translation() - torch_poses[k, i, :3, 3]).max(),
                np.abs(x_mj - torch_poses[k, i, :3, 3]).max(),
            )
    assert worst < 1e-5, f"link origins differ by {worst:.2e} m"


def test_fk_batch_float32_matches_float64(hand_name):
    hand = load_hand(hand_name)
    wrist, q = random_configs(hand, 16, seed=1)
    p64 = hand.surface_points(torch.tensor(wrist), torch.tensor(q))
    p32 = hand.surface_points(
        torch.tensor(wrist, dtype=torch.float32), torch.tensor(q, dtype=torch.float32)
    )
    assert p64.shape == (16, 512, 3)
    assert torch.allclose(p64.float(), p32, atol=1e-5)


MENAGERIE = {
    "shadow": "shadow_hand/right_hand.xml",
    "allegro": "wonik_allegro/right_hand.xml",
    "leap": "leap_hand/right_hand.xml",
}


@pytest.mark.parametrize("hand_name", sorted(MENAGERIE))
def test_fingertips_match_menagerie(hand_name):
    """Joints matched by name, palm frames aligned: our root link frame is the vendor's
    root body frame (no fixed offset)."""
    hand = load_hand(hand_name)
    vendor = mujoco.MjModel.from_xml_path(str(reference_dir("hands") / MENAGERIE[hand_name]))
    data = mujoco.MjData(vendor)
    root = mujoco.mj_name2id(vendor, mujoco.mjtObj.mjOBJ_BODY, hand.root_link)
    _, q = random_configs(hand, 50, seed=2)
    identity = torch.tensor([[0, 0, 0, 1.0, 0, 0, 0]]).repeat(len(q), 1).double()
    ours = hand.fingertip_positions(identity, torch.tensor(q)).numpy()
    worst = 0.0
    for k in range(len(q)):
        data.qpos[:] = 0
        for name, value in zip(hand.joint_names, q[k], strict=True):
            j = mujoco.mj_name2id(vendor, mujoco.mjtObj.mjOBJ_JOINT, name)
            data.qpos[vendor.jnt_qposadr[j]] = value
        mujoco.mj_kinematics(vendor, data)
        r_root, p_root = data.xmat[root].reshape(3, 3), data.xpos[root]
        for f, tip in enumerate(hand.meta.fingertips):
            b = mujoco.mj_name2id(vendor, mujoco.mjtObj.mjOBJ_BODY, tip.link)
            world = data.xmat[b].reshape(3, 3) @ tip.point + data.xpos[b]
            worst = max(worst, np.linalg.norm(r_root.T @ (world - p_root) - ours[k, f]))
    print(f"{hand_name}: worst fingertip error against Menagerie {worst * 1000:.4f} mm")
    assert worst < 3e-3


def test_open_pose_has_no_self_collision(hand_name):
    hand = load_hand(hand_name)
    identity = np.array([0, 0, 0, 1.0, 0, 0, 0])
    model, data, qadr = mujoco_hand(hand)
    set_mujoco(hand, model, data, qadr, identity, hand.open_pose)
    assert data.ncon == 0
    plant, handle, context = drake_hand(hand, filter_self_collisions=False)
    handle.set_state(plant, context, identity, hand.open_pose)
    query = plant.get_geometry_query_input_port().Eval(context)
    assert query.ComputePointPairPenetration() == []
    # the check can fail: a fist drives fingers into each other and the palm
    fist = hand.lower + 0.95 * (hand.upper - hand.lower) * (hand.closing_direction > 0)
    set_mujoco(hand, model, data, qadr, identity, fist)
    handle.set_state(plant, context, identity, fist)
    assert data.ncon > 0 or query.ComputePointPairPenetration() != []


def test_surface_points_lie_on_link_geometry(hand_name):
    hand = load_hand(hand_name)
    idx, local = hand.surface
    assert idx.shape == (512,) and local.shape == (512, 3)
    assert len(set(idx)) == len(hand.link_names), "every link carries surface points"
    for li, link in enumerate(hand.link_names):
        pts = local[idx == li]
        dist = np.min([signed_distance(g, pts) for g in hand.tree.geoms[link]], axis=0)
        assert np.abs(dist).max() < 5e-4, f"{link}: {np.abs(dist).max():.2e} m off the surface"


def test_surface_points_are_fixed_across_loads(hand_name):
    hand = load_hand(hand_name)
    idx, local = hand.surface
    fresh = type(hand)(hand.folder, hand.meta, hand.tree)
    np.testing.assert_array_equal(idx, fresh.surface[0])
    np.testing.assert_array_equal(local, fresh.surface[1])


def test_unknown_hand_lists_available():
    with pytest.raises(HandError, match="allegro, leap, shadow"):
        load_hand("nohand")


def test_wrong_joint_vector_names_expected_dof(hand_name):
    hand = load_hand(hand_name)
    wrist = torch.tensor([[0, 0, 0, 1.0, 0, 0, 0]])
    with pytest.raises(HandError, match=f"expected {hand.dof} values.*{hand.joint_names[0]}"):
        hand.link_poses(wrist, torch.zeros(1, hand.dof + 1))
    with pytest.raises(HandError, match="NaN"):
        hand.check_joints(np.full(hand.dof, np.nan))


def test_user_hand_loads_from_folder(tmp_path, hand_name):
    builtin = load_hand(hand_name)
    folder = tmp_path / "myhand"
    shutil.copytree(builtin.folder, folder)
    meta = json.loads((folder / "hand.json").read_text())
    meta["name"] = "myhand"
    (folder / "hand.json").write_text(json.dumps(meta))
    mine = load_hand(folder)
    assert mine.name == "myhand" and mine.dof == builtin.dof
    assert mine.mujoco_spec().compile().nu == len(builtin.actuators())


def test_coupled_joints_share_one_actuator(hand_name):
    """Each coupling is one tendon actuator; the rest one actuator per joint; the projection
    onto the couplings keeps the plan ratio within limits."""
    hand = load_hand(hand_name)
    model = hand.mujoco_spec().compile()
    coupled = sum(len(c.joints) for c in hand.meta.couplings)
    assert model.nu == hand.dof - coupled + len(hand.meta.couplings)
    assert model.ntendon == len(hand.meta.couplings)
    q = np.random.default_rng(0).uniform(hand.lower, hand.upper, size=(5, hand.dof))
    projected = hand.couple(q)
    assert hand.coupling_violation(projected) < 1e-12
    assert np.all(projected >= hand.lower) and np.all(projected <= hand.upper)
    assert np.allclose(hand.couple(projected), projected)


def test_shadow_couples_j1_j2_like_menagerie():
    """ShadowHand: J1 and J2 of FF, MF, RF, LF ride one tendon each (Menagerie: 18 actuators
    for 22 joints); the thumb's joints are independent."""
    hand = load_hand("shadow")
    pairs = {tuple(sorted(c.joints)) for c in hand.meta.couplings}
    assert pairs == {(f"rh_{f}J1", f"rh_{f}J2") for f in ("FF", "MF", "RF", "LF")}
    assert len(hand.actuators()) == 18


@pytest.mark.parametrize(
    "coupling, message",
    [
        ({"name": "x", "joints": ["nope", "nope2"], "tendon": [1, 1]}, "not in joint_order"),
        ({"name": "x", "joints": ["J1"], "tendon": [1]}, "2 or more"),
        ({"name": "x", "joints": ["J1", "J2"], "tendon": [1]}, "1 values for 2 joints"),
        ({"name": "x", "joints": ["J1", "J2"], "tendon": [1, 1], "plan_ratio": [0, 1]}, "non-zero"),
        ({"joints": ["J1", "J2"]}, "must be an object"),
    ],
)
def test_bad_coupling_is_named(tmp_path, coupling, message):
    folder = tmp_path / "bad"
    shutil.copytree(load_hand("allegro").folder, folder)
    meta = json.loads((folder / "hand.json").read_text())
    names = meta["joint_order"]
    coupling = json.loads(
        json.dumps(coupling).replace('"J1"', f'"{names[1]}"').replace('"J2"', f'"{names[2]}"')
    )
    meta["couplings"] = [coupling]
    (folder / "hand.json").write_text(json.dumps(meta))
    with pytest.raises(HandError, match=message):
        load_hand(folder)


def test_user_hand_missing_metadata_names_fields(tmp_path):
    folder = tmp_path / "partial"
    shutil.copytree(load_hand("allegro").folder, folder)
    meta = json.loads((folder / "hand.json").read_text())
    del meta["fingertips"], meta["palm"]["normal"]
    (folder / "hand.json").write_text(json.dumps(meta))
    with pytest.raises(HandError, match="missing fields: fingertips, palm.normal"):
        load_hand(folder)
    (folder / "hand.json").unlink()
    with pytest.raises(HandError, match="needs hand.urdf and hand.json"):
        load_hand(folder)


def test_user_hand_program_hulls_need_links_with_several_boxes(tmp_path):
    folder = tmp_path / "hulls"
    shutil.copytree(load_hand("allegro").folder, folder)
    meta = json.loads((folder / "hand.json").read_text())
    for link in ("ff_distal", "no_such_link"):  # one box; not a link
        (folder / "hand.json").write_text(json.dumps({**meta, "program_hull_links": [link]}))
        with pytest.raises(HandError, match=f"program_hull_links names '{link}' with"):
            load_hand(folder)


def test_cli_hands_json():
    out = subprocess.run(
        [sys.executable, "-m", "planner.cli", "hands", "--json"],
        capture_output=True,
        text=True,
        check=True,
    )
    hands = {h["name"]: h for h in json.loads(out.stdout)}
    assert {"shadow": 22, "allegro": 16, "leap": 16} == {n: h["dof"] for n, h in hands.items()}
    assert all(len(h["anchor_fingers"]) == 4 for h in hands.values())
    for name, h in hands.items():  # the closing the planner validates with, from hand.json
        meta = load_hand(name).meta
        assert (h["squeeze_depth"], h["retry_squeeze_depths"], h["pinch_proposals"]) == (
            meta.squeeze_depth,
            list(meta.retry_squeeze_depths),
            meta.pinch_proposals,
        )


def test_cli_unknown_hand_is_a_clear_error():
    out = subprocess.run(
        [sys.executable, "-m", "planner.cli", "hands", "nohand"], capture_output=True, text=True
    )
    assert out.returncode == 2
    assert "unknown hand 'nohand'" in out.stderr and "Traceback" not in out.stderr


def test_program_hulls_contain_the_link_boxes_and_leave_the_open_pose_free(hand_name):
    """Merged link hulls (hand.json program_hull_links) replace the boxes, are conservative
    (every point is at least as close to them), and leave the open pose free of self-collision;
    collision meshes stay as thinned hulls."""
    hand = load_hand(hand_name)
    plain, plain_handle, plain_context = drake_hand(hand, filter_self_collisions=False)
    plant, handle, context = drake_hand(hand, filter_self_collisions=False, merge_hull_links=True)
    merged = len(handle.geometry_ids)
    boxes = sum(
        sum(g.kind == "box" for g in hand.tree.geoms[link]) for link in hand.meta.program_hull_links
    )
    assert merged == plain.num_collision_geometries() - boxes + len(hand.meta.program_hull_links)
    # conservative: no point is closer to the boxes than to the hulls
    rng = np.random.default_rng(1)
    wrist, q = np.array([0, 0, 0, 1.0, 0, 0, 0]), (hand.lower + hand.upper) / 2
    points = rng.uniform(-0.12, 0.12, (300, 3))
    distances = []
    for p, h, c in ((plain, plain_handle, plain_context), (plant, handle, context)):
        h.set_state(p, c, wrist, q)
        query = p.get_geometry_query_input_port().Eval(c)
        distances.append(
            [min(d.distance for d in query.ComputeSignedDistanceToPoint(x)) for x in points]
        )
    # collision meshes keep a thinned hull in the program: within 1 mm of the full one
    meshes = any(g.kind == "mesh" for geoms in hand.tree.geoms.values() for g in geoms)
    assert np.all(np.array(distances[1]) <= np.array(distances[0]) + (1e-3 if meshes else 1e-9))
    open_q = np.array([hand.meta.open_pose[j] for j in hand.joint_names])
    handle.set_state(plant, context, np.array([0, 0, 0, 1.0, 0, 0, 0]), open_q)
    query = plant.get_geometry_query_input_port().Eval(context)
    pairs = query.ComputeSignedDistancePairwiseClosestPoints(0.0)
    assert not [(p.id_A, p.id_B, p.distance) for p in pairs if p.distance < 0]


def test_user_hand_closing_values_must_be_positive(tmp_path):
    folder = tmp_path / "closing"
    shutil.copytree(load_hand("leap").folder, folder)
    meta = json.loads((folder / "hand.json").read_text())
    assert load_hand("leap").meta.squeeze_depth == 1.0  # the default where hand.json is silent
    for field, value in (
        ("squeeze_depth", 0),
        ("pregrasp_clearance", -0.01),
        ("squeeze_depth", "2"),
        ("pregrasp_clearance", True),
    ):
        (folder / "hand.json").write_text(json.dumps({**meta, field: value}))
        with pytest.raises(HandError, match=f"{field} must be a positive number"):
            load_hand(folder)


def test_user_hand_pinch_proposals_must_be_a_count(tmp_path):
    folder = tmp_path / "pinches"
    shutil.copytree(load_hand("allegro").folder, folder)
    meta = json.loads((folder / "hand.json").read_text())
    for bad in (-1, 2.5, "4"):
        (folder / "hand.json").write_text(json.dumps({**meta, "pinch_proposals": bad}))
        with pytest.raises(HandError, match="pinch_proposals must be a whole number"):
            load_hand(folder)
    (folder / "hand.json").write_text(json.dumps({**meta, "pinch_proposals": 3}))
    assert load_hand(folder).meta.pinch_proposals == 3


def test_user_hand_retry_squeeze_depths(tmp_path):
    """Retry squeezes are optional (none where hand.json is silent), distinct, positive and
    other than the first squeeze; the old single `retry_squeeze_depth` is refused by name."""
    meta = json.loads((load_hand("allegro").folder / "hand.json").read_text())
    meta.pop("retry_squeeze_depths", None)
    silent = tmp_path / "silent"
    shutil.copytree(load_hand("allegro").folder, silent)
    (silent / "hand.json").write_text(json.dumps(meta))
    assert load_hand(silent).meta.retry_squeeze_depths == ()
    folder = tmp_path / "retry"
    shutil.copytree(load_hand("allegro").folder, folder)
    for bad in ([meta["squeeze_depth"]], [0.5, 0.5], [0], 3, ["3"], [True], None):
        (folder / "hand.json").write_text(json.dumps({**meta, "retry_squeeze_depths": bad}))
        with pytest.raises(HandError, match="retry_squeeze_depths must be a list of distinct"):
            load_hand(folder)
    (folder / "hand.json").write_text(json.dumps({**meta, "retry_squeeze_depth": 5}))
    with pytest.raises(HandError, match="did you mean 'retry_squeeze_depths'"):
        load_hand(folder)
    (folder / "hand.json").write_text(json.dumps({**meta, "retry_squeeze_depths": [5, 1]}))
    assert load_hand(folder).meta.retry_squeeze_depths == (5.0, 1.0)


# ---- fixed joints: links rigidly attached to their parent (fingertip bodies, mounting links)
def _fixed_joint(name: str, parent: str, child: str, pose: np.ndarray) -> ET.Element:
    joint = ET.Element("joint", name=name, type="fixed")
    ET.SubElement(joint, "parent", link=parent)
    ET.SubElement(joint, "child", link=child)
    rpy = Rotation.from_matrix(pose[:3, :3]).as_euler("xyz")
    ET.SubElement(
        joint,
        "origin",
        xyz=" ".join(f"{v:.17g}" for v in pose[:3, 3]),
        rpy=" ".join(f"{v:.17g}" for v in rpy),
    )
    return joint


BASE_TO_PALM = np.eye(4)
BASE_TO_PALM[:3, :3] = Rotation.from_euler("xyz", [0.3, -0.2, 0.5]).as_matrix()
BASE_TO_PALM[:3, 3] = [0.01, -0.02, 0.05]
SPACER = np.eye(4)
SPACER[:3, :3] = Rotation.from_euler("xyz", [0.1, 0.2, -0.3]).as_matrix()
SPACER[:3, 3] = [0.002, -0.001, 0.02]


def user_hand_with_fixed_links(tmp_path) -> tuple:
    """Allegro as a user's URDF might have it: a mounting root link `base` (no geometry, no
    inertia) with the palm on a fixed joint, and a fixed `ff_spacer` link between the first
    finger's proximal and medial links (ffj2 then starts from the spacer). Every other link
    keeps Allegro's frames, so their poses relative to the palm are the built-in hand's."""
    builtin = load_hand("allegro")
    folder = tmp_path / "fixed"
    shutil.copytree(builtin.folder, folder)
    tree = ET.parse(folder / "hand.urdf")
    robot = tree.getroot()
    robot.insert(0, ET.Element("link", name="base"))
    robot.insert(1, ET.Element("link", name="ff_spacer"))
    ffj2 = next(j for j in robot.findall("joint") if j.get("name") == "ffj2")
    origin = builtin.tree.joints["ff_medial"].origin
    rest = np.linalg.inv(SPACER) @ origin
    ffj2.find("parent").set("link", "ff_spacer")
    ffj2.find("origin").set("xyz", " ".join(f"{v:.17g}" for v in rest[:3, 3]))
    rpy = Rotation.from_matrix(rest[:3, :3]).as_euler("xyz")
    ffj2.find("origin").set("rpy", " ".join(f"{v:.17g}" for v in rpy))
    robot.append(_fixed_joint("base_to_palm", "base", "palm", BASE_TO_PALM))
    robot.append(_fixed_joint("ff_spacer_fixed", "ff_proximal", "ff_spacer", SPACER))
    tree.write(folder / "hand.urdf")
    meta = json.loads((folder / "hand.json").read_text())
    meta["name"] = "fixed"
    (folder / "hand.json").write_text(json.dumps(meta))
    return builtin, load_hand(folder)


def test_fixed_links_anywhere_in_a_user_urdf(tmp_path):
    """Fixed joints at the root, mid-finger and at the tips: the same 16 joints, the same
    link poses as the built-in hand (relative to the palm), and PyTorch, Drake and MuJoCo agree
    on every link, the joint-less ones included."""
    builtin, hand = user_hand_with_fixed_links(tmp_path)
    assert hand.root_link == "base" and hand.joint_names == builtin.joint_names
    assert len(hand.link_names) == len(builtin.link_names) + 2
    assert [j.name for j in hand.tree.moving_joints] == [j.name for j in builtin.tree.moving_joints]
    assert hand.tree.rigid_link("ff_spacer") == "ff_proximal"
    assert hand.tree.rigid_link("palm") == "base" and hand.tree.rigid_link("ff_tip") == "ff_distal"
    _, q = random_configs(hand, 20, seed=3)
    identity = torch.tensor([[0, 0, 0, 1.0, 0, 0, 0]], dtype=torch.float64).repeat(len(q), 1)
    ours = hand.link_poses(identity, torch.tensor(q)).numpy()
    theirs = builtin.link_poses(identity, torch.tensor(q)).numpy()
    for i, link in enumerate(builtin.link_names):
        expected = BASE_TO_PALM @ theirs[:, i]
        np.testing.assert_allclose(ours[:, hand.link_index(link)], expected, atol=1e-12)
    tips = builtin.fingertip_positions(identity, torch.tensor(q)).numpy()
    np.testing.assert_allclose(
        hand.fingertip_positions(identity, torch.tensor(q)).numpy(),
        tips @ BASE_TO_PALM[:3, :3].T + BASE_TO_PALM[:3, 3],
        atol=1e-12,
    )
    assert_fk_agrees(hand)
    # MuJoCo keeps every link a body of its own, with its own mass (none for base, spacer)
    ours_mj, theirs_mj = hand.mujoco_spec().compile(), builtin.mujoco_spec().compile()
    for link in hand.link_names:
        mass = ours_mj.body(link).mass[0]
        assert mass == (theirs_mj.body(link).mass[0] if link in builtin.link_names else 0.0)
    # the same surface points, on the same links
    idx, local = hand.surface
    ref_idx, ref_local = builtin.surface
    assert [hand.link_names[i] for i in idx] == [builtin.link_names[i] for i in ref_idx]
    np.testing.assert_allclose(local, ref_local, atol=1e-12)


def mujoco_collision_pairs(model: mujoco.MjModel) -> set[tuple[str, str]]:
    """Body pairs of the hand MuJoCo may collide: contype/conaffinity, then its body filter
    (one weld body; a weld body and its parent weld body; <exclude> pairs)."""
    excluded = set(model.exclude_signature.tolist())
    hand_geoms = [g for g in range(model.ngeom) if model.geom_bodyid[g] > 0]
    pairs = set()
    for i, g1 in enumerate(hand_geoms):
        for g2 in hand_geoms[i + 1 :]:
            if not (
                model.geom_contype[g1] & model.geom_conaffinity[g2]
                or model.geom_contype[g2] & model.geom_conaffinity[g1]
            ):
                continue
            b1, b2 = sorted((int(model.geom_bodyid[g1]), int(model.geom_bodyid[g2])))
            w1, w2 = model.body_weldid[b1], model.body_weldid[b2]
            p1 = model.body_weldid[model.body_parentid[w1]]
            p2 = model.body_weldid[model.body_parentid[w2]]
            if w1 == w2 or (w1 and w2 and (w1 == p2 or w2 == p1)):
                continue
            if (b1 << 16) + b2 in excluded:
                continue
            pairs.add((model.body(b1).name, model.body(b2).name))
    return pairs


def drake_collision_pairs(hand) -> set[tuple[str, str]]:
    """Body pairs of the hand Drake may collide (hand-hand filtering off, as in the program)."""
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
    handle = hand.add_to_plant(plant, scene_graph, filter_self_collisions=False)
    plant.Finalize()
    inspector = scene_graph.model_inspector()
    order = {name: i for i, name in enumerate(hand.link_names)}
    body = {
        g: plant.GetBodyFromFrameId(inspector.GetFrameId(g)).name() for g in handle.geometry_ids
    }
    pairs = set()
    for i, g1 in enumerate(handle.geometry_ids):
        for g2 in handle.geometry_ids[i + 1 :]:
            if body[g1] != body[g2] and not inspector.CollisionFiltered(g1, g2):
                pairs.add(tuple(sorted((body[g1], body[g2]), key=order.get)))
    return pairs


def test_drake_and_mujoco_collide_the_same_link_pairs(hand_name, tmp_path):
    """The grasp program's hand-hand constraint sees the pairs MuJoCo's validation collides:
    a fixed link (Allegro's fingertips) is filtered against its own rigid body and the parent
    rigid body, as MuJoCo's weld-body filter does, not only against its parent link."""
    hands = [load_hand(hand_name)]
    if hand_name == "allegro":
        hands.append(user_hand_with_fixed_links(tmp_path)[1])
    for hand in hands:
        model = hand.mujoco_spec().compile()
        order = {name: i for i, name in enumerate(hand.link_names)}
        mujoco_pairs = {tuple(sorted(p, key=order.get)) for p in mujoco_collision_pairs(model)}
        assert mujoco_pairs == drake_collision_pairs(hand)
    if hand_name == "allegro":
        assert ("ff_medial", "ff_tip") not in mujoco_pairs
        assert ("ff_tip", "mf_tip") in mujoco_pairs


def _collision_geoms(model: mujoco.MjModel, body: int) -> list[tuple]:
    """(type, size, pos, quat) of a body's colliding geoms, rounded, sorted."""
    out = []
    for g in np.flatnonzero(model.geom_bodyid == body):
        if model.geom_contype[g] or model.geom_conaffinity[g]:
            out.append(
                (
                    int(model.geom_type[g]),
                    *np.round(np.concatenate([model.geom_size[g], model.geom_pos[g]]), 7),
                    *np.round(model.geom_quat[g], 6),
                )
            )
    return sorted(out)


def test_allegro_bodies_match_dexgraspbench():
    """Allegro as DexGraspBench's hand file (Menagerie, kp 5) builds it: every body, the four
    light tip bodies included, with the file's mass, inertia, centre of mass, inverse weight
    (a tip's contacts are as soft: 41.6, not the 21.3 of a tip fused into its distal link),
    collision geometry, and the same joints, actuators and exclusions."""
    from planner.validation.hands import MJCF_PREFIX, mjcf_hand, project_hand

    xml = reference_dir("dexgraspbench", "hand") / "allegro_right_hand.xml"
    ours = project_hand("allegro").spec_factory().compile()
    theirs = mjcf_hand(xml).spec_factory().compile()
    hand = load_hand("allegro")
    assert {"ff_tip", "mf_tip", "rf_tip", "th_tip"} <= set(hand.link_names)
    for link in hand.link_names:
        a, b = ours.body(link).id, theirs.body(MJCF_PREFIX + link).id
        for field in ("body_mass", "body_inertia", "body_ipos", "body_invweight0"):
            np.testing.assert_allclose(
                getattr(ours, field)[a],
                getattr(theirs, field)[b],
                rtol=1e-5,
                atol=1e-10,
                err_msg=f"{link} {field}",
            )
        assert _collision_geoms(ours, a) == _collision_geoms(theirs, b), link
    assert ours.body("ff_tip").invweight0[0] == pytest.approx(41.6, abs=0.1)
    for joint in hand.joint_names:
        a, b = ours.joint(joint), theirs.joint(MJCF_PREFIX + joint)
        np.testing.assert_allclose(a.range, b.range)
        for field in ("dof_damping", "dof_armature", "dof_frictionloss"):
            assert getattr(ours, field)[a.dofadr[0]] == getattr(theirs, field)[b.dofadr[0]]
    for u in range(theirs.nu):
        joint = theirs.joint(theirs.actuator_trnid[u, 0]).name.removeprefix(MJCF_PREFIX)
        mine = next(
            v for v in range(ours.nu) if ours.joint(ours.actuator_trnid[v, 0]).name == joint
        )
        for field in ("actuator_gainprm", "actuator_biasprm", "actuator_ctrlrange"):
            np.testing.assert_allclose(getattr(ours, field)[mine], getattr(theirs, field)[u])

    def excluded(model):
        names = {
            (model.body(s >> 16).name, model.body(s & 0xFFFF).name) for s in model.exclude_signature
        }
        return {tuple(sorted(n.removeprefix(MJCF_PREFIX) for n in p)) for p in names}

    assert excluded(ours) == excluded(theirs)


def _build_tool():
    import importlib.util

    path = load_hand("allegro").folder.parents[2] / "tools" / "build_hand_urdf.py"
    spec = importlib.util.spec_from_file_location("build_hand_urdf", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_allegro_urdf_is_the_build_tools_with_fixed_tips(tmp_path):
    """tools/build_hand_urdf.py writes Allegro's URDF with its tip bodies as fixed links; fused
    instead, the same hand has one body per distal link + tip (their mass and centre of mass
    summed) and the same fingertips and surface points."""
    reference_dir("hands", "wonik_allegro")
    tool = _build_tool()
    hand = load_hand("allegro")
    assert tool.build("allegro") == hand.urdf_path.read_text()
    folder = tmp_path / "fused"
    shutil.copytree(hand.folder, folder)
    (folder / "hand.urdf").write_text(tool.build("allegro", "fuse"))
    meta = json.loads((folder / "hand.json").read_text())
    for tip in meta["fingertips"]:
        tip["link"] = tip["link"].replace("_tip", "_distal")
    (folder / "hand.json").write_text(json.dumps({**meta, "name": "fused"}))
    fused = load_hand(folder)
    assert set(hand.link_names) - set(fused.link_names) == {"ff_tip", "mf_tip", "rf_tip", "th_tip"}
    wrist, q = random_configs(hand, 10, seed=4)
    np.testing.assert_allclose(
        hand.fingertip_positions(torch.tensor(wrist), torch.tensor(q)),
        fused.fingertip_positions(torch.tensor(wrist), torch.tensor(q)),
        atol=1e-12,
    )
    np.testing.assert_array_equal(
        hand.surface_points(torch.tensor(wrist), torch.tensor(q)),
        fused.surface_points(torch.tensor(wrist), torch.tensor(q)),
    )
    split, whole = hand.mujoco_spec().compile(), fused.mujoco_spec().compile()
    for finger in ("ff", "mf", "rf", "th"):
        distal, tip = split.body(f"{finger}_distal"), split.body(f"{finger}_tip")
        assert distal.subtreemass[0] == pytest.approx(whole.body(f"{finger}_distal").mass[0])
        assert tip.mass[0] == pytest.approx(0.00684, abs=1e-5)
        com = (distal.mass * distal.ipos + tip.mass * tip.ipos) / distal.subtreemass
        np.testing.assert_allclose(com, whole.body(f"{finger}_distal").ipos, atol=1e-8)


def test_user_urdf_joint_errors_are_named(tmp_path):
    """Prismatic joints are refused by name; hand.json joint_order lists revolute joints only."""
    folder = tmp_path / "joints"
    shutil.copytree(load_hand("allegro").folder, folder)
    urdf = (folder / "hand.urdf").read_text()
    (folder / "hand.urdf").write_text(
        urdf.replace('name="ffj1" type="revolute"', 'name="ffj1" type="prismatic"')
    )
    with pytest.raises(HandError, match="joint ffj1 is prismatic"):
        load_hand(folder)
    (folder / "hand.urdf").write_text(urdf)
    meta = json.loads((folder / "hand.json").read_text())
    meta["joint_order"].append("ff_tip_fixed")
    meta["open_pose"]["ff_tip_fixed"] = meta["closing_direction"]["ff_tip_fixed"] = 0
    (folder / "hand.json").write_text(json.dumps(meta))
    with pytest.raises(HandError, match=r"names fixed joints \['ff_tip_fixed'\]"):
        load_hand(folder)


def test_collision_meshes_are_convex_hulls_in_every_model():
    """ShadowHand's distal links collide with the vendor's hulls: read by the URDF reader (hull
    vertices), MuJoCo (a mesh geom) and the grasp program (a thinned Convex), and sampled by the
    surface points."""
    hand = load_hand("shadow")
    geoms = hand.tree.geoms["rh_ffdistal"]
    assert [g.kind for g in geoms] == ["mesh"] and len(geoms[0].vertices) > 1000
    model = hand.mujoco_spec().compile()
    distal = model.body("rh_ffdistal").id
    kinds = {int(model.geom_type[g]) for g in range(model.ngeom) if model.geom_bodyid[g] == distal}
    assert int(mujoco.mjtGeom.mjGEOM_MESH) in kinds
    idx, _ = hand.surface
    assert hand.link_index("rh_ffdistal") in set(idx.tolist())


@pytest.mark.parametrize(
    "filename, message",
    [("meshes/missing.obj", "cannot read collision mesh"), ("package://x/y.obj", "relative")],
)
def test_bad_collision_mesh_is_named(tmp_path, filename, message):
    folder = tmp_path / "meshy"
    shutil.copytree(load_hand("shadow").folder, folder)
    urdf = folder / "hand.urdf"
    urdf.write_text(urdf.read_text().replace("meshes/f_distal_pst_hull.obj", filename))
    with pytest.raises(HandError, match=message):
        load_hand(folder)


# ---- issue 28: every malformed hand a HandError naming the file, the field and the fix ----
def test_builtin_hands_pass_the_load_check(hand_name):
    """load_hand checks a user's hand against MuJoCo and Drake; the built-in hands skip that
    at load (it costs a second per process), so it is run here: their surface points sample,
    MuJoCo and Drake build them, and every link agrees in PyTorch, MuJoCo and Drake."""
    load_hand(hand_name).check()


def _user_hand(tmp_path, name="mine", meta_change=None, urdf_change=None):
    folder = tmp_path / name
    shutil.copytree(load_hand("allegro").folder, folder)
    meta = json.loads((folder / "hand.json").read_text())
    if meta_change is not None:
        meta = meta_change(meta)
    (folder / "hand.json").write_text(meta if isinstance(meta, str) else json.dumps(meta))
    if urdf_change is not None:
        urdf = folder / "hand.urdf"
        urdf.write_text(urdf_change(urdf.read_text()))
    return folder


@pytest.mark.parametrize(
    "change, message",
    [
        (lambda m: m | {"open_pose": 5}, "open_pose must be an object"),
        (lambda m: m | {"urdf": None}, "urdf .* must be a non-empty string, got None"),
        (lambda m: "[1, 2]", "must be a JSON object .* it holds a list"),
        (
            lambda m: m | {"fingertips": [{"name": "th", "point": [0, 0, 0], "radius": 0.01}]},
            r"fingertips\[0\] lacks link",
        ),
        (lambda m: m | {"anchor_fingers": "th ff mf rf"}, "anchor_fingers must name 4"),
        (
            lambda m: m | {"closing_direction": dict.fromkeys(m["joint_order"], "1")},
            "closing_direction must be 1",
        ),
        (
            lambda m: m | {"palm": {**m["palm"], "normal": [0, 0, 0]}},
            "palm.normal must be a non-zero",
        ),
        (
            lambda m: m | {"actuator": {"kp": float("nan")}},
            "actuator.kp must be a positive number",
        ),
        (
            lambda m: m | {"pinch_proposal": 3},
            "unknown field in hand.json: 'pinch_proposal' .did you mean 'pinch_proposals'",
        ),
        (
            lambda m: m | {"open_pose": {**m["open_pose"], "ffj0": 3.0}},
            "open_pose is outside the joint limits .* ffj0 3",
        ),
        (
            lambda m: m | {"learned_start_closure": 1.0},
            r"learned_start_closure must be a number from 0 .* got 1.0",
        ),
    ],
)
def test_user_hand_json_faults_are_named(tmp_path, change, message):
    folder = _user_hand(tmp_path, meta_change=change)
    with pytest.raises(HandError, match=message) as err:
        load_hand(folder)
    assert str(folder / "hand.json") in str(err.value)


def test_user_hand_json_not_utf8_is_named(tmp_path):
    folder = _user_hand(tmp_path)
    (folder / "hand.json").write_bytes(b"\xff\xfe{")
    with pytest.raises(HandError, match="hand.json is not UTF-8 text"):
        load_hand(folder)


@pytest.mark.parametrize(
    "change, message",
    [
        (lambda u: u.replace('<axis xyz="0 0 1"/>', "", 1), r'needs <axis xyz="x y z"/>'),
        (
            lambda u: u.replace('lower="', 'lower="x', 1),
            "<limit lower> must be one finite number, got 'x",
        ),
        (
            lambda u: u.replace('lower="-0.47" upper="0.47"', 'lower="0.47" upper="-0.47"', 1),
            "lower 0.47 >= upper -0.47",
        ),
        (lambda u: u.replace("<child ", "<nochild ", 1), "needs <parent link> and <child link>"),
        (lambda u: u.replace('<axis xyz="0 0 1"', '<axis xyz="0 0 0"', 1), "zero axis"),
        (
            lambda u: u.replace('<mass value="', '<mass value="nan', 1),
            "<mass value> must be one finite number",
        ),
        (
            lambda u: u.replace('<box size="', '<box size="nan ', 1),
            "<box size> must be 3 positive numbers",
        ),
        (
            lambda u: u.replace("</robot>", '<link name="palm"/></robot>'),
            "two links are named palm",
        ),
    ],
)
def test_user_urdf_faults_are_named(tmp_path, change, message):
    folder = _user_hand(tmp_path, urdf_change=change)
    with pytest.raises(HandError, match=message) as err:
        load_hand(folder)
    assert str(folder / "hand.urdf") in str(err.value)


def test_user_hand_the_simulators_refuse_is_a_hand_error(tmp_path):
    """Faults only MuJoCo or Drake find (zero mass of a moving link; a visual mesh that is not
    there) are found when the hand loads, not in the middle of a validation or a plan."""
    import re

    massless = _user_hand(
        tmp_path,
        "massless",
        urdf_change=lambda u: re.sub(r'<mass value="[^"]*"', '<mass value="0"', u),
    )
    with pytest.raises(HandError, match="hand.urdf: MuJoCo cannot build this hand: .*mass > 0"):
        load_hand(massless)
    visual = '<visual><geometry><mesh filename="missing.obj"/></geometry></visual><visual>'
    unseen = _user_hand(tmp_path, "unseen", urdf_change=lambda u: u.replace("<visual>", visual, 1))
    with pytest.raises(HandError, match="hand.urdf: Drake cannot build this hand: .*missing.obj"):
        load_hand(unseen)


def test_hand_check_finds_a_reader_that_disagrees_with_the_simulators(tmp_path):
    """The load check compares every link in PyTorch, MuJoCo and Drake: a tree that differs from
    what the simulators read from the same URDF is refused."""
    from dataclasses import replace

    hand = load_hand(_user_hand(tmp_path))
    joints = dict(hand.tree.joints)
    moved = joints["ff_medial"].origin.copy()
    moved[2, 3] += 0.001
    joints["ff_medial"] = replace(joints["ff_medial"], origin=moved)
    wrong = type(hand)(hand.folder, hand.meta, replace(hand.tree, joints=joints))
    with pytest.raises(HandError, match="MuJoCo puts link ff_medial elsewhere"):
        wrong.check()


def test_hand_api_takes_arrays_lists_and_unbatched_inputs():
    """q as a tensor, array or list, of shape (dof,) or (B, dof); wrist (7,), (B, 7), (4, 4) or
    (B, 4, 4); a batch of one is repeated. The answer is always batched and the same."""
    hand = load_hand("allegro")
    wrist, q = random_configs(hand, 3, seed=7)
    ref = hand.fingertip_positions(torch.tensor(wrist), torch.tensor(q)).numpy()
    matrix = np.eye(4)
    matrix[:3, :3] = Rotation.from_quat(wrist[0, 3:], scalar_first=True).as_matrix()
    matrix[:3, 3] = wrist[0, :3]
    for w, j in [
        (wrist[0], q[0]),
        (wrist[0].tolist(), q[0].tolist()),
        (torch.tensor(wrist[:1]), q[:1]),
        (matrix, torch.tensor(q[0])),
        (torch.tensor(matrix[None]), q[0]),
    ]:
        out = hand.fingertip_positions(w, j)
        assert out.shape == (1, 4, 3) and out.dtype == torch.float64
        np.testing.assert_allclose(out.numpy(), ref[:1], atol=1e-12)
    many = hand.surface_points(wrist[0], q)  # one wrist for three joint vectors
    np.testing.assert_allclose(
        many[0].numpy(), hand.surface_points(wrist[0], q[0])[0].numpy(), atol=1e-12
    )
    assert many.shape == (3, 512, 3)
    qt = torch.tensor(q, requires_grad=True)
    hand.link_poses(torch.tensor(wrist), qt).sum().backward()
    assert qt.grad is not None and torch.isfinite(qt.grad).all()


@pytest.mark.parametrize(
    "wrist, q, message",
    [
        (
            np.zeros((1, 6)),
            np.zeros(16),
            r"wrist pose .* shape \(1, 6\); expected \(7,\) or \(B, 7\)",
        ),
        ([0, 0, 0, 0, 0, 0, 0], np.zeros(16), "zero quaternion"),
        ([0, 0, 0, 1, 1, 1, 1], np.zeros(16), r"non-unit \(norm 2\) quaternion"),
        (2 * np.eye(4), np.zeros(16), "not a rigid transform"),
        ([0, 0, 0, 1, 0, 0, 0], np.zeros(16, dtype=bool), "must hold real numbers, got booleans"),
        ([0, 0, 0, 1, 0, 0, 0], [[0.0] * 16, [0.0] * 3], "list of equal-length rows"),
        ([0, 0, 0, 1, 0, 0, 0], np.zeros((2, 1, 16)), r"shape \(2, 1, 16\); expected \(16,\)"),
        (
            np.tile([0, 0, 0, 1.0, 0, 0, 0], (2, 1)),
            np.zeros((3, 16)),
            "2 wrist poses for 3 joint vectors",
        ),
    ],
)
def test_hand_api_refuses_bad_wrists_and_joint_vectors(wrist, q, message):
    hand = load_hand("allegro")
    for api in (hand.link_poses, hand.fingertip_positions, hand.surface_points):
        with pytest.raises(HandError, match=message):
            api(wrist, q)
