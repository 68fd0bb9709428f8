"""Training of the interaction model: DDPM noise prediction on augmented, paraphrased grasps.

Run by `drograsp train interaction --data DIR --out DIR [--minutes M] [--seed S]`. Objects are
regenerated once from (category, seed) and their point samples cached on disk (the library
takes ~0.5 s per object), so a step only gathers arrays. Each step augments (any yaw, tilt up to
30 degrees, scale +-10%), rewrites the instruction from the training paraphrase bank, drops the
text for classifier-free guidance, and takes an AdamW step; an exponential moving average of the
weights is what ships. Checkpoints (one safetensors file, the state in its header, no pickle) are
written every few minutes and a rerun of the same command resumes from the last one.
"""

from __future__ import annotations

import json
import math
import os
import random
import shutil
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from learned.dataset import DatasetError, GraspArrays, load_split
from learned.interaction import (
    Frame,
    InteractionConfig,
    InteractionModel,
    canonical_frame,
    encode_joints,
    encode_x,
    hand_points,
)
from learned.paraphrase import generic_paraphrases, request_of, train_paraphrases
from learned.pointnet import grouping
from learned.weights import WEIGHTS_DIR, load_weights, save_weights, weights_path
from models.objects import INTENTS, instruction_text

CHECKPOINT = "checkpoint"
MAX_TILT = math.radians(30.0)
SCALE_RANGE = 0.1


@dataclass
class TrainSettings:
    """How long and how: time budget, batch, optimiser, augmentation, checkpoint interval."""

    minutes: float = 15.0
    max_steps: int | None = None
    seed: int = 0
    batch: int = 32  # grasps per step (each with its own object sample)
    repeats: int = 4  # noise draws per grasp (the encoders run once per grasp)
    lr: float = 1e-3
    warmup: int = 200
    weight_decay: float = 1e-4
    ema: float = 0.995
    canonical_share: float = 0.3  # share of steps that keep the dataset's canonical instruction
    # rows drawn with weight count(instruction) ** -balance: 0 uniform over grasps, 1 uniform
    # over instructions (rare ones, e.g. 10 pump grasps beside 157 neck grasps, seen as often).
    # 0.5 measured on grasps_v1 test: part accuracy 74.9 -> 83.6%, instruction sensitivity
    # 31 -> 57% (1434 vs 1302 steps, FiLM on both)
    balance: float = 0.5
    # share of steps whose instruction names no category ("Use the object by its handle"):
    # teaches the part word and the shape over the category's name, for unseen categories
    generic_share: float = 0.2
    # learn also from grasps that hold on the instructed part but miss their intent's
    # definition (intent_ok 0): three times the rows of dataset v2, intent taught less cleanly
    all_rows: bool = False
    # learn each grasp under every intent it meets on its part (the dataset's `intents_met`,
    # `drograsp dataset check-intents`), not only the one it was planned for; a grasp meeting
    # none is learned (under its own instruction) only with `all_rows`
    relabel: bool = False
    # learn only from grasps with at least this many of their 4 anchors on the instructed part
    # (the objects' part labels curate the rows; they are never a model input); 0 keeps all.
    # The dataset's anchors meet 3 of 4 on 92% of its test rows, and a model trained on every
    # row met it on 91.6% of its samples: it learned the rows' misses too (docs/learned_log.md)
    anchors_on_part: int = 3
    # sampling weight (x the balance weight) of the grasps learned under their own instruction
    # although they miss its intent (intent_ok 0; kept only with `all_rows`): below 1 they
    # still teach where the parts are, less often than the grasps that meet the intent teach
    # what the intent asks
    unmet_weight: float = 1.0
    # share of the grasps learned with the object's canonical frame turned half round about z:
    # the frame's sign comes from the cloud's third moment, which a completed single view can
    # flip (a knife read from blade to handle, docs/learned_log.md); with turned frames in
    # training, which end is which has to be read from the shape. 0 keeps the convention.
    turn_share: float = 0.0
    samples_per_object: int = 4  # cached 2048-point samples per object
    # the first blocks of each dataset folder only: the dataset as an earlier run saw it (the
    # shipped direct-diffusion weights were trained on the first 17 of data/grasps_v2)
    blocks: int | None = None
    checkpoint_minutes: float = 3.0
    threads: int = 1
    augment: bool = True
    progress: bool = True

    def __post_init__(self) -> None:
        if self.unmet_weight != 1.0 and not self.all_rows:
            raise DatasetError(
                "--unmet-weight weighs the grasps that miss their intent, which only --all-rows "
                "keeps: add --all-rows or drop --unmet-weight"
            )


