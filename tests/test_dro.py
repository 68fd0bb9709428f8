"""The D(R,O) network: shapes, weights files, a tiny over-fit, resumable training, and the grasp
program's distance-matching cost."""

from __future__ import annotations

import hashlib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
import trimesh

from learned import train_dro
from learned.dro import (
    DROConfig,
    DRONet,
    input_hand_points,
    load_weights,
    place_hand,
    predict,
    save_weights,
    surface_targets,
)
from learned.weights import WeightsError
from models.errors import DrograspError
from models.hands import available_hands, load_hand
from planner.grasp_program import GraspTargets, grasp_program

DATA = Path(__file__).resolve().parents[1] / "data" / "grasps_v2"
TINY = DROConfig(edge_widths=(16, 16), feature_dim=32, kernel_hidden=16, k=8)


def _inputs(b: int = 2, n: int = 64, m: int = 96) -> tuple[torch.Tensor, ...]:
    g = torch.Generator().manual_seed(0)
    hand = torch.rand(b, n, 3, generator=g) * 0.1
    obj = torch.cat([torch.rand(b, m, 3, generator=g) * 0.1, torch.rand(b, m, 1, generator=g)], -1)
    return hand, obj, torch.nn.functional.normalize(torch.randn(b, 384, generator=g), dim=-1)


def test_network_shapes_and_positive_distances():
    torch.manual_seed(0)
    net = DRONet(TINY)
    hand, obj, text = _inputs()
    d = net(hand, obj, text)
    assert d.shape == (2, 64, 96) and bool((d > 0).all())
    sub = net(hand, obj, text, hand_index=torch.tensor([[0, 5], [1, 2]]))
    assert torch.allclose(sub[0], d[0, [0, 5]], atol=1e-6)


def test_weights_round_trip(tmp_path):
    torch.manual_seed(1)
    net = DRONet(TINY).eval()
    path = tmp_path / "w.safetensors"
    save_weights(net, path, {"steps": 3})
    back = load_weights(path)
    assert back.net.cfg == TINY and back.meta == {"steps": 3}
    hand, obj, text = _inputs()
    with torch.no_grad():
        assert torch.equal(net(hand, obj, text), back.net(hand, obj, text))


def test_missing_or_damaged_weights_name_the_file_and_the_fix(tmp_path):
    missing = tmp_path / "none.safetensors"
    with pytest.raises(WeightsError, match="none.safetensors.*drograsp train dro"):
        load_weights(missing)
    damaged = tmp_path / "bad.safetensors"
    damaged.write_bytes(b"\x08\x00\x00\x00\x00\x00\x00\x00{garbage")
    with pytest.raises(WeightsError, match="bad.safetensors.*damaged"):
        load_weights(damaged)
    other = tmp_path / "other.safetensors"
    save_weights(DRONet(TINY), other)
    from safetensors.torch import load_file, safe_open, save_file

    with safe_open(str(other), framework="pt") as f:
        header = f.metadata()
    tensors = load_file(str(other))
    tensors.pop(next(iter(tensors)))
    save_file(tensors, str(other), metadata=header)
    with pytest.raises(WeightsError, match="other.safetensors.*another network"):
        load_weights(other)
    # the interaction model's file is no D(R,O) network either
    save_file(tensors, str(other), metadata={"drograsp": '{"format": "drograsp-interaction/1"}'})
    with pytest.raises(WeightsError, match="other.safetensors.*format"):
        load_weights(other)


def _fake_embed(texts: list[str]) -> np.ndarray:
    """A fixed unit vector per text (the sentence encoder takes 10 s to load)."""
    out = []
    for t in texts:
        seed = int(hashlib.sha256(t.encode()).hexdigest()[:8], 16)
        v = np.random.default_rng(seed).normal(size=384)
        out.append(v / np.linalg.norm(v))
    return np.asarray(out, np.float32)


needs_data = pytest.mark.skipif(not (DATA / "meta.json").is_file(), reason="no dataset v2")


