"""The interaction model: frames, over-fitting, checkpoints and weights, paraphrase sets, inputs."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from learned.dataset import load_split
from learned.interaction import (
    Condition,
    InteractionConfig,
    InteractionModel,
    SamplingError,
    canonical_frame,
    decode_x,
    encode_x,
    prepare_cloud,
)
from learned.paraphrase import (
    EVAL_TEMPLATES,
    GENERIC_NOUNS,
    TRAIN_TEMPLATES,
    eval_paraphrases,
    generic_paraphrases,
    request_of,
    train_paraphrases,
)
from learned.text import encode
from learned.weights import WeightsError
from models.errors import InstructionError, ObjectError
from models.hands import available_hands
from models.objects import TABLE, instructions, make_object
from tests.tiny_models import TINY_INTERACTION

DATA = Path(__file__).resolve().parents[1] / "data" / "grasps_v2"
TINY = TINY_INTERACTION


@pytest.fixture(scope="module")
def mug() -> np.ndarray:
    return make_object("mug", 3).points[::4].copy()


@pytest.fixture(scope="module")
def tiny_model() -> InteractionModel:
    return InteractionModel.new(TINY, seed=0)


# ---- paraphrases -------------------------------------------------------------------------------
def test_paraphrase_sets_disjoint() -> None:
    assert not set(TRAIN_TEMPLATES) & set(EVAL_TEMPLATES)
    for category in TABLE:
        for instr in instructions(category):
            req = request_of(instr.text)
            train = {t.lower() for t in train_paraphrases(req)}
            held = [t.lower() for t in eval_paraphrases(req)]
            assert len(set(held)) == len(held)
            assert not train & set(held), instr.text
            assert instr.text.lower() in train  # the canonical form is trained on


# ---- frames ------------------------------------------------------------------------------------
def test_weights_from_before_the_profile_sign_keep_the_moment() -> None:
    assert InteractionConfig.from_json({}).frame_sign == "moment"
    assert InteractionConfig().frame_sign == "profile"
    with pytest.raises(ValueError, match="frame_sign"):
        InteractionConfig(frame_sign="skew")


@pytest.mark.parametrize("category", ["knife", "spray_bottle", "mug", "pan"])
def test_frame_reads_a_completed_view_end_to_end_as_the_whole_object(category: str) -> None:
    """The model learned grasps in frames of whole objects; a completed single view (dense
    where the camera saw) must point the same end to +x, or a knife is read blade for handle.
    The points' third moment fails this for two of three test knives and spray bottles."""
    from models.objects.completion import complete_view
    from models.objects.splits import seeds
    from models.objects.views import sampled_cloud_object, single_view_object

    for seed in seeds(category, "test", 3):
        obj = make_object(category, seed)
        whole = canonical_frame(sampled_cloud_object(obj, 2048, seed=seed).points)
        view = canonical_frame(complete_view(single_view_object(obj, seed=seed)).points)
        assert whole.rot[0, :2] @ view.rot[0, :2] > 0.9, (category, seed)


def test_encode_decode_round_trip(mug: np.ndarray) -> None:
    frame = canonical_frame(mug)
    rng = np.random.default_rng(0)
    q = Rotation.random(5, random_state=1).as_quat(scalar_first=True)
    q *= np.sign(q[:, :1])
    wrists = np.concatenate([rng.normal(0, 0.1, (5, 3)), q], axis=1)
    anchors = rng.normal(0, 0.05, (5, 4, 3))
    w, a = decode_x(encode_x(wrists, anchors, frame), frame)
    np.testing.assert_allclose(w, wrists, atol=1e-9)
    np.testing.assert_allclose(a, anchors, atol=1e-12)