@dataclass
class TrainResult:
    steps: int
    minutes: float
    final_loss: float
    val_loss: float | None
    weights: Path
    curve: Path
    resumed_from: int = 0
    history: list[dict[str, float]] = field(default_factory=list)


# ---- object point cache ------------------------------------------------------------------------
class ObjectPoints:
    """Per (category, seed): K cached 2048-point samples (object frame, metres), their labels
    (scoring only, never a model input) and part names; on disk as one npz per object."""

    def __init__(self, folder: str | Path, points: int = 2048, samples: int = 4):
        self.folder = Path(folder)
        self.points, self.samples = points, samples
        self._mem: dict[tuple[str, int], dict[str, Any]] = {}

    def get(self, category: str, seed: int) -> dict[str, Any]:
        key = (category, int(seed))
        if key in self._mem:
            return self._mem[key]
        path = self.folder / f"{category}_{int(seed)}_{self.points}x{self.samples}.npz"
        item = None
        if path.is_file():
            try:
                with np.load(path, allow_pickle=False) as z:
                    item = {k: z[k] for k in z.files}
            except (OSError, ValueError, EOFError):
                item = None
        if item is None:
            from models.objects import make_object

            obj = make_object(category, int(seed))
            dense, labels = obj.points, obj.point_labels
            idx = np.stack(
                [
                    np.random.default_rng(s).choice(len(dense), self.points, replace=False)
                    for s in range(self.samples)
                ]
            )
            item = {
                "points": dense[idx].astype(np.float32),
                "labels": labels[idx].astype(np.int16),
                "part_names": np.array(obj.part_names),
            }
            self.folder.mkdir(parents=True, exist_ok=True)
            # a name of this process's own: two runs sharing the cache may write the same item
            tmp = path.with_suffix(f".{os.getpid()}.tmp.npz")
            np.savez(tmp, **item)
            os.replace(tmp, path)
        item["groups"] = None
        self._mem[key] = item
        return item

    def groups(self, category: str, seed: int, config: InteractionConfig) -> list:
        item = self.get(category, seed)
        if item["groups"] is None:
            item["groups"] = [grouping(p, config.levels("object")) for p in item["points"]]
        return item["groups"]


# ---- rows --------------------------------------------------------------------------------------
def usable_rows(data: GraspArrays, all_rows: bool = False) -> np.ndarray:
    """Rows to learn from: all but those known to miss their intent (intent_ok 0; 1 is a
    pass, -1 or an absent column means not checked); every row with `all_rows`."""
    ok = data.arrays.get("intent_ok")
    if ok is None or all_rows:
        return np.arange(len(data))
    return np.flatnonzero(np.asarray(ok) != 0)


def training_pairs(
    data: GraspArrays, all_rows: bool = False, relabel: bool = False
) -> tuple[np.ndarray, list[str]]:
    """The (row, instruction) pairs to learn from: each usable row under its own instruction
    (`usable_rows`), or with `relabel` under every instruction of the table whose intent it
    meets on its part. Rows never checked against the other intents (intents_met all -1)
    keep their own instruction."""
    meta, a = data.meta, data.arrays
    own = [meta["instructions"][i] for i in a["instruction"]]
    if not relabel:
        rows = usable_rows(data, all_rows)
        return rows, [own[r] for r in rows]
    met = a["intents_met"]
    if not (met >= 0).any() and len(data):
        raise DatasetError(
            "--relabel needs every grasp checked against every intent of its part: run "
            "`drograsp dataset check-intents DIR` on the dataset first"
        )
    usable = set(usable_rows(data, all_rows).tolist())
    rows, texts = [], []
    for r in range(len(data)):
        if (met[r] < 0).all():  # not checked: as without relabel
            if r in usable:
                rows.append(r)
                texts.append(own[r])
            continue
        cat, part = meta["categories"][a["category"][r]], meta["parts"][a["part"][r]]
        meets = [instruction_text(i, cat, part) for k, i in enumerate(INTENTS) if met[r, k] == 1]
        if not meets and all_rows:
            meets = [own[r]]
        rows += [r] * len(meets)
        texts += meets
    return np.asarray(rows, dtype=np.int64), texts