@needs_data
def test_tiny_overfit_reaches_low_loss(monkeypatch):
    """Two grasps, a small network, 60 steps on the same pairs: the clipped L1 falls to under
    a third and the error on the near pairs falls too."""
    monkeypatch.setattr(train_dro, "embed", _fake_embed)
    torch.manual_seed(0)
    torch.set_num_threads(1)
    cfg = train_dro.TrainConfig(str(DATA), "", hand_points=256, lr=1e-2, pose_weight=0, net=TINY)
    data = train_dro.prepare(DATA, "test", max_rows=2, progress=False)
    net = DRONet(TINY)
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr)
    rows = np.arange(2)
    before = train_dro.d_error(net.eval(), data, rows, cfg)
    net.train()
    batch = train_dro.make_batch(data, rows, cfg, None)
    index = np.arange(0, 512, 4)
    first = None
    for _ in range(60):
        loss = train_dro.losses(net, batch, replace(cfg, penetration_weight=0), index)["l1"]
        first = float(loss) if first is None else first
        opt.zero_grad()
        loss.backward()
        opt.step()
    after = train_dro.d_error(net.eval(), data, rows, cfg)
    assert float(loss) < first / 3 and after < before, (first, float(loss), before, after)


@needs_data
def test_training_writes_and_resumes(tmp_path, monkeypatch):
    monkeypatch.setattr(train_dro, "embed", _fake_embed)
    cfg = train_dro.TrainConfig(
        str(DATA), str(tmp_path), epochs=1, batch=2, max_rows=4, val_rows=2, net=TINY
    )
    weights = train_dro.train(cfg, progress=False)
    for name in ("checkpoint.pt", "loss.png", "dro.safetensors", "cache_train.npz"):
        assert (tmp_path / name).is_file()
    first = load_weights(weights)
    assert first.meta["steps"] == 2
    train_dro.train(cfg, progress=False)  # resumes at the end: nothing more to do
    again = load_weights(weights)
    for key, value in first.net.state_dict().items():
        assert torch.equal(value, again.net.state_dict()[key])
    with pytest.raises(train_dro.TrainingError, match="other settings"):
        train_dro.train(replace(cfg, lr=0.5), progress=False)