@pytest.mark.parametrize("hand", ["allegro", "leap", "shadow"])
def test_rotating_the_input_rotates_the_output(
    hand: str, mug: np.ndarray, tiny_model: InteractionModel
) -> None:
    """Turned about the vertical and moved, the cloud gives the same grasps turned and moved:
    the canonical frame takes the pose out before the network sees the cloud."""
    rot = Rotation.from_euler("z", 2.3)
    shift = np.array([0.4, -0.2, 0.1])
    w0, a0 = tiny_model.sample(mug, "Use a mug by handle", hand, 4, seed=5)
    w1, a1 = tiny_model.sample(rot.apply(mug) + shift, "Use a mug by handle", hand, 4, seed=5)
    np.testing.assert_allclose(w1[:, :3], rot.apply(w0[:, :3]) + shift, atol=1e-6)
    turned = rot * Rotation.from_quat(w0[:, 3:], scalar_first=True)
    diff = turned.inv() * Rotation.from_quat(w1[:, 3:], scalar_first=True)
    assert diff.magnitude().max() < 1e-5
    np.testing.assert_allclose(
        a1, rot.apply(a0.reshape(-1, 3)).reshape(a0.shape) + shift, atol=1e-6
    )
    # anchors are cloud points
    assert np.isclose(np.linalg.norm(mug[None] - a0.reshape(-1, 1, 3), axis=2).min(1), 0).all()


def test_sample_shapes_and_unit_quaternions(mug: np.ndarray, tiny_model: InteractionModel) -> None:
    w, a = tiny_model.sample(mug, "grab the mug by its handle", "allegro", 3)
    assert w.shape == (3, 7) and a.shape == (3, 4, 3)
    np.testing.assert_allclose(np.linalg.norm(w[:, 3:], axis=1), 1.0, atol=1e-9)
    assert (w[:, 3] >= 0).all()


# ---- over-fitting ------------------------------------------------------------------------------
@pytest.mark.skipif(not DATA.is_dir(), reason="data/grasps_v2 absent")
def test_tiny_overfit() -> None:
    """Four grasps of one mug learned to a small noise error in seconds; samples then land
    near the taught grasps."""
    torch.set_num_threads(1)
    data = load_split(DATA, "train")
    a, meta = data.arrays, data.meta
    rows = list(range(4))
    assert len({(a["category"][r], a["seed"][r]) for r in rows}) == 1
    obj = make_object(meta["categories"][a["category"][0]], int(a["seed"][0]))
    model = InteractionModel.new(TINY, seed=0)
    prep = prepare_cloud(obj.points, TINY)
    texts = [meta["instructions"][a["instruction"][r]] for r in rows]
    hands = [meta["hands"][a["hand"][r]] for r in rows]
    vecs = encode(texts)
    x = torch.tensor(
        np.stack(
            [encode_x(a["wrist"][r][None], a["anchors"][r][None], prep.frame)[0] for r in rows]
        )
    ).float()
    model.net.x_mean.copy_(x.mean(0))
    model.net.x_std.copy_(x.std(0).clamp(min=0.05))
    x0 = (x - model.net.x_mean) / model.net.x_std
    opt = torch.optim.AdamW(model.net.parameters(), 3e-3)
    gen = torch.Generator().manual_seed(0)
    losses = []
    for _ in range(300):
        conds = [model.condition([prep], h, vecs[i : i + 1]) for i, h in enumerate(hands)]
        cond = Condition(torch.cat([c.tokens for c in conds]), torch.cat([c.glob for c in conds]))
        batch = Condition(cond.tokens.repeat(16, 1, 1), cond.glob.repeat(16, 1))
        loss = model.net.loss(x0.repeat(16, 1), batch, gen)
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(float(loss.detach()))
    assert np.mean(losses[-20:]) < 0.25 * np.mean(losses[:5])
    w, _ = model.sample(obj.points, texts[0], hands[0], 8, guidance=1.0, steps=20)
    taught = np.stack(
        [a["wrist"][r][:3] for r in rows if texts[r] == texts[0] and hands[r] == hands[0]]
    )
    near = np.linalg.norm(w[:, None, :3] - taught[None], axis=2).min(1)
    assert np.median(near) < 0.1 and near.min() < 0.02, near


