"""Benchmark of the interaction model (issue 24) beside a nearest-neighbour baseline.

For every object of a split, every instruction of its category's table and every hand: draw
8 samples from the model (and 8 from the baseline) and score them with the object's part labels
(used only to score, never as input):

- part accuracy: samples with >= 3 of 4 anchors on the instructed part;
- instruction sensitivity: on objects with two or more instructible parts, the share of pairs
  of instructions naming different parts A, B where most samples for A land on A and most
  samples for B on B;
- palm outside: the palm centre (hand.json's palm) outside the object's mesh;
- diversity: mean pairwise wrist distance of the 8 samples, beside the dataset's own spread for
  the same (object, instruction, hand) where it has two or more grasps;
- the data's own part accuracy: the split's grasps with >= 3 anchors on the part, counted as
  training curates its rows (on each object's cached points); a model that reproduced its data
  would score about this;
- time: median wall time of `sample(cloud, text, hand, 8)` on one thread.

The baseline returns the training grasps of the most similar instruction embedding and object
shape (same hand), each moved onto the query through the canonical frames: it shows what the
learned model adds over retrieval.

    python -m eval.interaction --split test [--paraphrase] [--rotate] [--weights DIR]
"""

from __future__ import annotations

import argparse
import itertools
import json
import statistics
import time
from collections import defaultdict
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation
from tqdm import tqdm

from learned import text as text_model
from learned.dataset import load_split
from learned.interaction import (
    InteractionModel,
    canonical_frame,
    decode_x,
    encode_x,
    load_model,
    snap_to_cloud,
)
from learned.paraphrase import eval_paraphrases, request_of
from learned.train_interaction import ObjectPoints, anchors_on_part, random_rotation, usable_rows
from models.hands import available_hands, load_hand
from models.objects import instructions, make_object
from models.objects.cache import cache_dir

SAMPLES = 8


@dataclass
class GroupResult:
    """One (object, instruction text, hand) with its samples scored, for one method."""

    method: str
    hand: str
    category: str
    seed: int
    instruction: str
    text: str
    part: str
    on_part: list[bool]  # per sample: >= 3 of 4 anchors on the instructed part
    palm_outside: list[bool]
    spread: float  # mean pairwise wrist distance, m
    data_spread: float | None  # the dataset's for the same group, m
    seconds: float


@dataclass
class Summary:
    method: str
    hand: str
    samples: int
    part_accuracy: float
    sensitivity: float | None
    sensitivity_pairs: int
    palm_outside: float
    spread_cm: float
    data_spread_cm: float | None
    median_seconds: float


@dataclass
class Report:
    split: str
    paraphrase: bool
    rotate: bool
    weights: dict
    summaries: list[Summary] = field(default_factory=list)
    groups: list[GroupResult] = field(default_factory=list)
    # the split's own grasps with >= 3 of 4 anchors on the instructed part, per hand and
    # "all": what a model reproducing its data would score
    data_part_accuracy: dict[str, float] = field(default_factory=dict)


# ---- the nearest-neighbour baseline ------------------------------------------------------------
def shape_descriptor(points: np.ndarray) -> np.ndarray:
    """Canonical-frame extents and a histogram of distances to the centroid (metres-aware)."""
    frame = canonical_frame(points)
    c = frame.to_canonical(points)
    ext = np.ptp(c, axis=0)
    r = np.linalg.norm(c, axis=1)
    hist = np.histogram(r, bins=16, range=(0.0, 0.25))[0] / len(r)
    return np.concatenate([ext * 10.0, hist])


