"""Batch results -> the compact dataset (learned.dataset's format) and its dataset card.

Keeps the grasps that hold in validation and touch the instructed part, drops duplicates
(same object, instruction and hand, wrist within 1 mm and 1 degree, joints within 0.01 rad),
splits by object instance (models.objects.split_of), and writes the card from the written
arrays, so the card always matches what the loader reads. `compact` writes a dataset afresh
(one block); `add_block` appends one block to a growing dataset (dataset generation adds one
per range of seeds, so a generation spread over sessions keeps every finished block).
"""

from __future__ import annotations

import json
import os
from collections import Counter, defaultdict
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from learned.dataset import (
    FORMAT,
    METRICS,
    SOURCES,
    SPLIT_NAMES,
    DatasetError,
    block_path,
    dataset_info,
    empty_arrays,
    load_split,
    read_meta,
)
from models.hands import load_hand
from models.objects import INTENTS, categories, category, parse_instruction, split_of
from planner.batch.runner import read_results, write_atomic

DUPLICATE_POSITION = 0.001  # m
DUPLICATE_ANGLE = 1.0  # degrees
DUPLICATE_JOINTS = 0.01  # rad, largest joint difference


@dataclass
class GeneratorStats:
    """How the generator did, per source (plan, transfer) and hand, before deduplication."""

    jobs: Counter = field(default_factory=Counter)
    errors: Counter = field(default_factory=Counter)
    holds: Counter = field(default_factory=Counter)
    valid: Counter = field(default_factory=Counter)  # jobs with a valid grasp
    grasps: Counter = field(default_factory=Counter)  # valid grasps (several per validate_all job)
    kept: Counter = field(default_factory=Counter)
    transfers: Counter = field(default_factory=Counter)  # "src->dst" jobs
    transfers_valid: Counter = field(default_factory=Counter)
    skipped_objects: int = 0  # valid grasps on non-library objects (no split): not kept

    def to_dict(self) -> dict[str, Any]:
        def rows(counter: Counter) -> dict[str, int]:
            return {k: int(v) for k, v in sorted(counter.items())}

        return {
            "jobs": rows(self.jobs),
            "errors": rows(self.errors),
            "holds": rows(self.holds),
            "valid": rows(self.valid),
            "grasps": rows(self.grasps),
            "kept": rows(self.kept),
            "transfers": rows(self.transfers),
            "transfers_valid": rows(self.transfers_valid),
            "skipped_objects": self.skipped_objects,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> GeneratorStats:
        counters = {k: Counter(v) for k, v in data.items() if k != "skipped_objects"}
        return cls(**counters, skipped_objects=int(data.get("skipped_objects", 0)))

    def __add__(self, other: GeneratorStats) -> GeneratorStats:
        sums = {
            name: getattr(self, name) + getattr(other, name)
            for name in self.__dataclass_fields__
            if name != "skipped_objects"
        }
        return GeneratorStats(**sums, skipped_objects=self.skipped_objects + other.skipped_objects)


def _rotation_deg(a: np.ndarray, b: np.ndarray) -> float:
    w = min(1.0, abs(float(np.dot(a / np.linalg.norm(a), b / np.linalg.norm(b)))))
    return float(np.degrees(2 * np.arccos(w)))


def _duplicate(row: dict[str, Any], kept: list[dict[str, Any]]) -> bool:
    for other in kept:
        if np.linalg.norm(row["wrist"][:3] - other["wrist"][:3]) > DUPLICATE_POSITION:
            continue
        if _rotation_deg(row["wrist"][3:], other["wrist"][3:]) > DUPLICATE_ANGLE:
            continue
        if np.abs(row["q_grasp"] - other["q_grasp"]).max() <= DUPLICATE_JOINTS:
            return True
    return False


def _row(record: dict[str, Any]) -> dict[str, Any]:
    job, grasp = record["job"], record["grasp"]
    validation = record.get("validation") or {}
    values = {
        "anchor_error": record.get("anchor_error"),
        "min_distance": record.get("min_distance"),
        "translation": validation.get("translation"),
        "rotation_deg": validation.get("rotation_deg"),
        "grasp_penetration": validation.get("grasp_penetration"),
        "contact_count": validation.get("contact_count"),
    }
    instruction = parse_instruction(job["instruction"])
    return {
        "hand": job["hand"],
        "category": category(job["object"]["category"]).name,
        "seed": int(job["object"]["seed"]),
        "instruction": instruction.text,
        "intent": instruction.intent,
        "part": record["part_voted"],
        "source": "transfer" if "source" in job else "plan",
        "variant": -1 if "source" in job else int(job.get("variant", 0)),
        "wrist": np.array(grasp["wrist_pos"] + grasp["wrist_quat"], dtype=float),
        "q_grasp": np.asarray(grasp["grasp"], dtype=float),
        "q_pregrasp": np.asarray(grasp["pregrasp"], dtype=float),
        "q_squeeze": np.asarray(grasp["squeeze"], dtype=float),
        "anchors": np.asarray(grasp["anchors"], dtype=float).reshape(4, 3),
        "metrics": np.array([np.nan if values[m] is None else values[m] for m in METRICS]),
        "intent_ok": {True: 1, False: 0}.get(grasp.get("metrics", {}).get("intent_ok"), -1),
    }


def _valid_grasps(record: dict[str, Any]) -> list[dict[str, Any]]:
    """The record's valid grasps as records of one grasp each: every holding candidate of a
    validate_all job, else the returned grasp if it is valid."""
    if "holding" in record:
        part = record["part_instructed"]
        return [{**record, **entry, "part_voted": part} for entry in record["holding"]]
    if record.get("valid") and record.get("grasp") is not None:
        return [record]
    return []


def collect(records: Iterable[dict[str, Any]]) -> tuple[list[dict[str, Any]], GeneratorStats]:
    """Valid, deduplicated rows from result records (in record order) and the generator's
    success counts."""
    stats = GeneratorStats()
    groups: dict[tuple, list[dict[str, Any]]] = defaultdict(list)
    rows = []
    for record in records:
        job = record.get("job") or {}
        source = "transfer" if "source" in job else "plan"
        key = f"{source}:{job.get('hand')}"
        stats.jobs[key] += 1
        stats.errors[key] += record.get("error") is not None
        stats.holds[key] += bool(record.get("success"))
        stats.valid[key] += bool(record.get("valid"))
        if source == "transfer":
            pair = f"{job['source']['hand']}->{job['hand']}"
            stats.transfers[pair] += 1
            stats.transfers_valid[pair] += bool(record.get("valid"))
        valid = _valid_grasps(record)
        stats.grasps[key] += len(valid)
        if valid and "category" not in job["object"]:
            stats.skipped_objects += len(valid)
            continue
        for one in valid:
            row = _row(one)
            group = groups[(row["hand"], row["category"], row["seed"], row["instruction"])]
            if _duplicate(row, group):
                continue
            group.append(row)
            rows.append(row)
            stats.kept[key] += 1
    return rows, stats


FIXED_TABLES = {
    "categories": list(categories()),
    "intents": list(INTENTS),
    "sources": list(SOURCES),
}


def _tables(rows: list[dict[str, Any]], old: dict[str, Any] | None) -> dict[str, list[str]]:
    """Name tables for `rows`: the old tables with any new names appended (indices of earlier
    blocks stay valid)."""
    tables: dict[str, list[str]] = {}
    for key, column in (("hands", "hand"), ("instructions", "instruction"), ("parts", "part")):
        names = list((old or {}).get(key, []))
        names += sorted({r[column] for r in rows} - set(names))
        tables[key] = names
    return tables | FIXED_TABLES


def _arrays(rows: list[dict[str, Any]], tables: dict[str, list[str]], dof: int) -> dict:
    out = empty_arrays(dof, len(rows))
    index = {key: {v: i for i, v in enumerate(vals)} for key, vals in tables.items()}
    for i, r in enumerate(rows):
        out["split"][i] = SPLIT_NAMES.index(split_of(r["category"], r["seed"]))
        out["hand"][i] = index["hands"][r["hand"]]
        out["category"][i] = index["categories"][r["category"]]
        out["seed"][i] = r["seed"]
        out["instruction"][i] = index["instructions"][r["instruction"]]
        out["intent"][i] = index["intents"][r["intent"]]
        out["part"][i] = index["parts"][r["part"]]
        out["source"][i] = index["sources"][r["source"]]
        out["variant"][i] = r["variant"]
        out["wrist"][i] = r["wrist"]
        d = len(r["q_grasp"])
        for phase in ("q_grasp", "q_pregrasp", "q_squeeze"):
            out[phase][i, :d] = r[phase]
        out["dof_mask"][i, :d] = True
        out["anchors"][i] = r["anchors"]
        out["metrics"][i] = r["metrics"]
        out["intent_ok"][i] = r["intent_ok"]
    return out


def _write(
    out: Path,
    name: str,
    rows: list[dict[str, Any]],
    stats: GeneratorStats,
    old: dict[str, Any] | None,
    extra: dict[str, Any],
    block: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Write block `name` from `rows` (`block`: more facts for its meta entry), then meta.json
    (the block listed: it is the commit point) and the card. Returns `dataset_info(out)`."""
    tables = _tables(rows, old)
    hand_dof = {h: load_hand(h).dof for h in tables["hands"]}
    out.mkdir(parents=True, exist_ok=True)
    path = block_path(out, name)
    path.parent.mkdir(exist_ok=True)
    tmp = path.with_name(f".{name}.{os.getpid()}.tmp.npz")
    np.savez_compressed(tmp, **_arrays(rows, tables, max(hand_dof.values(), default=1)))
    os.replace(tmp, path)
    blocks = dict((old or {}).get("blocks", {}))
    blocks[name] = {"grasps": len(rows), "generator": stats.to_dict()} | (block or {})
    total = GeneratorStats()
    for block in blocks.values():
        total = total + GeneratorStats.from_dict(block["generator"])
    meta = {
        "format": FORMAT,
        **tables,
        "hand_dof": hand_dof,
        "metrics": list(METRICS),
        "blocks": blocks,
        "generator": total.to_dict(),
        **extra,
    }
    write_atomic(out / "meta.json", json.dumps(meta, indent=1) + "\n")
    info = dataset_info(out)
    write_atomic(out / "card.md", dataset_card(out, info, meta))
    return info


def compact(
    result_dirs: Sequence[str | Path],
    out: str | Path,
    command: str | None = None,
    code: Sequence[str] = (),
) -> dict[str, Any]:
    """Write the dataset folder `out` afresh (one block, "all") from batch output folders
    (planned, then transfers): meta.json, blocks/all.npz, card.md. Returns `dataset_info(out)`."""
    out = Path(out)
    rows, stats = collect(r for d in result_dirs for r in read_results(d))
    for stale in (out / "blocks").glob("*.npz"):
        stale.unlink()
    return _write(out, "all", rows, stats, None, {"command": command, "code": list(code)})


def dataset_blocks(out: str | Path) -> dict[str, Any]:
    """The blocks a dataset folder holds (empty when there is no dataset yet)."""
    return read_meta(out)["blocks"] if (Path(out) / "meta.json").is_file() else {}


def check_settings(out: str | Path, settings: dict[str, Any]) -> None:
    """Refuse to grow a dataset with blocks made another way (checked before any work)."""
    if not (Path(out) / "meta.json").is_file():
        return
    old = read_meta(out).get("settings")
    if old != settings:
        changed = sorted(
            k for k in set(old or {}) | set(settings) if (old or {}).get(k) != settings.get(k)
        )
        raise DatasetError(
            f"{out} was generated with other settings (differing: {', '.join(changed)}); give a "
            "new output folder or the options it was made with (its card shows the command)"
        )


def _union(first: Sequence[str], more: Sequence[str]) -> list[str]:
    """`first`, then the items of `more` it lacks, in order."""
    return [*first, *(c for c in more if c not in first)]


def add_block(
    out: str | Path,
    name: str,
    result_dirs: Sequence[str | Path],
    *,
    settings: dict[str, Any],
    seeds: tuple[int, int],
    planned: tuple[int, int] | None = None,
    command: str | None = None,
    code: Sequence[str] = (),
    refreshed: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Append block `name` (results of seeds [start, end)) to the dataset in `out`, made with
    `settings` (what generated it; every block of a dataset must share them); `planned` is the
    seed range the generation aims at (the card reports progress against it). `refreshed`
    ({"categories", "code"}): replace the block the dataset holds instead, recording that these
    categories' rows were made again (see planner.batch.generate.refresh_dataset)."""
    out = Path(out)
    check_settings(out, settings)
    old = read_meta(out) if (out / "meta.json").is_file() else None
    held = (old or {}).get("blocks", {}).get(name)
    if held is not None and refreshed is None:
        raise DatasetError(f"{out} already holds block {name}")
    if held is None and refreshed is not None:
        raise DatasetError(f"{out} holds no block {name} to refresh")
    rows, stats = collect(r for d in result_dirs for r in read_results(d))
    if held is not None:  # the earlier code made the rows that were kept
        code = _union(held.get("code", []), code)
    codes = _union((old or {}).get("code", []), code)
    extra = {
        "settings": settings,
        "planned_seeds": list(planned or seeds),
        "command": command or (old or {}).get("command"),
        "code": codes,
    }
    block = {"seeds": list(seeds), "code": list(code)}
    if refreshed is not None:
        block["refreshed"] = [*held.get("refreshed", []), refreshed]
    return _write(out, name, rows, stats, old, extra, block)


def diversity(root: str | Path) -> dict[str, float]:
    """Spread of grasps within each (object, instruction, hand) group: grasps per group and
    mean pairwise wrist distance, wrist rotation and joint distance (groups of 2 or more)."""
    sizes, moves, turns, joints = [], [], [], []
    distinct = 0
    for split in SPLIT_NAMES:
        a = load_split(root, split).arrays
        pose = np.concatenate(  # the same hand pose on the same object, whatever instruction
            [
                np.stack([a["hand"], a["category"], a["seed"]], axis=1),
                np.round(a["wrist"] * 1000),
                np.round(a["q_grasp"] * 100),
            ],
            axis=1,
        )
        distinct += len(np.unique(pose, axis=0))
        keys = np.stack([a["hand"], a["category"], a["seed"], a["instruction"]], axis=1)
        _, group = np.unique(keys, axis=0, return_inverse=True)
        for g in np.unique(group):
            idx = np.flatnonzero(group == g)
            sizes.append(len(idx))
            for i, j in ((i, j) for k, i in enumerate(idx) for j in idx[k + 1 :]):
                moves.append(np.linalg.norm(a["wrist"][i, :3] - a["wrist"][j, :3]))
                turns.append(_rotation_deg(a["wrist"][i, 3:], a["wrist"][j, 3:]))
                mask = a["dof_mask"][i]
                diff = a["q_grasp"][i, mask] - a["q_grasp"][j, mask]
                joints.append(float(np.sqrt(np.mean(diff**2))))

    def mean(values: list[float]) -> float:
        return float(np.mean(values)) if values else float("nan")

    return {
        "distinct_poses": distinct,
        "groups": len(sizes),
        "grasps_per_group": mean(sizes),
        "wrist_distance_cm": 100 * mean(moves),
        "wrist_rotation_deg": mean(turns),
        "joint_rms_rad": mean(joints),
    }


def intent_table(root: str | Path) -> list[str]:
    """Per intent: grasps, the share meeting the intent's definition (rows checked), and
    distinct hand poses (wrist to 1 mm, joints to 0.01 rad, per object and hand)."""
    meta = read_meta(root)
    lines = [
        "| intent | grasps | meets its definition | not checked | distinct poses |",
        "|---|---:|---:|---:|---:|",
    ]
    columns = [load_split(root, split).arrays for split in SPLIT_NAMES]
    a = {k: np.concatenate([c[k] for c in columns]) for k in ("intent", "intent_ok")}
    a |= {k: np.concatenate([c[k] for c in columns]) for k in ("hand", "category", "seed")}
    a |= {k: np.concatenate([c[k] for c in columns]) for k in ("wrist", "q_grasp")}
    for i, name in enumerate(meta["intents"]):
        rows = a["intent"] == i
        n = int(rows.sum())
        checked = rows & (a["intent_ok"] >= 0)
        ok = int((a["intent_ok"][checked] == 1).sum())
        pose = np.concatenate(
            [
                np.stack([a["hand"], a["category"], a["seed"]], axis=1)[rows],
                np.round(a["wrist"][rows] * 1000),
                np.round(a["q_grasp"][rows] * 100),
            ],
            axis=1,
        )
        distinct = len(np.unique(pose, axis=0)) if n else 0
        share = f"{ok} ({100 * ok / checked.sum():.0f}%)" if checked.any() else "-"
        lines.append(f"| {name} | {n} | {share} | {n - int(checked.sum())} | {distinct} |")
    return lines + [""]


def _table(title: str, counts: dict[str, int]) -> list[str]:
    lines = [f"| {title} | grasps |", "|---|---:|"]
    lines += [f"| {k} | {v} |" for k, v in counts.items()]
    return lines + [""]


def _blocks_line(meta: dict[str, Any]) -> str:
    blocks = meta["blocks"]
    sizes = ", ".join(f"{name} ({b['grasps']})" for name, b in blocks.items())
    line = f"{len(blocks)} block(s), grasps kept in each: {sizes}."
    if "planned_seeds" in meta:
        first, end = meta["planned_seeds"]
        held = {seed for b in blocks.values() for seed in range(*b["seeds"])}
        done = len(held & set(range(first, end)))
        line += (
            f" Seeds {first}..{end - 1} of every category are planned; {done} of "
            f"{end - first} seeds are done."
        )
    refreshes = Counter(
        (tuple(r["categories"]), r["code"]) for b in blocks.values() for r in b.get("refreshed", [])
    )
    for (names, code), n in refreshes.items():
        line += (
            f" The rows of {', '.join(names)} were made again in {n} block(s) by code {code} "
            f"(`drograsp dataset refresh DIR --categories {' '.join(names)}`; the other "
            "categories' results were kept)."
        )
    return line


def dataset_card(root: str | Path, info: dict[str, Any], meta: dict[str, Any]) -> str:
    """The dataset card (markdown), computed from the written arrays."""
    gen = meta["generator"]
    div = diversity(root)
    lines = [
        "# Functional grasp dataset",
        "",
        f"Format `{meta['format']}`. {info['total']} validated functional grasps (held in MuJoCo with "
        "the paper preset and touching the instructed part), labelled with the instruction, "
        "the 4 anchors (object points nearest the anchor fingertips), the voted part and the "
        "validation metrics. Objects regenerate from (category, seed) with "
        "`models.objects.make_object`; load with `learned.dataset.GraspDataset(root, split)`.",
        "",
        "## Counts",
        "",
    ]
    lines += _table("split", info["splits"])
    hands_by_split = ["| hand | " + " | ".join(SPLIT_NAMES) + " | all |"]
    hands_by_split.append("|---|" + "---:|" * (len(SPLIT_NAMES) + 1))
    for hand, total in info["hands"].items():
        cells = [str(info["split_hands"][s].get(hand, 0)) for s in SPLIT_NAMES]
        hands_by_split.append(f"| {hand} | " + " | ".join(cells) + f" | {total} |")
    lines += hands_by_split + [""]
    lines += _table("category", info["categories"])
    lines += [
        "Intents: each grasp is checked against its intent's definition "
        "(`planner.intent.check_intent`, models/objects/intents.py) when it is made.",
        "",
    ]
    lines += intent_table(root)
    lines += _table("source", info["sources"])
    lines += ["## Generator success rates", ""]
    lines += [
        "A job is one planner run (a window of candidates for one object, instruction and hand) "
        "or one transfer; `holds` and `valid` count jobs whose returned grasp held / held on the "
        "instructed part; `valid grasps` counts every such grasp the jobs found.",
        "",
        "| source:hand | jobs | errors | holds | valid | valid grasps | kept (after dedup) |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for key, jobs in gen["jobs"].items():
        valid = gen["valid"].get(key, 0)
        lines.append(
            f"| {key} | {jobs} | {gen['errors'].get(key, 0)} | {gen['holds'].get(key, 0)} | "
            f"{valid} ({100 * valid / max(jobs, 1):.0f}%) | {gen['grasps'].get(key, 0)} | "
            f"{gen['kept'].get(key, 0)} |"
        )
    lines.append("")
    if gen["transfers"]:
        lines += ["Cross-hand transfers (a valid grasp of one hand seeding another):", ""]
        lines += ["| source->target | transfers | valid |", "|---|---:|---:|"]
        for pair, n in gen["transfers"].items():
            ok = gen["transfers_valid"].get(pair, 0)
            lines.append(f"| {pair} | {n} | {ok} ({100 * ok / max(n, 1):.0f}%) |")
        lines.append("")
    lines += [
        "## Diversity",
        "",
        f"Within each (object, instruction, hand) group ({div['groups']} groups, "
        f"{div['grasps_per_group']:.2f} grasps per group): mean pairwise wrist distance "
        f"{div['wrist_distance_cm']:.1f} cm, wrist rotation {div['wrist_rotation_deg']:.1f} deg, "
        f"joint RMS difference {div['joint_rms_rad']:.3f} rad.",
        "",
        f"Distinct hand poses: {div['distinct_poses']} of {info['total']} grasps (wrist to 1 mm, "
        "joints to 0.01 rad, per object and hand, whatever the instruction).",
        "",
        "## Blocks",
        "",
        _blocks_line(meta),
        "",
        "## Regenerate",
        "",
        "```bash",
        meta.get("command") or "(not recorded)",
        "```",
        "",
        "The command resumes: it skips the blocks the folder holds and the finished shards of an "
        "interrupted block (kept under its work folder).",
        "",
        "Generated by code version(s): " + (", ".join(meta.get("code") or []) or "not recorded"),
        "",
    ]
    return "\n".join(lines)