# ---- weights and checkpoints -------------------------------------------------------------------
def test_weights_round_trip(tmp_path: Path, mug: np.ndarray, tiny_model: InteractionModel) -> None:
    tiny_model.save(str(tmp_path))
    loaded = InteractionModel.load(str(tmp_path))
    assert loaded.config == TINY
    for k, v in tiny_model.net.state_dict().items():
        assert torch.equal(v, loaded.net.state_dict()[k]), k
    w0, a0 = tiny_model.sample(mug, "Hold a mug by body", "leap", 2, seed=3)
    w1, a1 = loaded.sample(mug, "Hold a mug by body", "leap", 2, seed=3)
    np.testing.assert_array_equal(w0, w1)
    np.testing.assert_array_equal(a0, a1)


def test_missing_and_corrupt_weights(tmp_path: Path, tiny_model: InteractionModel) -> None:
    with pytest.raises(WeightsError, match=r"interaction\.safetensors.*drograsp train interaction"):
        InteractionModel.load(str(tmp_path / "nowhere"))
    tiny_model.save(str(tmp_path))
    tensors = tmp_path / "interaction.safetensors"
    tensors.write_bytes(tensors.read_bytes()[:100])
    with pytest.raises(WeightsError, match=r"interaction\.safetensors is damaged.*drograsp train"):
        InteractionModel.load(str(tmp_path))
    # the config lives in the file's header (learned.weights): a damaged or foreign header
    from safetensors.torch import load_file, save_file

    tiny_model.save(str(tmp_path))
    state = load_file(str(tensors))
    save_file(state, str(tensors), metadata={"drograsp": "{not json"})
    with pytest.raises(WeightsError, match=r"interaction\.safetensors is damaged"):
        InteractionModel.load(str(tmp_path))
    save_file(state, str(tensors))
    with pytest.raises(WeightsError, match=r"interaction\.safetensors is damaged.*no 'drograsp'"):
        InteractionModel.load(str(tmp_path))
    save_file(state, str(tensors), metadata={"drograsp": json.dumps({"format": "other/1"})})
    with pytest.raises(WeightsError, match="does not hold an interaction model"):
        InteractionModel.load(str(tmp_path))
    other = InteractionModel.new(InteractionConfig(width=64, heads=2, layers=1), seed=0)
    cfg = {"format": "drograsp-interaction/1", "config": other.config.to_json(), "info": {}}
    save_file(state, str(tensors), metadata={"drograsp": json.dumps(cfg)})
    with pytest.raises(WeightsError, match="does not fit the model"):
        InteractionModel.load(str(tmp_path))


def _mini_dataset(root: Path) -> None:
    """Four train grasps of one object and two val grasps, in the dataset's layout."""
    meta = json.loads((DATA / "meta.json").read_text())
    train, val = load_split(DATA, "train"), load_split(DATA, "val")
    block = {k: np.concatenate([train.arrays[k][:4], val.arrays[k][:2]]) for k in train.arrays}
    (root / "blocks").mkdir(parents=True)
    np.savez(root / "blocks" / "b0.npz", **block)
    meta["blocks"] = {"b0": {"grasps": 6}}
    (root / "meta.json").write_text(json.dumps(meta), encoding="utf-8")


@pytest.mark.skipif(not DATA.is_dir(), reason="data/grasps_v2 absent")
def test_training_checkpoint_resume(tmp_path: Path) -> None:
    from learned.train_interaction import TrainSettings, train

    data, out = tmp_path / "data", tmp_path / "run"
    _mini_dataset(data)
    settings = TrainSettings(
        minutes=5, max_steps=2, batch=4, repeats=2, samples_per_object=1, progress=False
    )
    first = train(data, out, settings, TINY)
    assert first.steps == 2 and first.resumed_from == 0
    assert (out / "checkpoint.safetensors").is_file() and (out / "loss.png").is_file()
    settings.max_steps = 4
    second = train(data, out, settings, TINY)
    assert second.resumed_from == 2 and second.steps == 4
    model = InteractionModel.load(str(out))
    assert model.info["steps"] == 4
    w, a = model.sample(make_object("mug", 3).points, "Use a mug by handle", "shadow", 2)
    assert np.isfinite(w).all() and np.isfinite(a).all()
    shutil.rmtree(out / "object_points")