def unmet_intent(data: GraspArrays, rows: np.ndarray, texts: list[str]) -> np.ndarray:
    """Per (row, text) pair: the grasp is learned under its own instruction and misses that
    instruction's intent (intent_ok 0); False where the intent was never checked."""
    ok = data.arrays.get("intent_ok")
    if ok is None:
        return np.zeros(len(rows), dtype=bool)
    own = data.meta["instructions"]
    same = np.array(
        [own[i] == t for i, t in zip(data.arrays["instruction"][rows], texts, strict=True)],
        dtype=bool,
    )
    return same & (np.asarray(ok)[rows] == 0)


def anchors_on_part(data: GraspArrays, rows: np.ndarray, cache: ObjectPoints) -> np.ndarray:
    """Per row: how many of its 4 anchors lie on its instructed part (the part label of the
    nearest of the object's cached points); 4 where the part is not one of the object's."""
    meta, a = data.meta, data.arrays
    counts = np.full(len(rows), 4, dtype=np.int64)
    by_object: dict[tuple[str, int], list[int]] = {}
    for k, r in enumerate(rows):
        by_object.setdefault((meta["categories"][a["category"][r]], int(a["seed"][r])), []).append(
            k
        )
    for (cat, seed), ks in by_object.items():
        item = cache.get(cat, seed)
        names = [str(n) for n in item["part_names"]]
        tree = cKDTree(item["points"].reshape(-1, 3))
        labels = item["labels"].reshape(-1)
        for k in ks:
            r = rows[k]
            part = meta["parts"][a["part"][r]]
            if part in names:
                near = labels[tree.query(a["anchors"][r].reshape(-1, 3))[1]]
                counts[k] = int((near == names.index(part)).sum())
    return counts


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """Any yaw, then a tilt about a random horizontal axis of up to 30 degrees."""
    yaw = Rotation.from_euler("z", rng.uniform(0, 2 * math.pi))
    axis_angle = rng.uniform(0, 2 * math.pi)
    axis = np.array([math.cos(axis_angle), math.sin(axis_angle), 0.0])
    tilt = Rotation.from_rotvec(axis * rng.uniform(0, MAX_TILT))
    return (tilt * yaw).as_matrix()