class NearestNeighbour:
    """Training grasps retrieved by instruction embedding, then object shape, per hand."""

    def __init__(self, data: str, cache: ObjectPoints):
        train = load_split(data, "train")
        rows = usable_rows(train)
        a, meta = train.arrays, train.meta
        self.hands = np.array([meta["hands"][i] for i in a["hand"][rows]])
        texts = [meta["instructions"][i] for i in a["instruction"][rows]]
        self.text_vecs = text_model.encode(texts)
        self.wrist = a["wrist"][rows].astype(np.float64)
        self.anchors = a["anchors"][rows].astype(np.float64)
        keys = list(
            zip([meta["categories"][i] for i in a["category"][rows]], a["seed"][rows], strict=True)
        )
        desc, frames = {}, {}
        for cat, seed in sorted(set(keys)):
            pts = cache.get(cat, int(seed))["points"][0].astype(np.float64)
            desc[(cat, seed)] = shape_descriptor(pts)
            frames[(cat, seed)] = canonical_frame(pts)
        self.desc = np.stack([desc[k] for k in keys])
        # training grasps in their objects' canonical frames (unnormalised network units)
        self.x = np.stack(
            [
                encode_x(self.wrist[i][None], self.anchors[i][None], frames[k])[0]
                for i, k in enumerate(keys)
            ]
        )

    def sample(
        self, cloud: np.ndarray, text_vec: np.ndarray, hand: str, n: int
    ) -> tuple[np.ndarray, np.ndarray]:
        mask = self.hands == hand
        if not mask.any():
            mask = np.ones(len(self.hands), dtype=bool)
        idx = np.flatnonzero(mask)
        sim = self.text_vecs[idx] @ text_vec
        best = idx[sim >= sim.max() - 1e-6]  # the closest instruction(s)
        d = np.linalg.norm(self.desc[best] - shape_descriptor(cloud)[None], axis=1)
        chosen = best[np.argsort(d, kind="stable")[:n]]
        if len(chosen) < n:
            chosen = np.resize(chosen, n)
        wrists, anchors = decode_x(self.x[chosen], canonical_frame(cloud))
        return wrists, snap_to_cloud(anchors, cloud)


# ---- scoring -----------------------------------------------------------------------------------
def mean_pairwise(points: np.ndarray) -> float:
    if len(points) < 2:
        return float("nan")
    d = [np.linalg.norm(a - b) for a, b in itertools.combinations(points, 2)]
    return float(np.mean(d))


def score(
    wrists: np.ndarray,
    anchors: np.ndarray,
    labelled: np.ndarray,
    labels: np.ndarray,
    part: int,
    mesh,
    palm_centre: np.ndarray,
) -> tuple[list[bool], list[bool]]:
    """(on part, palm outside) per sample; inputs in the object's own frame."""
    tree = cKDTree(labelled)
    lab = labels[tree.query(anchors.reshape(-1, 3))[1]].reshape(len(anchors), 4)
    on_part = [(row == part).sum() >= 3 for row in lab]
    rot = Rotation.from_quat(wrists[:, 3:], scalar_first=True)
    palms = wrists[:, :3] + rot.apply(palm_centre)
    with np.errstate(divide="ignore", invalid="ignore"):  # trimesh's ray test on edge hits
        outside = [not bool(v) for v in mesh.contains(palms)]
    return [bool(v) for v in on_part], outside