@pytest.mark.skipif(not DATA.is_dir(), reason="data/grasps_v2 absent")
@pytest.mark.parametrize("share", [0.0, 1.0])
def test_turn_share_learns_objects_with_their_frame_turned_half_round(
    tmp_path: Path, share: float
) -> None:
    import random

    from learned.train_interaction import Batcher, ObjectPoints, TrainSettings, training_pairs

    data = load_split(DATA, "train")
    rows, texts = training_pairs(data, False, False)
    rows, texts = rows[:6], texts[:6]
    settings = TrainSettings(turn_share=share, samples_per_object=1, progress=False)
    batcher = Batcher(
        data, rows, ObjectPoints(tmp_path, TINY.points, 1), TINY, settings, list(texts)
    )
    batch = batcher.make(np.arange(6), np.random.default_rng(0), random.Random(0))
    # the canonical frame puts the heavier tail (the larger third moment) toward +x; turned
    # half round, toward -x
    third = (batch["xyz"][:, :, 0].double() ** 3).sum(1)
    assert ((third < 0) if share else (third > 0)).all(), third


# ---- bad input ---------------------------------------------------------------------------------
def test_bad_inputs(mug: np.ndarray, tiny_model: InteractionModel) -> None:
    with pytest.raises(ObjectError, match="empty"):
        tiny_model.sample(np.zeros((0, 3)), "Use a mug by handle", "shadow", 2)
    bad = mug.copy()
    bad[5, 1] = np.nan
    with pytest.raises(ObjectError, match="NaN"):
        tiny_model.sample(bad, "Use a mug by handle", "shadow", 2)
    with pytest.raises(ObjectError, match="millimetres"):
        tiny_model.sample(mug * 1000, "Use a mug by handle", "shadow", 2)
    with pytest.raises(InstructionError):
        tiny_model.sample(mug, "   ", "shadow", 2)
    with pytest.raises(ValueError, match="positive integer"):
        tiny_model.sample(mug, "Use a mug by handle", "shadow", 0)


def test_generic_wordings_name_no_category_and_stay_apart_from_evaluation() -> None:
    nouns = {request_of(i.text).noun for c in TABLE for i in instructions(c)}
    for category in TABLE:
        for instr in instructions(category)[:2]:
            req = request_of(instr.text)
            generic = generic_paraphrases(req)
            assert generic and len(set(generic)) == len(generic)
            assert not any(n in t.split() for t in generic for n in nouns - {req.part})
            assert all(req.part in t for t in generic)
            assert all(any(g in t for g in GENERIC_NOUNS) for t in generic)
            assert not {t.lower() for t in generic} & {t.lower() for t in eval_paraphrases(req)}


def test_cli_generic_share_reaches_the_settings_and_is_checked(capsys) -> None:
    from planner.cli import build_parser
    from planner.commands.train import interaction_setup

    argv = ["train", "interaction", "--data", "D", "--out", "O", "--generic-share", "0.5"]
    _, settings = interaction_setup(build_parser(argv).parse_args(argv))
    assert settings.generic_share == 0.5 and settings.turn_share == 0.0
    turned = argv + ["--turn-share", "0.5"]
    assert interaction_setup(build_parser(turned).parse_args(turned))[1].turn_share == 0.5
    bad = argv[:-1] + ["1.5"]
    with pytest.raises(SystemExit) as exc:
        build_parser(bad).parse_args(bad)
    assert exc.value.code == 2 and "between 0 and 1" in capsys.readouterr().err


