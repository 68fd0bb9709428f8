"""Training of the D(R,O) network on the functional grasp dataset.

    drograsp train dro --data data/grasps_v2 --out runs/dro [--minutes 15]

Each dataset row gives one sample: the object (regenerated once per (category, seed) and
subsampled to `dense_points`), its 512 x 4 input from the row's anchors (learned.contact_map,
sampled once per row with a seed from the row), the hand's surface points at the row's wrist
with the fingers near the open pose (fresh joint and wrist noise every step: the first stage's
wrist is not exact), the instruction's embedding, and as the answer the hand's surface points
at the dataset grasp. Losses per step:

- L1 on D for `hand_points` random hand points x all 512 object points, both sides clipped at
  `clip` (5 cm): how far a point is beyond that does not matter to the grasp (the mean error
  over the near pairs plus the mean shortfall of the far pairs below the clip);
- pose: those hand points multilaterated from their predicted row, every hand point placed by
  per-body Kabsch (weighted by predicted closeness), mean distance to the truth over the hand
  points truly within `clip` of the object;
- penetration: how deep those placed points are behind the nearest object input point's
  normal (within 1 cm of it).

Seeded (torch and per-step numpy generators), resumable (`checkpoint.pt` in the output folder;
re-run the same command), a tqdm bar with the loss, `loss.png`, and the weights as
`dro.safetensors`. The prepared per-row arrays are cached in the output folder.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import shutil
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
import torch

from learned.contact_map import object_input
from learned.dataset import DatasetError, load_split
from learned.dro import (
    NO_ANCHOR_WEIGHTS,
    WEIGHTS,
    DROConfig,
    DRONet,
    input_hand_points,
    load_weights,
    place_hand,
    save_weights,
)
from models.errors import DrograspError


class TrainingError(DrograspError, RuntimeError):
    """Training cannot start or resume (no rows, a checkpoint of another run)."""


@dataclass
class TrainConfig:
    """One training run; every field is a command-line option."""

    data: str | list[str]  # a dataset folder, or several read as one
    out: str
    epochs: int = 20
    steps: int | None = None  # stop (and save) after this many steps; the schedule spans `epochs`
    minutes: float | None = None  # stop (and save) after this much training time
    batch: int = 8
    lr: float = 1e-3
    hand_points: int = 128  # hand points per step whose rows of D enter the losses
    clip: float = 0.05  # m: distances beyond are equal to the loss
    pose_weight: float = 0.1  # the pose loss's gradient through multilateration is noisy
    penetration_weight: float = 1.0
    neighbours: int = 128  # object points per multilateration
    joint_noise: float = 0.05  # rad, std around the open pose
    wrist_rotation_noise: float = 0.1  # rad, largest angle
    wrist_translation_noise: float = 0.005  # m, std per axis
    dense_points: int = 4096
    hands: tuple[str, ...] | None = None  # train on these hands' rows only (leave-one-out)
    max_rows: int | None = None  # the first rows of each split only (quick runs, tests)
    # the first blocks of each dataset folder only: the dataset as an earlier run saw it (the
    # shipped network was trained on the first 17 of data/grasps_v2)
    blocks: int | None = None
    val_rows: int = 128
    checkpoint_every: int = 200
    seed: int = 0
    threads: int = 1
    net: DROConfig = field(default_factory=DROConfig)


# ---- prepared data -------------------------------------------------------------------------
@dataclass
class Prepared:
    """Per-row arrays of one split, ready for batching."""

    hands: list[str]  # per row
    text: np.ndarray  # (rows, 384)
    wrist: np.ndarray  # (rows, 7)
    q_grasp: np.ndarray  # (rows, padded dof)
    obj: np.ndarray  # (rows, 512, 4) xyz + Omega
    normals: np.ndarray  # (rows, 512, 3) outward normals of the object input points
    grasp_points: np.ndarray  # (rows, 512, 3) hand surface points at the dataset grasp
    instructions: list[str]
    categories: list[str]
    seeds: np.ndarray
    anchors: np.ndarray
    row: np.ndarray  # row index in the split

    def __len__(self) -> int:
        return len(self.hands)


_OBJECTS: dict[tuple[str, int, int], tuple[np.ndarray, np.ndarray]] = {}


def dense_object(category: str, seed: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3) surface points and outward normals of a library object, a fixed random subset of
    its dense sample; cached per process (regenerating an object costs up to 0.6 s)."""
    key = (category, seed, n)
    if key not in _OBJECTS:
        from models.objects import make_object

        obj = make_object(category, seed)
        pick = np.random.default_rng(seed).choice(len(obj.points), min(n, len(obj.points)), False)
        _OBJECTS[key] = (
            np.asarray(obj.points[pick], np.float64),
            np.asarray(obj.normals[pick], np.float64),
        )
    return _OBJECTS[key]


