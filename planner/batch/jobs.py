"""Batch jobs: one (object, instruction, hand, variant) to solve, and the JSONL jobs file.

A job carries everything its result depends on (object reference, instruction text, hand,
variant index, planner caps, validation preset, and for a cross-hand transfer the source
grasp), so a jobs file fully determines a batch: any machine, any number of workers, same
results. Ids are readable and unique; the runner keys resumption on them.
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from models.errors import DrograspError
from models.hand_names import builtin_hands, check_hand_name
from models.objects.names import SPLITS


class JobError(DrograspError, ValueError):
    """A malformed jobs file or job (unknown field, duplicate id, bad object reference)."""


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9]+", "-", text).strip("-")


def object_name(ref: dict[str, Any]) -> str:
    """A short name for an object reference: `mug_00003`, a mesh file's stem, or the name of
    an object given inline."""
    if "category" in ref:
        seed = ref.get("seed", 0)
        if (
            not isinstance(ref["category"], str)
            or isinstance(seed, bool)
            or not isinstance(seed, int)
            or seed < 0
        ):
            raise JobError(
                f"object reference {ref}: category must be a name and seed a non-negative integer"
            )
        return f"{ref['category']}_{seed:05d}"
    if "path" in ref:
        if not isinstance(ref["path"], str) or not ref["path"]:
            raise JobError(f"object reference {ref}: path must be a file name")
        return Path(ref["path"]).stem
    if "name" in ref and isinstance(ref["name"], str) and ("cloud" in ref or "vertices" in ref):
        return _slug(ref["name"]) or "object"
    raise JobError(f"object reference {ref} has neither category+seed, path nor inline geometry")


@dataclass(frozen=True)
class Job:
    """What to solve. `variant` k makes the planner start at its k-th ranked proposal, so
    variants of one (object, instruction, hand) give different wrist poses. With `source`
    (a Grasp.to_dict() of another hand, validated) the job is a cross-hand transfer instead."""

    object: dict[str, Any]  # planner.objectref.object_ref: {"category", "seed"} or {"path", ...}
    instruction: str
    hand: str
    variant: int = 0
    max_candidates: int = 8
    protocol: str = "paper"
    source: dict[str, Any] | None = None
    validate_all: bool = False  # keep every holding candidate, not just the first (datasets)
    id: str = field(default="")

    def __post_init__(self) -> None:
        if not isinstance(self.object, dict):
            raise JobError(f"job object must be a dict reference, got {self.object!r}")
        object_name(self.object)
        for name in ("instruction", "hand", "protocol"):
            value = getattr(self, name)
            if not isinstance(value, str) or not value.strip():
                raise JobError(f"job {name} must be a non-empty string, got {value!r}")
        for name, low in (("variant", 0), ("max_candidates", 1)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                raise JobError(f"job {name} must be a whole number >= {low}, got {value!r}")
        if not isinstance(self.validate_all, bool):
            raise JobError(f"job validate_all must be true or false, got {self.validate_all!r}")
        if not isinstance(self.id, str):
            raise JobError(f"job id must be a string, got {self.id!r}")
        if self.source is not None and (
            not isinstance(self.source, dict) or not {"id", "hand", "grasp"} <= set(self.source)
        ):
            raise JobError("a transfer job's source needs id, hand and grasp")
        if not self.id:
            object.__setattr__(self, "id", self.default_id())

    @property
    def kind(self) -> str:
        return "plan" if self.source is None else "transfer"

    def default_id(self) -> str:
        base = f"{self.hand}/{object_name(self.object)}/{_slug(self.instruction)}"
        if self.source is None:
            return f"{base}/v{self.variant}"
        return f"{base}/from:{self.source['id']}"

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        if d["source"] is None:
            d.pop("source")
        if not d["validate_all"]:
            d.pop("validate_all")  # jobs files written before the field existed stay the same
        return d

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Job:
        known = set(cls.__dataclass_fields__)
        unknown = set(data) - known
        if unknown:
            raise JobError(f"unknown job fields {sorted(unknown)}; known: {sorted(known)}")
        try:
            return cls(**data)
        except TypeError as err:
            raise JobError(f"bad job {data}: {err}") from None


def write_jobs(jobs: Iterable[Job], path: str | Path) -> Path:
    """Write one JSON object per line (keys sorted, so the file is byte-stable)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    lines = [json.dumps(job.to_dict(), sort_keys=True) for job in jobs]
    check_unique(Job.from_dict(json.loads(line)) for line in lines)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text("".join(line + "\n" for line in lines))
    tmp.replace(path)
    return path