# ---- the joints target (direct-diffusion ablation) ------------------------------------------
@pytest.mark.parametrize("hand", available_hands())
def test_joint_encoding_round_trips_within_limits_and_couplings(hand: str) -> None:
    from learned.interaction import decode_joints, encode_joints
    from models.hands import load_hand

    model = load_hand(hand)
    rng = np.random.default_rng(0)
    basis = model.coupling_basis
    q = np.clip(rng.uniform(-1, 1, (6, basis.shape[1])) @ basis.T, model.lower, model.upper)
    z = encode_joints(q, model.lower, model.upper, 24)
    assert z.shape == (6, 24) and np.abs(z).max() <= 1 + 1e-9 and not z[:, model.dof :].any()
    back = decode_joints(z, model)
    np.testing.assert_allclose(back, q, atol=1e-9)
    wild = decode_joints(rng.uniform(-3, 3, (6, 24)), model)  # off limits and couplings
    assert (wild >= model.lower - 1e-12).all() and (wild <= model.upper + 1e-12).all()
    np.testing.assert_allclose(wild @ model.coupling_equalities.T, 0, atol=1e-9)


@pytest.mark.skipif(not DATA.is_dir(), reason="data/grasps_v2 absent")
def test_joints_target_trains_saves_as_direct_and_samples_configurations(tmp_path: Path) -> None:
    from learned.train_interaction import TrainSettings, train
    from models.hands import load_hand

    data, out = tmp_path / "data", tmp_path / "run"
    _mini_dataset(data)
    settings = TrainSettings(
        minutes=5, max_steps=2, batch=4, repeats=2, samples_per_object=1, progress=False
    )
    result = train(data, out, settings, replace(TINY, target="joints"))
    assert result.weights.name == "direct.safetensors" and result.weights.is_file()
    model = InteractionModel.load(str(out), "direct")
    assert model.config.target == "joints" and "--target joints" in model.info["command"]
    assert "--steps 2 " in model.info["command"]
    shadow = load_hand("shadow")
    cloud = make_object("mug", 3).points
    wrists, q = model.sample_configurations(cloud, "Use a mug by handle", shadow, 3)
    assert wrists.shape == (3, 7) and q.shape == (3, shadow.dof)
    assert (q >= shadow.lower - 1e-12).all() and (q <= shadow.upper + 1e-12).all()
    np.testing.assert_allclose(q @ shadow.coupling_equalities.T, 0, atol=1e-9)
    with pytest.raises(SamplingError, match="draws joints"):
        model.sample(cloud, "Use a mug by handle", shadow, 2)
    with pytest.raises(ValueError, match="unknown target"):
        InteractionConfig(target="fingers")


def test_rows_known_to_miss_their_intent_are_left_out_unless_all_rows() -> None:
    from learned.dataset import GraspArrays
    from learned.train_interaction import usable_rows

    ok = np.array([1, 0, -1, 0, 1])
    data = GraspArrays("train", {"intent_ok": ok, "hand": np.zeros(5, dtype=int)}, {})
    assert usable_rows(data).tolist() == [0, 2, 4]
    assert usable_rows(data, all_rows=True).tolist() == [0, 1, 2, 3, 4]


