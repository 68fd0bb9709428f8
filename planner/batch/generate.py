"""Dataset generation end to end: jobs -> planned batch -> transfer batch -> compact + card.

Every stage is resumable (re-run the same command after a kill) and deterministic: the
intermediate jobs files and result shards live in a work folder beside the dataset.
"""

from __future__ import annotations

import json
import subprocess
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from models.hands import available_hands
from planner.batch.dataset import compact
from planner.batch.jobs import make_jobs, read_jobs, write_jobs
from planner.batch.runner import read_results, run_batch


@dataclass
class GenerateSettings:
    """What to generate and where to run it (mirrors `drograsp dataset generate`'s options)."""

    hands: Sequence[str] = field(default_factory=available_hands)
    splits: Sequence[str] = ("train", "val", "test", "heldout")
    category_names: Sequence[str] | None = None
    objects_per_category: int = 10
    start_seed: int = 0
    variants: int = 3
    max_candidates: int = 8
    protocol: str = "paper"
    validate_all: bool = True  # keep every holding candidate of a job (see PlannerSettings)
    transfer: bool = True
    transfer_per_pair: int | None = 1
    workers: int = 1
    ray: bool = False
    ray_address: str | None = None
    shard_size: int = 16
    progress: bool = True


CODE_DIRS = ("models", "learned", "planner", "eval")


def code_version() -> str:
    """The git commit of this checkout (+"-dirty" with uncommitted changes to the code
    packages), or the installed package version when not in a git checkout."""
    root = Path(__file__).resolve().parents[2]
    try:
        git = ["git", "-C", str(root)]
        commit = subprocess.run(
            [*git, "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=True
        ).stdout.strip()
        changes = subprocess.run(
            [*git, "status", "--porcelain", "--", *CODE_DIRS],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
        return commit + ("-dirty" if changes else "")
    except (OSError, subprocess.CalledProcessError):
        from importlib.metadata import PackageNotFoundError, version

        try:
            return "drograsp " + version("drograsp")
        except PackageNotFoundError:
            return "unknown"


def _record_code(work: Path) -> list[str]:
    """Every code version that has worked in `work` (a resumed run may span several)."""
    path = work / "code.json"
    versions = json.loads(path.read_text()) if path.is_file() else []
    current = code_version()
    if current not in versions:
        versions.append(current)
        path.write_text(json.dumps(versions) + "\n")
    return versions


def generate_dataset(
    out: str | Path,
    settings: GenerateSettings,
    work: str | Path | None = None,
    command: str | None = None,
) -> dict[str, Any]:
    """Generate (or resume generating) the dataset in `out`; return its `dataset_info`."""
    s = settings
    out = Path(out)
    work = Path(work) if work is not None else out / "work"
    work.mkdir(parents=True, exist_ok=True)
    if work.resolve().parent == out.resolve():
        (out / ".gitignore").write_text(f"{work.name}/\n")  # shards are not part of the dataset
    code = _record_code(work)
    jobs_file = work / "jobs.jsonl"
    jobs = make_jobs(
        hands=s.hands,
        splits=s.splits,
        category_names=s.category_names,
        objects_per_category=s.objects_per_category,
        start_seed=s.start_seed,
        variants=s.variants,
        max_candidates=s.max_candidates,
        protocol=s.protocol,
        validate_all=s.validate_all,
    )
    write_jobs(jobs, jobs_file)
    run = dict(
        workers=s.workers,
        ray=s.ray,
        ray_address=s.ray_address,
        shard_size=s.shard_size,
        progress=s.progress,
    )
    run_batch(read_jobs(jobs_file), work / "plan", **run)
    dirs = [work / "plan"]
    if s.transfer and len(s.hands) > 1:
        from planner.batch.transfer import transfer_jobs

        transfers = transfer_jobs(read_results(work / "plan"), list(s.hands), s.transfer_per_pair)
        write_jobs(transfers, work / "transfer_jobs.jsonl")
        run_batch(transfers, work / "transfer", **run)
        dirs.append(work / "transfer")
    return compact(dirs, out, command, code)
