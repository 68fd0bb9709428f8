"""Batch results -> the compact dataset (learned.dataset's format) and its dataset card.

Keeps the grasps that hold in validation and touch the instructed part, drops duplicates
(same object, instruction and hand, wrist within 1 mm and 1 degree, joints within 0.01 rad),
splits by object instance (models.objects.split_of), and writes the card from the written
arrays, so the card always matches what the loader reads.
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
    ARRAYS,
    FORMAT,
    METRICS,
    SOURCES,
    SPLIT_NAMES,
    dataset_info,
    load_split,
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


def _tables(rows: list[dict[str, Any]]) -> dict[str, list[str]]:
    hands = sorted({r["hand"] for r in rows})
    parts = sorted({r["part"] for r in rows})
    texts = sorted({r["instruction"] for r in rows})
    return {
        "hands": hands,
        "categories": list(categories()),
        "instructions": texts,
        "intents": list(INTENTS),
        "parts": parts,
        "sources": list(SOURCES),
    }


def _arrays(rows: list[dict[str, Any]], tables: dict[str, list[str]], dof: int) -> dict:
    n = len(rows)
    out = {}
    for name, (dtype, shape) in ARRAYS.items():
        shape = tuple(dof if s == "dof" else s for s in shape)
        out[name] = np.zeros((n, *shape), dtype=dtype)
    index = {key: {v: i for i, v in enumerate(vals)} for key, vals in tables.items()}
    for i, r in enumerate(rows):
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
    return out


def compact(
    result_dirs: Sequence[str | Path],
    out: str | Path,
    command: str | None = None,
    code: Sequence[str] = (),
) -> dict[str, Any]:
    """Write the dataset folder `out` from batch output folders (planned, then transfers):
    meta.json, <split>.npz for every split, card.md. Returns `dataset_info(out)`."""
    records = (r for d in result_dirs for r in read_results(d))
    rows, stats = collect(records)
    tables = _tables(rows)
    dof = max((load_hand(h).dof for h in tables["hands"]), default=1)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    by_split: dict[str, list[dict[str, Any]]] = {s: [] for s in SPLIT_NAMES}
    for row in rows:
        by_split[split_of(row["category"], row["seed"])].append(row)
    for split, split_rows in by_split.items():
        tmp = out / f".{split}.{os.getpid()}.tmp.npz"
        np.savez_compressed(tmp, **_arrays(split_rows, tables, dof))
        os.replace(tmp, out / f"{split}.npz")
    meta = {
        "format": FORMAT,
        **tables,
        "hand_dof": {h: load_hand(h).dof for h in tables["hands"]},
        "metrics": list(METRICS),
        "generator": stats.to_dict(),
        "command": command,
        "code": list(code),
    }
    write_atomic(out / "meta.json", json.dumps(meta, indent=1) + "\n")
    info = dataset_info(out)
    write_atomic(out / "card.md", dataset_card(out, info, meta))
    return info


def diversity(root: str | Path) -> dict[str, float]:
    """Spread of grasps within each (object, instruction, hand) group: grasps per group and
    mean pairwise wrist distance, wrist rotation and joint distance (groups of 2 or more)."""
    sizes, moves, turns, joints = [], [], [], []
    for split in SPLIT_NAMES:
        a = load_split(root, split).arrays
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
        "groups": len(sizes),
        "grasps_per_group": mean(sizes),
        "wrist_distance_cm": 100 * mean(moves),
        "wrist_rotation_deg": mean(turns),
        "joint_rms_rad": mean(joints),
    }


def _table(title: str, counts: dict[str, int]) -> list[str]:
    lines = [f"| {title} | grasps |", "|---|---:|"]
    lines += [f"| {k} | {v} |" for k, v in counts.items()]
    return lines + [""]


def dataset_card(root: str | Path, info: dict[str, Any], meta: dict[str, Any]) -> str:
    """The dataset card (markdown), computed from the written arrays."""
    gen = meta["generator"]
    div = diversity(root)
    lines = [
        "# Functional grasp dataset",
        "",
        f"Format `{FORMAT}`. {info['total']} validated functional grasps (held in MuJoCo with "
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
    lines += _table("intent", info["intents"])
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
        "## Regenerate",
        "",
        "```bash",
        meta.get("command") or "(not recorded)",
        "```",
        "",
        "Generated by code version(s): " + (", ".join(meta.get("code") or []) or "not recorded"),
        "",
    ]
    return "\n".join(lines)