def test_relabel_learns_each_grasp_under_every_intent_it_meets() -> None:
    from learned.dataset import DatasetError, GraspArrays
    from learned.train_interaction import training_pairs

    meta = {
        "instructions": ["Hold a mug by body", "Liftup a mug by body", "Use a mug by handle"],
        "categories": ["mug"],
        "parts": ["body", "handle"],
    }
    # columns Use, Hold, Handover, Liftup; -1: not asked of the part (or not checked)
    met = np.array(
        [
            [-1, 1, 1, 1],  # a Hold grasp meeting Hold, Handover and Liftup
            [-1, 0, 0, 1],  # a Hold grasp meeting only Liftup
            [-1, 0, 0, 0],  # a Liftup grasp meeting none
            [-1, -1, -1, -1],  # never checked: its own instruction, as without relabel
            [1, -1, -1, 0],  # a Use grasp on the handle meeting Use
        ]
    )
    arrays = {
        "instruction": np.array([0, 0, 1, 1, 2]),
        "category": np.zeros(5, dtype=int),
        "part": np.array([0, 0, 0, 0, 1]),
        "intent_ok": np.array([1, 0, 0, 1, 1]),
        "intents_met": met,
        "hand": np.zeros(5, dtype=int),
    }
    data = GraspArrays("train", arrays, meta)
    rows, texts = training_pairs(data, relabel=True)
    assert list(zip(rows.tolist(), texts, strict=True)) == [
        (0, "Hold a mug by body"),
        (0, "Handover a mug by body"),
        (0, "Liftup a mug by body"),
        (1, "Liftup a mug by body"),
        (3, "Liftup a mug by body"),
        (4, "Use a mug by handle"),
    ]
    rows, texts = training_pairs(data, all_rows=True, relabel=True)
    assert (2, "Liftup a mug by body") in zip(rows.tolist(), texts, strict=True)
    rows, texts = training_pairs(data)  # without relabel: own instructions, usable rows
    assert rows.tolist() == [0, 3, 4] and texts[0] == "Hold a mug by body"
    unchecked = GraspArrays("train", arrays | {"intents_met": np.full((5, 4), -1)}, meta)
    with pytest.raises(DatasetError, match="check-intents"):
        training_pairs(unchecked, relabel=True)
    # --unmet-weight applies to the pairs that teach a grasp under an intent it misses: row 1
    # (a Hold grasp missing Hold) only under its own instruction, row 2 (meeting none)
    from learned.train_interaction import unmet_intent

    rows, texts = training_pairs(data, all_rows=True)
    assert unmet_intent(data, rows, texts).tolist() == [False, True, True, False, False]
    rows, texts = training_pairs(data, all_rows=True, relabel=True)
    pairs = list(zip(rows.tolist(), texts, strict=True))
    unmet = unmet_intent(data, rows, texts)
    assert {p for p, u in zip(pairs, unmet, strict=True) if u} == {(2, "Liftup a mug by body")}
    no_column = GraspArrays("train", {k: v for k, v in arrays.items() if k != "intent_ok"}, meta)
    assert not unmet_intent(no_column, rows, texts).any()
    from learned.train_interaction import TrainSettings

    with pytest.raises(DatasetError, match="--all-rows"):
        TrainSettings(unmet_weight=0.3)  # without --all-rows there is nothing to weigh


def test_rows_are_counted_by_their_anchors_on_the_instructed_part(tmp_path: Path) -> None:
    from learned.dataset import GraspArrays
    from learned.train_interaction import ObjectPoints, anchors_on_part

    mug = make_object("mug", 3)
    handle = mug.points[mug.point_labels == mug.part_names.index("handle")]
    body = mug.points[mug.point_labels == mug.part_names.index("body")]
    anchors = np.stack(
        [
            handle[:4],  # all four on the handle
            np.concatenate([handle[:3], body[:1]]),  # three
            np.concatenate([handle[:2], body[:2]]),  # two
            body[:4],  # none on the handle, all on the body
        ]
    )
    meta = {"categories": ["mug"], "parts": ["body", "handle", "spout"]}
    arrays = {
        "category": np.zeros(5, dtype=int),
        "seed": np.full(5, 3),
        "part": np.array([1, 1, 1, 1, 2]),  # the last names a part the mug does not have
        "anchors": np.concatenate([anchors, body[None, :4]]).astype(np.float32),
        "hand": np.zeros(5, dtype=int),
    }
    data = GraspArrays("train", arrays, meta)
    cache = ObjectPoints(tmp_path, 2048, 2)
    counts = anchors_on_part(data, np.arange(5), cache)
    assert counts.tolist() == [4, 3, 2, 0, 4]
    assert anchors_on_part(data, np.array([3, 0]), cache).tolist() == [0, 4]