def read_jobs(path: str | Path) -> list[Job]:
    """Read a JSONL jobs file; blank lines and lines starting with # are skipped."""
    from models.paths import input_file

    if isinstance(path, str | Path) and not Path(path).expanduser().exists():
        raise JobError(f"{path}: no such jobs file (make one with `drograsp jobs make`)")
    path = input_file(path, "jobs file", JobError)
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as err:
        raise JobError(
            f"{path} is not UTF-8 text (byte {err.start}); a jobs file is JSON lines: make it "
            "again with `drograsp jobs make`"
        ) from None
    jobs = []
    for n, line in enumerate(text.splitlines(), 1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        try:
            data = json.loads(line)
        except json.JSONDecodeError as err:
            raise JobError(f"{path}:{n}: not JSON ({err})") from None
        if not isinstance(data, dict):
            raise JobError(f"{path}:{n}: a job must be a JSON object")
        try:
            jobs.append(Job.from_dict(data))
        except JobError as err:
            raise JobError(f"{path}:{n}: {err}") from None
    check_unique(jobs)
    return jobs


def check_unique(jobs: Iterable[Job]) -> None:
    seen: set[str] = set()
    for job in jobs:
        if job.id in seen:
            raise JobError(f"duplicate job id {job.id!r}: give distinct variants or ids")
        seen.add(job.id)


def make_jobs(
    *,
    hands: Sequence[str] | None = None,
    splits: Sequence[str] = ("train", "val", "test"),
    category_names: Sequence[str] | None = None,
    objects_per_category: int = 10,
    start_seed: int = 0,
    variants: int = 2,
    max_candidates: int = 8,
    protocol: str = "paper",
    validate_all: bool = False,
) -> list[Job]:
    """Jobs from the object library and instruction table.

    Seeds start_seed .. start_seed + objects_per_category - 1 of every category, kept where their
    split is in `splits` (held-out categories only with "heldout"); every instruction of the
    category; every hand; `variants` varied wrist poses each. Ordered by seed, then category,
    hand, instruction and variant: a worker reuses the (hand, object) program it just built, and
    a batch stopped part-way has covered every category alike.
    """
    from models.objects import categories, category, instructions, seeds

    for what, value in (("hands", hands), ("splits", splits), ("category_names", category_names)):
        if isinstance(value, str):
            raise JobError(f"{what} must be a list of names such as [{value!r}], not a string")
    hands = [check_hand_name(h) for h in (hands or builtin_hands())]
    unknown = set(splits) - set(SPLITS)
    if unknown:
        raise JobError(f"unknown splits {sorted(unknown)}; choose from {SPLITS}")
    names = [category(c).name for c in (category_names or categories())]
    for what, value, low in (
        ("variants", variants, 1),
        ("objects_per_category", objects_per_category, 1),
        ("start_seed", start_seed, 0),
        ("max_candidates", max_candidates, 1),
    ):
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            raise JobError(f"{what} must be a whole number >= {low}, got {value!r}")
    objects = []
    for name in names:
        chosen = set()
        for split in splits:
            chosen.update(seeds(name, split, objects_per_category, start_seed))
        objects += [(s, name) for s in chosen if s < start_seed + objects_per_category]
    order = {name: i for i, name in enumerate(names)}
    jobs = []
    for seed, name in sorted(objects, key=lambda o: (o[0], order[o[1]])):
        ref = {"category": name, "seed": seed}
        for hand in hands:
            for instr in instructions(name):
                for k in range(variants):
                    jobs.append(
                        Job(
                            ref,
                            instr.text,
                            hand,
                            k,
                            max_candidates,
                            protocol,
                            validate_all=validate_all,
                        )
                    )
    return jobs