def _tiny_prediction_inputs(hand_name: str) -> tuple:
    """A tiny untrained network, a hand, a wrist above a random object input (512, 4) with
    unit normals, and a sentence embedding."""
    hand = load_hand(hand_name)
    torch.manual_seed(0)
    net = DRONet(TINY).eval()
    rng = np.random.default_rng(0)
    obj = np.c_[rng.uniform(-0.05, 0.05, (512, 3)), rng.uniform(0, 1, 512)]
    normals = rng.normal(size=(512, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    wrist = np.array([0, 0, 0.15, 1, 0, 0, 0.0])
    return net, hand, wrist, obj, normals, _fake_embed(["Use a mug by handle"])[0]


@pytest.mark.parametrize("hand_name", available_hands())
def test_predict_gives_a_target_for_every_hand_point(hand_name):
    net, hand, wrist, obj, _, text = _tiny_prediction_inputs(hand_name)
    pred = predict(net, hand, wrist, obj, text)
    assert pred.distances.shape == (512, 512) and pred.targets.shape == (512, 3)
    assert np.isfinite(pred.targets).all() and ((pred.closeness > 0) & (pred.closeness <= 1)).all()


@pytest.mark.parametrize("hand_name", available_hands())
def test_predict_places_by_surface_or_multilateration(hand_name):
    """Both placements give finite targets; the surface one needs the object's normals."""
    net, hand, wrist, obj, normals, text = _tiny_prediction_inputs(hand_name)
    surface = predict(net, hand, wrist, obj, text, normals, "surface")
    multi = predict(net, hand, wrist, obj, text, placement="multilateration")
    assert np.isfinite(surface.targets).all() and np.isfinite(multi.targets).all()
    assert not np.allclose(surface.targets, multi.targets)
    with pytest.raises(DrograspError, match="normals"):
        predict(net, hand, wrist, obj, text, placement="surface")
    with pytest.raises(DrograspError, match="placement"):
        predict(net, hand, wrist, obj, text, normals, "nearest")


def test_surface_targets_put_points_back_above_a_plane():
    """Exact distances to a dense patch of a plane (normals up): each point comes back within
    the grid spacing, whatever its height above the plane."""
    g = np.linspace(-0.05, 0.05, 41)  # 2.5 mm grid
    plane = torch.tensor([[x, y, 0.0] for x in g for y in g], dtype=torch.float64)[None]
    up = torch.zeros_like(plane)
    up[..., 2] = 1.0
    rng = np.random.default_rng(1)
    points = torch.tensor(
        np.c_[rng.uniform(-0.03, 0.03, (50, 2)), rng.uniform(0.0, 0.03, 50)], dtype=torch.float64
    )[None]
    placed = surface_targets(plane, up, torch.cdist(points, plane))
    assert float((placed - points).norm(dim=-1).max()) < 0.0025


@pytest.mark.parametrize("hand_name", available_hands())
def test_exact_distances_place_the_grasp_and_drake_follows(hand_name):
    """True D(R,O) of a grasp -> multilateration + Kabsch put every hand point back; the grasp
    program's distance-matching cost (point targets weighted by closeness) then moves the
    hand's points from the open pose to those targets."""
    hand = load_hand(hand_name)
    wrist = np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0])
    q_goal = 0.5 * hand.open_pose + 0.5 * (0.3 * hand.lower + 0.7 * hand.upper)
    q_goal = hand.couple(q_goal)
    truth = hand.surface_points(wrist, q_goal).double()
    # an "object" of points around the hand, 5-15 mm from its surface
    rng = np.random.default_rng(0)
    offsets = torch.tensor(rng.normal(size=(512, 3)))
    offsets = (
        offsets
        / offsets.norm(dim=1, keepdim=True)
        * torch.tensor(rng.uniform(0.005, 0.015, (512, 1)))
    )
    obj = (truth[0] + offsets)[None]
    placed = place_hand([hand.name], obj, torch.cdist(truth, obj), np.arange(512))
    assert float((placed - truth).norm(dim=-1).max()) < 1e-3
    weights = np.exp(-torch.cdist(truth, obj)[0].min(dim=1).values.numpy() / 0.01)
    # the program's object is a small box far from the hand: the cost alone moves the points
    box = trimesh.creation.box(extents=[0.02, 0.02, 0.02])
    program = grasp_program(hand, [box.vertices + [0.0, 0.0, -1.0]])
    index = np.arange(0, 512, 4)
    result = program.solve(
        GraspTargets(
            wrist,
            hand.open_pose,
            point_index=index,
            point_targets=placed[0, index].numpy(),
            point_weights=weights[index],
            fix_wrist=True,
        )
    )
    start = hand.surface_points(wrist, hand.open_pose)[0].double()
    end = hand.surface_points(result.wrist, result.q)[0].double()
    before = float((start[index] - truth[0, index]).norm(dim=1).mean())
    after = float((end[index] - truth[0, index]).norm(dim=1).mean())
    assert after < 0.25 * before and after < 0.005, (before, after)


def test_input_hand_points_use_the_open_pose():
    hand = load_hand(available_hands()[0])
    wrist = np.array([[0.1, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]])
    pts = input_hand_points(hand, wrist)
    ref = hand.surface_points(wrist, hand.open_pose).numpy()
    assert np.allclose(pts, ref, atol=1e-6)


def test_point_weights_of_the_wrong_shape_are_refused():
    from models.errors import PlanningError

    hand = load_hand(available_hands()[0])
    box = trimesh.creation.box(extents=[0.02, 0.02, 0.02])
    program = grasp_program(hand, [box.vertices + [0.0, 0.0, -1.0]])
    wrist = np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0])
    targets = GraspTargets(
        wrist,
        hand.open_pose,
        point_index=np.arange(3),
        point_targets=np.zeros((3, 3)),
        point_weights=np.ones(2),
    )
    with pytest.raises(PlanningError, match="point_weights"):
        program.solve(targets)