def test_interaction_benchmark_scores_the_splits_own_anchors_as_it_scores_samples(
    tmp_path: Path,
) -> None:
    from eval.interaction import data_part_accuracy
    from learned.dataset import GraspArrays
    from learned.train_interaction import ObjectPoints

    mug = make_object("mug", 3)
    handle = mug.points[mug.point_labels == mug.part_names.index("handle")]
    body = mug.points[mug.point_labels == mug.part_names.index("body")]
    anchors = np.stack([handle[:4], np.concatenate([handle[:2], body[:2]]), body[:4]])
    meta = {"categories": ["mug"], "parts": ["body", "handle"], "hands": ["allegro", "leap"]}
    arrays = {
        "category": np.zeros(3, dtype=int),
        "seed": np.full(3, 3),
        "part": np.array([1, 1, 0]),  # handle, handle (two anchors on it), body
        "anchors": anchors,
        "hand": np.array([0, 0, 1]),
    }
    data = GraspArrays("test", arrays, meta)
    cache = ObjectPoints(tmp_path, 2048, 1)
    shares = data_part_accuracy(data, [("mug", 3)], ["allegro", "leap"], cache)
    assert shares == {"allegro": 0.5, "leap": 1.0, "all": pytest.approx(2 / 3)}
    assert data_part_accuracy(data, [("mug", 4)], ["allegro"], cache) == {}


def test_intent_flag_conditions_the_model_is_dropped_with_the_text_and_round_trips(
    tmp_path: Path, mug: np.ndarray
) -> None:
    flagged = InteractionModel.new(replace(TINY, intent_flag=True), seed=0)
    prep = prepare_cloud(mug, flagged.config)
    vec = encode(["Hold a mug by body"])

    def glob(met: bool, drop: bool = False) -> torch.Tensor:
        return flagged.condition([prep], "leap", vec, drop=drop, met=met).glob

    # the flag changes the condition; sampling asks for "meets" (the default)
    assert not torch.allclose(glob(True), glob(False))
    assert torch.equal(flagged.condition([prep], "leap", vec).glob, glob(True))
    # with the text dropped (classifier-free guidance's other half) the flag is dropped too
    assert torch.equal(glob(True, drop=True), glob(False, drop=True))
    flagged.save(str(tmp_path))
    loaded = InteractionModel.load(str(tmp_path))
    assert loaded.config.intent_flag and torch.equal(loaded.net.met, flagged.net.met)
    # a config written before the option loads without it, and has no flag parameters
    old = {k: v for k, v in TINY.to_json().items() if k != "intent_flag"}
    assert InteractionConfig.from_json(old).intent_flag is False
    assert InteractionModel.new(TINY).net.met is None


@pytest.mark.skipif(not DATA.is_dir(), reason="data/grasps_v2 absent")
def test_intent_flag_needs_all_rows_and_learns_from_each_rows_flag(tmp_path: Path) -> None:
    from learned.dataset import DatasetError
    from learned.train_interaction import CHECKPOINT, TrainSettings, train
    from learned.weights import load_weights, weights_path

    data, out = tmp_path / "data", tmp_path / "run"
    _mini_dataset(data)
    config = replace(TINY, intent_flag=True)
    settings = TrainSettings(
        minutes=5, max_steps=3, batch=16, repeats=1, samples_per_object=1, progress=False
    )
    with pytest.raises(DatasetError, match="--intent-flag .* --all-rows"):
        train(data, out, settings, config)
    settings.all_rows = True
    result = train(data, out, settings, config)
    model = InteractionModel.load(str(out))
    assert model.config.intent_flag and "--intent-flag" in model.info["command"]
    assert result.steps == 3
    # both flags occur in the mini dataset's train rows, and both embeddings learn (the live
    # weights of the checkpoint: the shipped EMA weights move too little in 3 steps to see)
    assert set(load_split(data, "train").arrays["intent_ok"].tolist()) >= {0, 1}
    start = InteractionModel.new(config, settings.seed).net.met.detach()
    live = load_weights(weights_path(CHECKPOINT, out), "")[0]["net.met"]
    assert not torch.allclose(live[0], start[0]) and not torch.allclose(live[1], start[1])