def row_object_input(
    category: str, seed: int, anchors: np.ndarray | None, row_seed: int, n: int
) -> tuple[np.ndarray, np.ndarray]:
    """(512, 4) object input and (512, 3) normals for one row, deterministic in `row_seed`
    (anchors None: the input without anchors, learned.contact_map.object_input)."""
    pts, nrm = dense_object(category, seed, n)
    inp = object_input(pts, anchors, np.random.default_rng(row_seed))
    return inp.features, nrm[inp.index].astype(np.float32)


def embed(texts: list[str]) -> np.ndarray:
    """Sentence embeddings (learned.text) of each text, computed once per distinct text."""
    from learned.text import encode

    distinct = sorted(set(texts))
    table = dict(zip(distinct, encode(distinct), strict=True))
    return np.stack([table[t] for t in texts]).astype(np.float32)


def prepare(
    root: str | Path | Sequence[str | Path],
    split: str,
    hands: tuple[str, ...] | None = None,
    dense_points: int = 4096,
    cache: Path | None = None,
    progress: bool = True,
    max_rows: int | None = None,
    use_anchors: bool = True,
    blocks: int | None = None,
) -> Prepared:
    """The split's rows as arrays (optionally only some hands'), cached in `cache` (an .npz)
    keyed by the dataset's meta.json and the options; `use_anchors` False: object inputs without
    the anchors' contact map (DROConfig.anchors)."""
    from models.hands import load_hand

    data = load_split(root, split, blocks)
    a, meta = data.arrays, data.meta
    keep = np.ones(len(data), dtype=bool)
    if hands is not None:
        unknown = set(hands) - set(meta["hands"])
        if unknown:
            raise DatasetError(f"hands {sorted(unknown)} not in the dataset ({meta['hands']})")
        keep &= np.isin(a["hand"], [meta["hands"].index(h) for h in hands])
    if "intent_ok" in a:  # drop grasps known to miss their intent (0); unknown (-1) stays
        keep &= a["intent_ok"].astype(bool)
    rows = np.flatnonzero(keep)[:max_rows]
    if len(rows) == 0:
        raise TrainingError(f"{root}: no {split} rows" + (f" for hands {hands}" if hands else ""))
    roots = [root] if isinstance(root, str | Path) else list(root)
    meta_text = b"".join((Path(r) / "meta.json").read_bytes() for r in roots)
    key = hashlib.sha256(
        meta_text
        + json.dumps([split, hands, dense_points, rows.tolist()]).encode()
        + (b"" if use_anchors else b"no anchors")
    ).hexdigest()[:16]
    hand_names = [meta["hands"][i] for i in a["hand"][rows]]
    instructions = [meta["instructions"][i] for i in a["instruction"][rows]]
    categories = [meta["categories"][i] for i in a["category"][rows]]
    seeds = a["seed"][rows].astype(np.int64)
    anchors = a["anchors"][rows].astype(np.float64)
    arrays = None
    if cache is not None and cache.is_file():
        with np.load(cache, allow_pickle=False) as npz:
            if str(npz["key"]) == key:
                arrays = {k: npz[k] for k in ("obj", "normals", "grasp_points")}
    if arrays is None:
        obj = np.zeros((len(rows), 512, 4), np.float32)
        normals = np.zeros((len(rows), 512, 3), np.float32)
        from tqdm import tqdm

        for i in tqdm(range(len(rows)), desc=f"object inputs ({split})", disable=not progress):
            obj[i], normals[i] = row_object_input(
                categories[i],
                int(seeds[i]),
                anchors[i] if use_anchors else None,
                int(rows[i]),
                dense_points,
            )
        grasp_points = np.zeros((len(rows), 512, 3), np.float32)
        for name in sorted(set(hand_names)):
            hand = load_hand(name)
            sel = np.flatnonzero(np.array(hand_names) == name)
            q = a["q_grasp"][rows[sel], : hand.dof].astype(np.float64)
            pts = hand.surface_points(a["wrist"][rows[sel]].astype(np.float64), q)
            grasp_points[sel] = pts.numpy().astype(np.float32)
        arrays = {"obj": obj, "normals": normals, "grasp_points": grasp_points}
        if cache is not None:
            cache.parent.mkdir(parents=True, exist_ok=True)
            tmp = cache.with_suffix(".tmp.npz")
            np.savez(tmp, key=np.array(key), **arrays)
            tmp.replace(cache)
    return Prepared(
        hands=hand_names,
        text=embed(instructions),
        wrist=a["wrist"][rows].astype(np.float64),
        q_grasp=a["q_grasp"][rows].astype(np.float64),
        instructions=instructions,
        categories=categories,
        seeds=seeds,
        anchors=anchors,
        row=rows,
        **arrays,
    )