def augment(
    points: np.ndarray, wrist: np.ndarray, anchors: np.ndarray, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The same random rotation and scale applied to cloud, wrist and anchors."""
    rot = random_rotation(rng)
    s = rng.uniform(1 - SCALE_RANGE, 1 + SCALE_RANGE)
    w = wrist.astype(np.float64).copy()
    w[:3] = s * rot @ w[:3]
    rm = rot @ Rotation.from_quat(w[3:], scalar_first=True).as_matrix()
    w[3:] = Rotation.from_matrix(rm).as_quat(scalar_first=True)
    return s * points @ rot.T, w, s * anchors @ rot.T


def training_frame(
    pts: np.ndarray, sign: str, turn_share: float, rng: np.random.Generator
) -> Frame:
    """The cloud's canonical frame, turned half round about z (canonical x and y change sign)
    for a `turn_share` of the calls; no random draw at 0, so runs without it are unchanged."""
    frame = canonical_frame(pts, sign)
    if turn_share > 0 and rng.random() < turn_share:
        return Frame(frame.centre, np.diag([-1.0, -1.0, 1.0]) @ frame.rot)
    return frame


class Batcher:
    """Makes training batches: augmented canonical clouds with their groupings, x, texts."""

    def __init__(
        self,
        data: GraspArrays,
        rows: np.ndarray,
        cache: ObjectPoints,
        config: InteractionConfig,
        settings: TrainSettings,
        instructions: list[str] | None = None,
    ):
        """`rows` may repeat a row; `instructions`: the text each is learned under (default
        the row's own, see `training_pairs`)."""
        from learned.text import encode

        self.data, self.rows, self.cache = data, rows, cache
        self.config, self.settings = config, settings
        meta, a = data.meta, data.arrays
        self.categories = [meta["categories"][i] for i in a["category"][rows]]
        self.seeds = a["seed"][rows].astype(int)
        self.hands = [meta["hands"][i] for i in a["hand"][rows]]
        self.hand_names = sorted(set(self.hands))
        self.hand_index = np.array([self.hand_names.index(h) for h in self.hands])
        instr = instructions or [meta["instructions"][i] for i in a["instruction"][rows]]
        self.instr_names = sorted(set(instr))
        self.instr_index = np.array([self.instr_names.index(t) for t in instr])
        counts = np.bincount(self.instr_index, minlength=len(self.instr_names))
        weights = counts[self.instr_index].astype(np.float64) ** -settings.balance
        unmet = unmet_intent(data, rows, instr)
        weights *= np.where(unmet, settings.unmet_weight, 1.0)
        if not weights.sum() > 0:
            raise DatasetError(
                "every training grasp misses its intent and --unmet-weight is 0: raise it"
            )
        self.row_weights = weights / weights.sum()
        # whether each row's grasp meets the intent of the text it is learned under (a model
        # with `intent_flag` is told; unknown counts as met, as the planner counts it)
        self.met = ~unmet
        # paraphrases per instruction: index 0 is the canonical text
        self.texts: list[list[str]] = []
        self.generic: list[list[str]] = []  # the same requests naming no category
        for t in self.instr_names:
            try:
                req = request_of(t)
            except ValueError:  # an instruction the parser cannot read: canonical only
                self.texts.append([t])
                self.generic.append([])
                continue
            self.texts.append([t, *train_paraphrases(req)[1:]])
            self.generic.append(generic_paraphrases(req) if settings.generic_share > 0 else [])
        flat = sorted({t for ts in self.texts + self.generic for t in ts})
        vecs = encode(flat)
        lookup = {t: v for t, v in zip(flat, vecs, strict=True)}
        self.vecs = [np.stack([lookup[t] for t in ts]) for ts in self.texts]
        self.generic_vecs = [
            np.stack([lookup[t] for t in ts]) if ts else None for ts in self.generic
        ]
        for cat, seed in sorted(set(zip(self.categories, self.seeds, strict=True))):
            cache.groups(cat, seed, config)
        self.wrist = a["wrist"][rows].astype(np.float64)
        self.anchors = a["anchors"][rows].astype(np.float64)
        self.joints = None  # the joints target: each row's joints scaled by its hand's limits
        if config.target == "joints":
            from models.hands import load_hand

            self.joints = np.zeros((len(rows), config.joint_slots))
            q = a["q_grasp"][rows].astype(np.float64)
            for k, name in enumerate(self.hand_names):
                hand = load_hand(name)
                mine = self.hand_index == k
                self.joints[mine] = encode_joints(
                    q[mine, : hand.dof], hand.lower, hand.upper, config.joint_slots
                )
        hp = [hand_points(h, config) for h in self.hand_names]
        self.hand_xyz = torch.from_numpy(np.stack([p for p, _ in hp])).float()
        self.hand_groups = {
            k: torch.stack([g.tensors()[k] for _, g in hp])
            for k in ("centres1", "nbrs1", "centres2", "nbrs2")
        }

    def __len__(self) -> int:
        return len(self.rows)

    def x(self, i: int, wrist: np.ndarray, anchors: np.ndarray, frame) -> np.ndarray:
        """Row i's numbers to learn (unnormalised): wrist and anchors, or wrist and joints."""
        x = encode_x(wrist[None], anchors[None], frame)[0]
        if self.joints is None:
            return x
        return np.concatenate([x[:9], self.joints[i]])

    def _text(self, instr: int, pyrng: random.Random) -> np.ndarray:
        """One wording's embedding: generic noun, canonical form or a training paraphrase."""
        generic = self.generic_vecs[instr]
        if generic is not None and pyrng.random() < self.settings.generic_share:
            return generic[pyrng.randrange(len(generic))]
        choices = self.vecs[instr]
        canon = pyrng.random() < self.settings.canonical_share or len(choices) == 1
        return choices[0 if canon else pyrng.randrange(1, len(choices))]

    def make(self, picks: np.ndarray, rng: np.random.Generator, pyrng: random.Random) -> dict:
        xyz, xs, texts = [], [], []
        groups: dict[str, list] = {k: [] for k in ("centres1", "nbrs1", "centres2", "nbrs2")}
        for i in picks:
            cat, seed = self.categories[i], int(self.seeds[i])
            item = self.cache.get(cat, seed)
            k = int(rng.integers(len(item["points"])))
            pts = item["points"][k].astype(np.float64)
            w, anc = self.wrist[i], self.anchors[i]
            if self.settings.augment:
                pts, w, anc = augment(pts, w, anc, rng)
            frame = training_frame(pts, self.config.frame_sign, self.settings.turn_share, rng)
            xyz.append(frame.to_canonical(pts) * 10.0)
            xs.append(self.x(i, w, anc, frame))
            g = self.cache.groups(cat, seed, self.config)[k]
            for key in groups:
                groups[key].append(getattr(g, key))
            texts.append(self._text(self.instr_index[i], pyrng))
        return {
            "xyz": torch.from_numpy(np.stack(xyz)).float(),
            "groups": {k: torch.from_numpy(np.stack(v)) for k, v in groups.items()},
            "x": torch.from_numpy(np.stack(xs)).float(),
            "text": torch.from_numpy(np.stack(texts)).float(),
            "hand": torch.from_numpy(self.hand_index[picks]),
            "met": torch.from_numpy(self.met[picks]),
        }


def batch_loss(
    model: InteractionModel,
    batcher: Batcher,
    batch: dict,
    repeats: int,
    drop: float,
    generator: torch.Generator,
) -> torch.Tensor:
    net = model.net
    b = batch["x"].shape[0]
    dropped = torch.rand(b, generator=generator) < drop
    cond = net.encode(
        batch["xyz"],
        batch["groups"],
        batcher.hand_xyz,
        batcher.hand_groups,
        batch["text"],
        dropped,
        hand_index=batch["hand"],
        met=batch["met"],
    )
    x0 = (batch["x"] - net.x_mean) / net.x_std
    return net.loss(x0.repeat_interleave(repeats, 0), cond.repeat(repeats), generator)


def x_statistics(batcher: Batcher, rng: np.random.Generator, n: int = 4096) -> tuple:
    """Mean and spread of the numbers learned, under augmentation; rotation dims share one scale so
    the 6-D rotation keeps its geometry, anchors share the translation's."""
    picks = rng.integers(0, len(batcher), size=min(n, 4 * len(batcher)))
    xs = []
    for i in picks:
        item = batcher.cache.get(batcher.categories[i], int(batcher.seeds[i]))
        pts, w, a = augment(
            item["points"][0].astype(np.float64), batcher.wrist[i], batcher.anchors[i], rng
        )
        xs.append(
            batcher.x(
                i,
                w,
                a,
                training_frame(pts, batcher.config.frame_sign, batcher.settings.turn_share, rng),
            )
        )
    x = np.stack(xs)
    mean = x.mean(0)
    mean[3:9] = 0.0
    std = np.empty(x.shape[1])
    std[:3] = x[:, :3].std(0).mean()
    std[3:9] = 0.5
    if batcher.joints is None:  # anchors share one scale, as the translation
        std[9:] = x[:, 9:].std(0).mean()
    else:  # joints each their own (padding slots stay at 0 with a unit scale)
        std[9:] = np.where(x[:, 9:].std(0) > 1e-3, x[:, 9:].std(0), 1.0)
    return torch.tensor(mean, dtype=torch.float32), torch.tensor(std, dtype=torch.float32)


# ---- checkpoints -------------------------------------------------------------------------------
def _save_checkpoint(out: Path, model, ema, opt, state: dict) -> None:
    tensors = {f"net.{k}": v for k, v in model.net.state_dict().items()}
    tensors.update({f"ema.{k}": v for k, v in ema.items()})
    opt_state = opt.state_dict()
    for pid, st in opt_state["state"].items():
        for k, v in st.items():
            tensors[f"opt.{pid}.{k}"] = torch.as_tensor(v)
    config = {**state, "format": "drograsp-interaction-checkpoint/1"}
    save_weights(weights_path(CHECKPOINT, out), tensors, config)


def _load_checkpoint(out: Path, model, ema, opt) -> dict | None:
    path = weights_path(CHECKPOINT, out)
    if not path.is_file():
        return None
    tensors, state = load_weights(path, "delete the checkpoint and train again", "checkpoint")
    model.net.load_state_dict({k[4:]: v for k, v in tensors.items() if k.startswith("net.")})
    for k in ema:
        ema[k].copy_(tensors[f"ema.{k}"])
    opt_state = opt.state_dict()
    for pid in range(len(opt_state["param_groups"][0]["params"])):
        st = {k.split(".", 2)[2]: v for k, v in tensors.items() if k.startswith(f"opt.{pid}.")}
        if st:
            opt_state["state"][pid] = st
    opt.load_state_dict(opt_state)
    return state


def write_curve(history: list[dict[str, float]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    steps = [h["step"] for h in history]
    loss = np.array([h["loss"] for h in history])
    if len(loss):
        k = max(1, len(loss) // 50)
        smooth = np.convolve(loss, np.ones(k) / k, mode="valid")
        ax.plot(steps, loss, alpha=0.3, label="train (per step)")
        ax.plot(steps[k - 1 :], smooth, label=f"train ({k}-step mean)")
    val = [(h["step"], h["val"]) for h in history if "val" in h]
    if val:
        ax.plot(*zip(*val, strict=True), "o-", label="val (EMA weights)")
    ax.set_xlabel("step")
    ax.set_ylabel("noise MSE")
    ax.set_yscale("log")
    ax.legend()
    ax.set_title("interaction model training")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


# ---- the loop ----------------------------------------------------------------------------------
def train(
    data: str | Path | Sequence[str | Path],
    out: str | Path,
    settings: TrainSettings | None = None,
    config: InteractionConfig | None = None,
    install: bool = False,
) -> TrainResult:
    """Train (or resume) in `out`; write weights, config, loss curve; optionally install them
    as the package's shipped weights."""
    settings = settings or TrainSettings()
    config = config or InteractionConfig()
    torch.set_num_threads(settings.threads)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    if config.intent_flag and not settings.all_rows:
        raise DatasetError(
            "--intent-flag tells the model which grasps miss their intent, which only "
            "--all-rows keeps: add --all-rows or drop --intent-flag"
        )
    train_data = load_split(data, "train", settings.blocks)
    rows, texts = training_pairs(train_data, settings.all_rows, settings.relabel)
    if len(rows) == 0:
        raise DatasetError(f"{data}: the train split has no usable rows")
    cache = ObjectPoints(out / "object_points", config.points, settings.samples_per_object)
    if settings.anchors_on_part > 0:
        keep = anchors_on_part(train_data, rows, cache) >= settings.anchors_on_part
        rows, texts = rows[keep], [t for t, k in zip(texts, keep, strict=True) if k]
        if len(rows) == 0:
            raise DatasetError(
                f"{data}: no train row has {settings.anchors_on_part} anchors on its instructed "
                "part; lower --anchors-on-part (0 keeps every row)"
            )
    rng = np.random.default_rng(settings.seed)
    pyrng = random.Random(settings.seed)
    gen = torch.Generator().manual_seed(settings.seed)
    model = InteractionModel.new(config, settings.seed)
    batcher = Batcher(train_data, rows, cache, config, settings, texts)
    val_batch = _val_batch(data, cache, config, settings)

    opt = torch.optim.AdamW(
        model.net.parameters(), lr=settings.lr, weight_decay=settings.weight_decay
    )
    ema = {k: v.detach().clone() for k, v in model.net.state_dict().items()}
    state = _load_checkpoint(out, model, ema, opt)
    if state is None:
        mean, std = x_statistics(batcher, rng)
        model.net.x_mean.copy_(mean)
        model.net.x_std.copy_(std)
        ema["x_mean"].copy_(mean)
        ema["x_std"].copy_(std)
        state = {"step": 0, "elapsed": 0.0, "history": [], "seed": settings.seed}
    else:
        rng = np.random.default_rng([settings.seed, state["step"]])
        pyrng = random.Random(settings.seed * 1_000_003 + state["step"])
        gen = torch.Generator().manual_seed(settings.seed * 1_000_003 + state["step"])
    resumed = int(state["step"])
    step, elapsed, history = int(state["step"]), float(state["elapsed"]), list(state["history"])
    budget = settings.minutes * 60.0

    from tqdm import tqdm

    bar = tqdm(
        total=settings.max_steps,
        initial=step,
        disable=not settings.progress,
        desc="train interaction",
        unit="step",
    )
    start = time.monotonic() - elapsed
    last_ckpt = time.monotonic()

    def checkpoint() -> None:
        vl = _val_loss(model, ema, batcher, val_batch, settings)
        if vl is not None and history:
            history[-1]["val"] = vl
        _save_checkpoint(
            out,
            model,
            ema,
            opt,
            {
                "step": step,
                "elapsed": time.monotonic() - start,
                "history": history,
                "seed": settings.seed,
                "settings": asdict(settings),
                "config": config.to_json(),
            },
        )
        write_curve(history, out / "loss.png")

    model.net.train()
    while True:
        if settings.max_steps is not None and step >= settings.max_steps:
            break
        if time.monotonic() - start >= budget:
            break
        lr = settings.lr * min(1.0, (step + 1) / settings.warmup)
        for g in opt.param_groups:
            g["lr"] = lr
        picks = rng.choice(len(batcher), size=settings.batch, p=batcher.row_weights)
        batch = batcher.make(picks, rng, pyrng)
        loss = batch_loss(model, batcher, batch, settings.repeats, config.text_dropout, gen)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.net.parameters(), 1.0)
        opt.step()
        with torch.no_grad():
            for k, v in model.net.state_dict().items():
                if v.dtype.is_floating_point:
                    ema[k].mul_(settings.ema).add_(v.detach(), alpha=1 - settings.ema)
                else:
                    ema[k].copy_(v)
        step += 1
        loss_value = float(loss.detach())
        history.append({"step": step, "loss": loss_value})
        bar.update(1)
        bar.set_postfix(loss=f"{loss_value:.4f}")
        if time.monotonic() - last_ckpt >= settings.checkpoint_minutes * 60.0:
            checkpoint()
            last_ckpt = time.monotonic()
    bar.close()
    checkpoint()

    final = InteractionModel.new(config, settings.seed)
    target = "" if config.target == "anchors" else f" --target {config.target}"
    target += " --all-rows" if settings.all_rows else ""
    target += " --intent-flag" if config.intent_flag else ""
    target += " --relabel" if settings.relabel else ""
    target += f" --frame-sign {config.frame_sign}" if config.frame_sign != "profile" else ""
    target += f" --turn-share {settings.turn_share:g}" if settings.turn_share else ""
    if settings.anchors_on_part != TrainSettings.anchors_on_part:
        target += f" --anchors-on-part {settings.anchors_on_part}"
    if settings.unmet_weight != TrainSettings.unmet_weight:
        target += f" --unmet-weight {settings.unmet_weight:g}"
    if settings.blocks is not None:
        target += f" --blocks {settings.blocks}"
    name = config.name
    steps = "" if settings.max_steps is None else f" --steps {settings.max_steps}"
    final.net.load_state_dict(ema)
    names = " ".join(map(str, data)) if not isinstance(data, str | Path) else str(data)
    final.info = {
        "data": names,
        "data_rows": int(len(rows)),
        "steps": step,
        "minutes": round((time.monotonic() - start) / 60.0, 2),
        "seed": settings.seed,
        "final_loss": float(np.mean([h["loss"] for h in history[-50:]])) if history else None,
        "val_loss": next((h["val"] for h in reversed(history) if "val" in h), None),
        "command": f"drograsp train interaction{target} --data {names} --out {out}{steps} "
        f"--minutes {settings.minutes:g} --seed {settings.seed}",
    }
    final.save(str(out))
    if install:
        WEIGHTS_DIR.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(weights_path(name, out), weights_path(name))
    (out / "history.json").write_text(json.dumps(history[-2000:]), encoding="utf-8")
    return TrainResult(
        steps=step,
        minutes=final.info["minutes"],
        final_loss=final.info["final_loss"] or float("nan"),
        val_loss=final.info["val_loss"],
        weights=weights_path(name, out),
        curve=out / "loss.png",
        resumed_from=resumed,
        history=history,
    )


def _val_batch(data, cache, config, settings) -> Batcher | None:
    try:
        val = load_split(data, "val", settings.blocks)
    except DatasetError:
        return None
    rows = usable_rows(val)
    if len(rows) == 0:
        return None
    rows = rows[np.random.default_rng(0).permutation(len(rows))[:256]]
    quiet = TrainSettings(
        **{
            **asdict(settings),
            "augment": False,
            "canonical_share": 1.0,
            "generic_share": 0.0,
            "turn_share": 0.0,
        }
    )
    return Batcher(val, rows, cache, config, quiet)


def _val_loss(model, ema, batcher, val: Batcher | None, settings) -> float | None:
    """Noise MSE of the EMA weights on fixed val grasps, noise and steps (comparable over time)."""
    if val is None:
        return None
    live = {k: v.clone() for k, v in model.net.state_dict().items()}
    model.net.load_state_dict(ema)
    model.net.eval()
    try:
        with torch.no_grad():
            rng = np.random.default_rng(1)
            batch = val.make(np.arange(len(val)), rng, random.Random(1))
            gen = torch.Generator().manual_seed(1)
            return float(batch_loss(model, val, batch, 2, 0.0, gen))
    finally:
        model.net.load_state_dict(live)
        model.net.train()
