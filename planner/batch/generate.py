"""Dataset generation end to end: jobs -> planned batch -> transfer batch -> block + card.

Generation runs block by block over object seeds (`block_seeds` seeds of every category each):
a finished block is appended to the dataset folder at once, so a generation that needs more
machine time than one session keeps every finished block (commit the folder; the same command
resumes in the next session). Within a block every stage is resumable (re-run after a kill) and
deterministic: the block's jobs files and result shards live in a work folder.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from learned.dataset import DatasetError, dataset_info, read_meta
from models.hands import available_hands
from models.objects import category
from planner.batch.dataset import add_block, check_settings, dataset_blocks
from planner.batch.jobs import Job, JobError, make_jobs, read_jobs, write_jobs
from planner.batch.runner import job_key, read_results, run_batch


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
    block_seeds: int = 1  # seeds per block: the unit of work kept across sessions
    extra_variants: int = 0  # more variants for pairs whose `variants` jobs found nothing
    progress: bool = True

    def dataset_settings(self) -> dict[str, Any]:
        """What decides a block's content: every block of one dataset must share it (the seed
        range may grow, so a dataset can be extended with more seeds later)."""
        keys = (
            "hands", "splits", "category_names", "variants", "max_candidates", "protocol",
            "validate_all", "transfer", "transfer_per_pair", "block_seeds", "extra_variants",
        )  # fmt: skip
        out = {k: getattr(self, k) for k in keys}
        return {k: list(v) if isinstance(v, list | tuple) else v for k, v in out.items()}

    def blocks(self) -> list[tuple[int, int]]:
        """Seed ranges [start, end) of the blocks, in order."""
        end = self.start_seed + self.objects_per_category
        step = max(self.block_seeds, 1)
        return [(a, min(a + step, end)) for a in range(self.start_seed, end, step)]


def topup_jobs(records: Iterable[dict[str, Any]], variants: int, extra: int) -> list[Job]:
    """More variants for every (object, instruction, hand) whose `variants` planned jobs found
    no valid grasp: hard parts (a bottle's neck, a bowl's rim) hold only at lower-ranked
    proposals, which the first windows do not reach. Variants `variants` .. `variants+extra-1`,
    in the order the pairs first appear."""
    found: dict[tuple[str, str, str], bool] = {}
    first: dict[tuple[str, str, str], Job] = {}
    for record in records:
        job = Job.from_dict(record["job"])
        key = (json.dumps(job.object, sort_keys=True), job.instruction, job.hand)
        first.setdefault(key, job)
        found[key] = found.get(key, False) or bool(record.get("valid"))
    return [
        replace(job, variant=variants + k, id="")
        for key, job in first.items()
        if not found[key]
        for k in range(extra)
    ]


def block_name(seeds: tuple[int, int]) -> str:
    a, b = seeds
    return f"seeds-{a:05d}" + (f"-{b - 1:05d}" if b - 1 > a else "")


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
    """Generate (or resume generating) the dataset in `out`, block by block; return its
    `dataset_info`. Blocks the folder already holds are skipped."""
    s = settings
    if s.block_seeds < 1:
        raise JobError(f"block seeds must be at least 1, got {s.block_seeds}")
    out = Path(out)
    work = Path(work) if work is not None else out / "work"
    work.mkdir(parents=True, exist_ok=True)
    if work.resolve().parent == out.resolve():
        (out / ".gitignore").write_text(f"{work.name}/\n")  # shards are not part of the dataset
    check_settings(out, s.dataset_settings())  # before hours of work, not after
    done = dataset_blocks(out)
    todo = [b for b in s.blocks() if block_name(b) not in done]
    for i, seeds in enumerate(todo):
        if s.progress:
            print(f"block {block_name(seeds)} ({i + 1} of {len(todo)} to do)", flush=True)
        _generate_block(out, work / block_name(seeds), s, seeds, command)
    return dataset_info(out)


STAGES = ("plan", "topup", "transfer")  # a block's result folders under its work folder


def refresh_dataset(
    out: str | Path,
    category_names: Sequence[str],
    *,
    work: str | Path | None = None,
    workers: int = 1,
    ray: bool = False,
    ray_address: str | None = None,
    progress: bool = True,
) -> dict[str, Any]:
    """Make the rows of `category_names` again in every block of `out` with this code (after a
    change to those categories' objects or planning), keeping every other category's results.

    Each block is generated again from the settings in meta.json, into a fresh work folder; the
    jobs of other categories are taken from the block's earlier work folder where it is still
    there (they would come out the same), else run again too. So a refreshed dataset is what the
    generation command gives from scratch with this code. A block is replaced only once its new
    version is complete, and blocks already refreshed this way are skipped: re-running resumes.
    Returns `dataset_info(out)`."""
    out = Path(out)
    if not (out / "meta.json").is_file():
        raise DatasetError(f"{out} holds no dataset (no meta.json) to refresh")
    names = sorted({category(c).name for c in category_names})
    if not names:
        raise DatasetError("give at least one category to refresh (--categories NAME ...)")
    meta = read_meta(out)
    if "settings" not in meta or any("seeds" not in b for b in meta["blocks"].values()):
        raise DatasetError(
            f"{out} was not made by `drograsp dataset generate` (no generation settings or seed "
            "blocks), so its blocks cannot be made again; run the generation afresh instead"
        )
    work = Path(work) if work is not None else out / "work"
    first, end = meta.get("planned_seeds") or (0, 0)
    s = GenerateSettings(
        **meta["settings"],
        objects_per_category=end - first,
        start_seed=first,
        workers=workers,
        ray=ray,
        ray_address=ray_address,
        progress=progress,
    )
    refreshed = {"categories": names, "code": code_version()}
    todo = [
        (name, block)
        for name, block in meta["blocks"].items()
        if refreshed not in block.get("refreshed", [])
    ]
    for i, (name, block) in enumerate(todo):
        if progress:
            print(
                f"refresh {', '.join(names)} in block {name} ({i + 1} of {len(todo)})", flush=True
            )
        earlier, fresh = work / name, work / f"{name}.refresh"
        _generate_block(
            out,
            fresh,
            s,
            tuple(block["seeds"]),
            meta.get("command"),
            reuse=_records_to_keep(earlier, names),
            refreshed=refreshed,
        )
        if earlier.is_dir():
            shutil.rmtree(earlier)
        fresh.rename(earlier)
    return dataset_info(out)


def _records_to_keep(work: Path, names: Sequence[str]) -> dict[str, dict[str, Any]]:
    """The records of a block's earlier work folder (every stage) for objects outside the
    categories `names`, by job_key (empty when the folder is gone)."""
    return {
        job_key(r["job"]): r
        for stage in STAGES
        for r in read_results(work / stage)
        if r["job"]["object"].get("category") not in names
    }


def _generate_block(
    out: Path,
    work: Path,
    s: GenerateSettings,
    seeds: tuple[int, int],
    command: str | None,
    reuse: Mapping[str, dict[str, Any]] | None = None,
    refreshed: dict[str, Any] | None = None,
) -> None:
    """Plan, top up, transfer and add the block of `seeds` (`refreshed`: replace the block the
    dataset holds, recording this refresh; `reuse`: records of earlier runs, see run_batch)."""
    work.mkdir(parents=True, exist_ok=True)
    code = _record_code(work)
    jobs_file = work / "jobs.jsonl"
    jobs = make_jobs(
        hands=s.hands,
        splits=s.splits,
        category_names=s.category_names,
        objects_per_category=seeds[1] - seeds[0],
        start_seed=seeds[0],
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
        reuse=reuse,
    )
    plan, topup, transfer = (work / stage for stage in STAGES)
    run_batch(read_jobs(jobs_file), plan, **run)
    dirs = [plan]
    if s.extra_variants > 0:
        extra = topup_jobs(read_results(plan), s.variants, s.extra_variants)
        write_jobs(extra, work / "topup_jobs.jsonl")
        run_batch(extra, topup, **run)
        dirs.append(topup)
    if s.transfer and len(s.hands) > 1:
        from planner.batch.transfer import transfer_jobs

        planned = (r for d in dirs for r in read_results(d))
        transfers = transfer_jobs(planned, list(s.hands), s.transfer_per_pair)
        write_jobs(transfers, work / "transfer_jobs.jsonl")
        run_batch(transfers, transfer, **run)
        dirs.append(transfer)
    add_block(
        out,
        block_name(seeds),
        dirs,
        settings=s.dataset_settings(),
        seeds=seeds,
        planned=(s.start_seed, s.start_seed + s.objects_per_category),
        command=command,
        code=code,
        refreshed=refreshed,
    )
    from planner.batch.intents import check_intents

    check_intents(out)  # every intent each new grasp meets (and any block made again)