# ---- batches -------------------------------------------------------------------------------
def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    w1, x1, y1, z1 = np.moveaxis(a, -1, 0)
    w2, x2, y2, z2 = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ],
        axis=-1,
    )


def perturb_wrist(
    wrist: np.ndarray, rng: np.random.Generator, rotation: float, translation: float
) -> np.ndarray:
    """Wrists (B, 7) turned by up to `rotation` rad about random axes and moved by Gaussian
    `translation` (m): the input a first stage that is close but not exact would give."""
    out = np.array(wrist, dtype=np.float64, copy=True)
    if rotation <= 0 and translation <= 0:
        return out
    axis = rng.normal(size=(len(out), 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    angle = rng.uniform(0, rotation, size=(len(out), 1))
    dq = np.concatenate([np.cos(angle / 2), np.sin(angle / 2) * axis], axis=1)
    out[:, 3:] = _quat_mul(dq, out[:, 3:])
    out[:, 3:] /= np.linalg.norm(out[:, 3:], axis=1, keepdims=True)
    out[:, :3] += rng.normal(scale=translation, size=(len(out), 3))
    return out


@dataclass
class Batch:
    hands: list[str]
    hand_in: torch.Tensor  # (B, 512, 3)
    obj: torch.Tensor  # (B, 512, 4)
    normals: torch.Tensor  # (B, 512, 3)
    text: torch.Tensor  # (B, 384)
    truth: torch.Tensor  # (B, 512, 3) hand points at the dataset grasp


def make_batch(
    data: Prepared, rows: np.ndarray, cfg: TrainConfig, rng: np.random.Generator | None
) -> Batch:
    """The rows' samples; with `rng`, fresh wrist and joint noise on the hand input."""
    from models.hands import load_hand

    names = [data.hands[r] for r in rows]
    wrist = data.wrist[rows]
    if rng is not None:
        wrist = perturb_wrist(wrist, rng, cfg.wrist_rotation_noise, cfg.wrist_translation_noise)
    hand_in = np.zeros((len(rows), 512, 3), np.float32)
    for name in sorted(set(names)):
        sel = np.flatnonzero(np.array(names) == name)
        hand_in[sel] = input_hand_points(
            load_hand(name), wrist[sel], rng, cfg.joint_noise if rng is not None else 0.0
        )
    return Batch(
        hands=names,
        hand_in=torch.from_numpy(hand_in),
        obj=torch.from_numpy(data.obj[rows]),
        normals=torch.from_numpy(data.normals[rows]),
        text=torch.from_numpy(data.text[rows]),
        truth=torch.from_numpy(data.grasp_points[rows]),
    )


# ---- losses --------------------------------------------------------------------------------
def losses(
    net: DRONet, batch: Batch, cfg: TrainConfig, index: np.ndarray
) -> dict[str, torch.Tensor]:
    """The step's losses for the hand points `index` (shared by the batch)."""
    idx = torch.as_tensor(index)[None].expand(len(batch.hands), -1)
    d = net(batch.hand_in, batch.obj, batch.text, hand_index=idx)
    obj_xyz = batch.obj[..., :3]
    true_d = torch.cdist(batch.truth[:, index], obj_xyz)
    # the near pairs' mean error plus the far pairs' mean shortfall below the clip, kept apart:
    # over all pairs the far ones (most of them) drown the near ones, and one mean over "near
    # on either side" is gamed by predicting everything just under the clip
    near_pair = true_d < cfg.clip
    near_err = ((d - true_d).abs() * near_pair).sum() / near_pair.sum().clamp_min(1)
    far_err = (torch.relu(cfg.clip - d) * ~near_pair).sum() / (~near_pair).sum().clamp_min(1)
    l1 = near_err + far_err
    prior = batch.hand_in[:, index]
    placed = place_hand(batch.hands, obj_xyz, d, index, cfg.neighbours, prior)
    all_d = torch.cdist(batch.truth, obj_xyz)
    near = (all_d.min(dim=-1).values < cfg.clip) & torch.isfinite(placed).all(-1)
    placed = torch.nan_to_num(placed)
    # clamped: a point thrown far by a bad multilateration should not dominate the step
    err = torch.linalg.norm(placed - batch.truth, dim=-1).clamp(max=cfg.clip)
    pose = (err * near).sum() / near.sum().clamp_min(1)
    to_obj = torch.cdist(placed, obj_xyz)
    nearest = to_obj.argmin(dim=-1)
    o = torch.gather(obj_xyz, 1, nearest[..., None].expand(-1, -1, 3))
    n = torch.gather(batch.normals, 1, nearest[..., None].expand(-1, -1, 3))
    depth = torch.relu(-((placed - o) * n).sum(-1)) * (to_obj.min(dim=-1).values < 0.01)
    penetration = (depth * near).sum() / near.sum().clamp_min(1)
    total = l1 + cfg.pose_weight * pose + cfg.penetration_weight * penetration
    return {"loss": total, "l1": l1, "pose": pose, "penetration": penetration}


@torch.no_grad()
def d_error(net: DRONet, data: Prepared, rows: np.ndarray, cfg: TrainConfig) -> float:
    """Mean |D_hat - D| (m) over pairs with D < 5 cm, dataset wrists and open fingers."""
    total, count = 0.0, 0
    for start in range(0, len(rows), cfg.batch):
        b = make_batch(data, rows[start : start + cfg.batch], cfg, None)
        d = net(b.hand_in, b.obj, b.text)
        true_d = torch.cdist(b.truth, b.obj[..., :3])
        close = true_d < 0.05
        total += float((d - true_d).abs()[close].sum())
        count += int(close.sum())
    return total / max(count, 1)


# ---- the loop ------------------------------------------------------------------------------
def _save_plot(history: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if not history:
        return
    steps = np.array([h["step"] for h in history])
    fig, ax = plt.subplots(figsize=(7, 4))
    for key in ("loss", "l1", "pose", "penetration"):
        y = np.array([h[key] for h in history])
        w = max(1, len(y) // 50)
        smooth = np.convolve(y, np.ones(w) / w, mode="valid")
        ax.plot(steps[w - 1 :], smooth, label=key)
    vals = [(h["step"], h["val_d_error"]) for h in history if "val_d_error" in h]
    if vals:
        ax.plot(*zip(*vals, strict=True), "k.", label="val D error (m, D<5cm)")
    ax.set_yscale("log")
    ax.set_xlabel("step")
    ax.set_ylabel("loss (m)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def train(cfg: TrainConfig, progress: bool = True) -> Path:
    """Train (or resume) into cfg.out; returns the weights file."""
    from tqdm import tqdm

    torch.set_num_threads(cfg.threads)
    out = Path(cfg.out)
    out.mkdir(parents=True, exist_ok=True)
    hands = tuple(cfg.hands) if cfg.hands else None
    args = (hands, cfg.dense_points)
    more = {"max_rows": cfg.max_rows, "use_anchors": cfg.net.anchors, "blocks": cfg.blocks}
    data = prepare(cfg.data, "train", *args, out / "cache_train.npz", progress, **more)
    val = prepare(cfg.data, "val", *args, out / "cache_val.npz", progress, **more)
    val_rows = np.random.default_rng(cfg.seed).permutation(len(val))[: cfg.val_rows]
    torch.manual_seed(cfg.seed)
    net = DRONet(cfg.net)
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr)
    per_epoch = math.ceil(len(data) / cfg.batch)
    total_steps = cfg.epochs * per_epoch
    sched = torch.optim.lr_scheduler.OneCycleLR(
        opt, max_lr=cfg.lr, total_steps=total_steps, pct_start=0.05
    )
    step, history, elapsed = 0, [], 0.0
    ckpt = out / "checkpoint.pt"
    stops = {"out": None, "minutes": None, "steps": None}  # a resumed run may stop elsewhere
    settings = json.dumps(asdict(cfg) | stops, sort_keys=True)
    if ckpt.is_file():
        state = torch.load(ckpt, weights_only=True)  # tensors and plain values, no pickle
        if state["settings"] != settings:
            raise TrainingError(
                f"{ckpt} was written by a run with other settings; use another --out or "
                "delete the checkpoint to start over"
            )
        net.load_state_dict(state["net"])
        opt.load_state_dict(state["opt"])
        sched.load_state_dict(state["sched"])
        step, history, elapsed = state["step"], state["history"], state["elapsed"]
        torch.set_rng_state(state["torch_rng"])

    def save() -> None:
        tmp = ckpt.with_suffix(".tmp")
        torch.save(
            {
                "net": net.state_dict(),
                "opt": opt.state_dict(),
                "sched": sched.state_dict(),
                "step": step,
                "history": history,
                "elapsed": elapsed,
                "settings": settings,
                "torch_rng": torch.get_rng_state(),
            },
            tmp,
        )
        tmp.replace(ckpt)
        _save_plot(history, out / "loss.png")

    budget = None if cfg.minutes is None else 60.0 * cfg.minutes
    bar = tqdm(total=total_steps, initial=step, desc="dro", disable=not progress)
    net.train()
    last = total_steps if cfg.steps is None else min(total_steps, cfg.steps)
    while step < last and (budget is None or elapsed < budget):
        epoch, pos = divmod(step, per_epoch)
        order = np.random.default_rng([cfg.seed, epoch]).permutation(len(data))
        rows = order[pos * cfg.batch : (pos + 1) * cfg.batch]
        rng = np.random.default_rng([cfg.seed, epoch, pos, 1])
        t0 = time.perf_counter()
        index = np.sort(rng.choice(512, cfg.hand_points, replace=False))
        parts = losses(net, make_batch(data, rows, cfg, rng), cfg, index)
        opt.zero_grad()
        parts["loss"].backward()
        torch.nn.utils.clip_grad_norm_(net.parameters(), 1.0)
        opt.step()
        sched.step()
        step += 1
        elapsed += time.perf_counter() - t0
        record = {"step": step, **{k: v.item() for k, v in parts.items()}}
        bar.set_postfix(loss=f"{record['loss']:.4f}", l1=f"{record['l1'] * 1000:.1f}mm")
        bar.update(1)
        if step % cfg.checkpoint_every == 0 or step == total_steps:
            net.eval()
            record["val_d_error"] = d_error(net, val, val_rows, cfg)
            net.train()
        history.append(record)
        if step % cfg.checkpoint_every == 0:
            save()
    bar.close()
    net.eval()
    if "val_d_error" not in history[-1]:
        history[-1]["val_d_error"] = d_error(net, val, val_rows, cfg)
    save()
    weights = out / "dro.safetensors"
    save_weights(
        net,
        weights,
        {
            "steps": step,
            "epochs": step / per_epoch,
            "train_rows": len(data),
            "hands": sorted(set(data.hands)),
            "data": cfg.data if isinstance(cfg.data, str) else " ".join(map(str, cfg.data)),
            "blocks": cfg.blocks,
            "val_d_error_m": history[-1]["val_d_error"],
            "train_seconds": round(elapsed, 1),
            "seed": cfg.seed,
        },
    )
    return weights


# TrainConfig fields that `drograsp train dro` sets (planner/commands/train.py)
OPTIONS = (
    "epochs",
    "minutes",
    "steps",
    "batch",
    "lr",
    "hand_points",
    "pose_weight",
    "seed",
    "threads",
    "checkpoint_every",
    "max_rows",
    "blocks",
)


def config_from_args(args: argparse.Namespace) -> TrainConfig:
    """A TrainConfig from parsed options; options left out keep TrainConfig's defaults."""
    given = {name: getattr(args, name, None) for name in OPTIONS}
    data = args.data[0] if isinstance(args.data, list) and len(args.data) == 1 else args.data
    cfg = TrainConfig(data, args.out, **{k: v for k, v in given.items() if v is not None})
    if getattr(args, "hands", None):
        cfg.hands = tuple(args.hands)
    if getattr(args, "no_anchors", False):
        cfg.net = replace(cfg.net, anchors=False)
    return cfg


def run(args: argparse.Namespace) -> int:
    """Train (or resume), print the outcome; with --install copy the weights into the package."""
    weights = train(config_from_args(args))
    meta = load_weights(weights).meta
    print(
        f"trained {meta['steps']} steps ({meta['epochs']:.2f} epochs, {meta['train_seconds']} s):"
        f" validation D error {meta['val_d_error_m'] * 1000:.1f} mm on pairs under 5 cm\n"
        f"weights: {weights}\ncurve: {Path(args.out) / 'loss.png'}"
    )
    if getattr(args, "install", False):
        target = WEIGHTS if load_weights(weights).net.cfg.anchors else NO_ANCHOR_WEIGHTS
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(weights, target)
        print(f"installed: {target}")
    return 0