def test_shipped_weights_load_when_present():
    from learned.dro import WEIGHTS

    if not WEIGHTS.is_file():
        pytest.skip("no shipped D(R,O) weights")
    ckpt = load_weights()
    assert ckpt.meta["steps"] > 0 and set(ckpt.meta["hands"]) == set(available_hands())


def test_cli_train_dro_options_reach_the_config():
    from planner.cli import build_parser

    argv = ["train", "dro", "--data", "D", "--out", "O", "--epochs", "2", "--hands", "leap"]
    args = build_parser(argv).parse_args(argv)
    cfg = train_dro.config_from_args(args)
    assert (cfg.data, cfg.out, cfg.epochs, cfg.hands) == ("D", "O", 2, ("leap",))
    assert cfg.batch == train_dro.TrainConfig("", "").batch  # left out: the config's default


def test_every_training_option_is_on_the_command_line():
    """`drograsp train dro` is the one way to train D(R,O): each option in train_dro.OPTIONS
    reaches the config with a value that differs from its default."""
    from planner.cli import build_parser

    base = train_dro.TrainConfig("", "")
    argv = ["train", "dro", "--data", "D", "--out", "O"]
    for name in train_dro.OPTIONS:
        default = getattr(base, name)
        value = 7 if default is None else default * 2 + 1
        argv += ["--" + name.replace("_", "-"), str(value)]
    cfg = train_dro.config_from_args(build_parser(argv).parse_args(argv))
    for name in train_dro.OPTIONS:
        assert getattr(cfg, name) != getattr(base, name), name


def test_cli_train_dro_steps_and_the_ablation_without_anchors():
    from planner.cli import build_parser

    argv = ["train", "dro", "--data", "D", "--out", "O", "--steps", "5", "--no-anchors"]
    cfg = train_dro.config_from_args(build_parser(argv).parse_args(argv))
    assert cfg.steps == 5 and cfg.net.anchors is False
    assert train_dro.TrainConfig("", "").net.anchors is True


@needs_data
def test_training_without_anchors_stops_at_its_steps(tmp_path, monkeypatch):
    """The ablation's object inputs carry no contact map, its weights say so, and --steps
    stops the run early without changing the schedule (a resumed run keeps its settings)."""
    monkeypatch.setattr(train_dro, "embed", _fake_embed)
    net = replace(TINY, anchors=False)
    cfg = train_dro.TrainConfig(
        str(DATA), str(tmp_path), epochs=1, batch=2, max_rows=6, val_rows=2, steps=1, net=net
    )
    weights = train_dro.train(cfg, progress=False)
    ckpt = load_weights(weights)
    assert ckpt.meta["steps"] == 1 and ckpt.net.cfg.anchors is False
    with np.load(tmp_path / "cache_train.npz") as cache:
        assert np.all(cache["obj"][..., 3] == 0)
    train_dro.train(replace(cfg, steps=2), progress=False)  # resumes: same settings
    assert load_weights(weights).meta["steps"] == 2


def test_eval_dro_solves_with_the_program_settings_it_is_given(monkeypatch):
    """`python -m eval.dro --set program.KEY=VALUE` reaches the grasp program of every solve;
    other settings are refused (nothing else of the planner runs there)."""
    from eval import dro as eval_dro

    seen = []

    class Reached(Exception):
        pass

    def capture(hand, pieces, settings=None):
        seen.append(settings)
        raise Reached

    monkeypatch.setattr(eval_dro, "grasp_program", capture)
    args = ["--split", "test", "--rows-per-hand", "1", "--validate", "1", "--hands", "allegro"]
    with pytest.raises(Reached):
        eval_dro.main([*args, "--set", "program.point_weight=2.5"])
    assert seen[0].point_weight == 2.5
    with pytest.raises(SystemExit):
        eval_dro.main([*args, "--set", "schedule.solve_batch=2"])
    with pytest.raises(DrograspError, match="unknown planner setting"):
        eval_dro.main([*args, "--set", "program.no_such_weight=1"])