def run(
    split: str,
    data: str = "data/grasps_v2",
    paraphrase: bool = False,
    rotate: bool = False,
    weights: str | None = None,
    hands: list[str] | None = None,
    limit: int | None = None,
    samples: int = SAMPLES,
    seed: int = 0,
    progress: bool = True,
    guidance: float | None = None,
    sample_steps: int | None = None,
) -> Report:
    torch.set_num_threads(1)
    model: InteractionModel = load_model(weights)
    if guidance is not None:
        model.config.guidance = guidance
    if sample_steps is not None:
        model.config.sample_steps = sample_steps
    cache = ObjectPoints(cache_dir("interaction_points"), model.config.points, 1)
    baseline = NearestNeighbour(data, cache)
    split_data = load_split(data, split)
    a, meta = split_data.arrays, split_data.meta
    objects = sorted(
        {(meta["categories"][c], int(s)) for c, s in zip(a["category"], a["seed"], strict=True)}
    )
    if limit is not None:
        objects = objects[:limit]
    hands = hands or available_hands()
    # the dataset's own spread per (category, seed, instruction, hand)
    groups_data: dict[tuple, list[np.ndarray]] = defaultdict(list)
    for r in usable_rows(split_data):
        key = (
            meta["categories"][a["category"][r]],
            int(a["seed"][r]),
            meta["instructions"][a["instruction"][r]],
            meta["hands"][a["hand"][r]],
        )
        groups_data[key].append(a["wrist"][r, :3].astype(np.float64))
    sampling = {"guidance": model.config.guidance, "sample_steps": model.config.sample_steps}
    report = Report(
        split, paraphrase, rotate, {"folder": weights or "package", **model.info, **sampling}
    )
    rng = np.random.default_rng(seed)
    jobs = [(o, h) for o in objects for h in hands]
    for (cat, oseed), hand in tqdm(jobs, disable=not progress, desc=f"eval {split}"):
        obj = make_object(cat, oseed)
        dense, labels = obj.points, obj.point_labels
        cloud = dense[np.random.default_rng(oseed).choice(len(dense), 4096, replace=False)]
        palm = np.asarray(load_hand(hand).meta.palm.center, dtype=np.float64)
        for instr in instructions(cat):
            canonical = instr.text
            part = obj.part_names.index(instr.part)
            texts = eval_paraphrases(request_of(canonical)) if paraphrase else [canonical]
            for txt in texts:
                rot = random_rotation(rng) if rotate else np.eye(3)
                query = cloud @ rot.T
                vec = text_model.encode([txt])[0]
                data_pts = groups_data.get((cat, oseed, canonical, hand), [])
                data_spread = mean_pairwise(np.stack(data_pts)) if len(data_pts) >= 2 else None
                for method in ("model", "nearest"):
                    t0 = time.perf_counter()
                    if method == "model":
                        w, anc = model.sample(
                            query, txt, hand, samples, seed=int(rng.integers(1 << 30))
                        )
                    else:
                        w, anc = baseline.sample(query, vec, hand, samples)
                    secs = time.perf_counter() - t0
                    # back to the object's frame for scoring
                    w = w.copy()
                    w[:, :3] = w[:, :3] @ rot
                    back = Rotation.from_matrix(rot.T) * Rotation.from_quat(
                        w[:, 3:], scalar_first=True
                    )
                    w[:, 3:] = back.as_quat(scalar_first=True)
                    anc = anc @ rot
                    on_part, outside = score(w, anc, dense, labels, part, obj.mesh, palm)
                    report.groups.append(
                        GroupResult(
                            method,
                            hand,
                            cat,
                            oseed,
                            canonical,
                            txt,
                            instr.part,
                            on_part,
                            outside,
                            mean_pairwise(w[:, :3]),
                            data_spread,
                            secs,
                        )
                    )
    report.summaries = summarise(report.groups, hands)
    report.data_part_accuracy = data_part_accuracy(split_data, objects, hands, cache)
    report.summaries += timing(model, hands)
    return report


def data_part_accuracy(
    split_data, objects: list[tuple[str, int]], hands: list[str], cache: ObjectPoints
) -> dict[str, float]:
    """Per hand of `hands` and "all": the share of the split's grasps on `objects` with >= 3
    of their 4 anchors on the instructed part (counted as training curates its rows,
    `learned.train_interaction.anchors_on_part`)."""
    a, meta = split_data.arrays, split_data.meta
    hand_names = np.asarray(meta["hands"])[a["hand"]]
    wanted = {(c, int(s)) for c, s in objects}
    on_objects = [
        (meta["categories"][c], int(s)) in wanted
        for c, s in zip(a["category"], a["seed"], strict=True)
    ]
    rows = np.flatnonzero(np.asarray(on_objects, dtype=bool) & np.isin(hand_names, hands))
    ok = anchors_on_part(split_data, rows, cache) >= 3
    shares = {h: ok[hand_names[rows] == h] for h in hands}
    shares["all"] = ok
    return {h: float(np.mean(v)) for h, v in shares.items() if len(v)}


def summarise(groups: list[GroupResult], hands: list[str]) -> list[Summary]:
    out = []
    for method in ("model", "nearest"):
        for hand in [*hands, "all"]:
            gs = [g for g in groups if g.method == method and (hand == "all" or g.hand == hand)]
            if not gs:
                continue
            on = [v for g in gs for v in g.on_part]
            palm = [v for g in gs for v in g.palm_outside]
            sens_ok, sens_n = sensitivity(gs)
            paired = [g for g in gs if g.data_spread is not None]
            out.append(
                Summary(
                    method=method,
                    hand=hand,
                    samples=len(on),
                    part_accuracy=float(np.mean(on)),
                    sensitivity=sens_ok / sens_n if sens_n else None,
                    sensitivity_pairs=sens_n,
                    palm_outside=float(np.mean(palm)),
                    spread_cm=100 * float(np.nanmean([g.spread for g in paired] or [np.nan])),
                    data_spread_cm=100 * float(np.mean([g.data_spread for g in paired]))
                    if paired
                    else None,
                    median_seconds=float(statistics.median(g.seconds for g in gs)),
                )
            )
    return out


def sensitivity(groups: list[GroupResult]) -> tuple[int, int]:
    """(pairs passed, pairs): instruction pairs on one object and hand naming different parts,
    passed when most samples of each land on its own part."""
    by_obj: dict[tuple, list[GroupResult]] = defaultdict(list)
    for g in groups:
        by_obj[(g.hand, g.category, g.seed, g.text == g.instruction)].append(g)
    ok = n = 0
    for gs in by_obj.values():
        for x, y in itertools.combinations(gs, 2):
            if x.part == y.part:
                continue
            n += 1
            ok += int(np.mean(x.on_part) > 0.5 and np.mean(y.on_part) > 0.5)
    return ok, n


def timing(model: InteractionModel, hands: list[str], repeats: int = 15) -> list[Summary]:
    """Median time of 8 samples for one (cloud, text, hand) on one thread, cached text."""
    obj = make_object("mug", 3)
    cloud = obj.points[::4]
    out = []
    for hand in hands:
        model.sample(cloud, "Use a mug by handle", hand, SAMPLES)
        times = []
        for i in range(repeats):
            t0 = time.perf_counter()
            model.sample(cloud, "Use a mug by handle", hand, SAMPLES, seed=i)
            times.append(time.perf_counter() - t0)
        out.append(
            Summary(
                "timing",
                hand,
                SAMPLES,
                float("nan"),
                None,
                0,
                float("nan"),
                float("nan"),
                None,
                float(statistics.median(times)),
            )
        )
    return out


def print_table(report: Report) -> None:
    mode = ", ".join(
        m for m, on in (("eval paraphrases", report.paraphrase), ("rotated", report.rotate)) if on
    )
    print(f"interaction benchmark: split {report.split}{' (' + mode + ')' if mode else ''}")
    head = f"{'method':8} {'hand':8} {'samples':>7} {'part acc':>8} {'sens':>11} {'palm out':>8} {'spread cm':>9} {'data cm':>7} {'med s':>6}"
    print(head)
    for s in report.summaries:
        if s.method == "timing":
            continue
        sens = (
            "-" if s.sensitivity is None else f"{100 * s.sensitivity:.0f}% ({s.sensitivity_pairs})"
        )
        data = "-" if s.data_spread_cm is None else f"{s.data_spread_cm:.1f}"
        print(
            f"{s.method:8} {s.hand:8} {s.samples:7d} {100 * s.part_accuracy:7.1f}% {sens:>11} "
            f"{100 * s.palm_outside:7.1f}% {s.spread_cm:9.1f} {data:>7} {s.median_seconds:6.3f}"
        )
    if report.data_part_accuracy:
        shares = ", ".join(f"{h} {100 * v:.1f}%" for h, v in report.data_part_accuracy.items())
        print(f"the split's own grasps with >= 3 anchors on the part: {shares}")
    for s in report.summaries:
        if s.method == "timing":
            print(f"8 samples, one thread, {s.hand}: median {s.median_seconds * 1000:.0f} ms")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--split", choices=["test", "val", "heldout", "train"], default="test")
    p.add_argument("--data", default="data/grasps_v2")
    p.add_argument("--paraphrase", action="store_true", help="evaluation-only paraphrases")
    p.add_argument("--rotate", action="store_true", help="any yaw, tilt <= 30 degrees")
    p.add_argument("--weights", default=None, help="folder of interaction.safetensors")
    p.add_argument("--hands", nargs="+", default=None)
    p.add_argument("--limit", type=int, default=None, help="first N objects of the split")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--guidance", type=float, default=None, help="guidance scale (the config's)")
    p.add_argument("--sample-steps", type=int, default=None, help="DDIM steps (the config's)")
    p.add_argument("--out", default=None, help="JSON path (default eval_interaction_SPLIT.json)")
    args = p.parse_args(argv)
    report = run(
        args.split,
        args.data,
        args.paraphrase,
        args.rotate,
        args.weights,
        args.hands,
        args.limit,
        seed=args.seed,
        guidance=args.guidance,
        sample_steps=args.sample_steps,
    )
    print_table(report)
    suffix = ("_para" if args.paraphrase else "") + ("_rot" if args.rotate else "")
    out = Path(args.out or f"eval_interaction_{args.split}{suffix}.json")
    out.write_text(json.dumps(asdict(report), indent=1, default=_json_default), encoding="utf-8")
    print(f"wrote {out}")
    return 0


def _json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")


if __name__ == "__main__":
    raise SystemExit(main())
