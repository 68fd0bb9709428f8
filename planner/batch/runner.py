"""Run a jobs list into an output folder of result shards; resumable and worker-count blind.

Layout of OUT_DIR:
    batch.json                 what the folder was made from (jobs digest, shard size)
    shards/shard-000012.jsonl  records of jobs 12*S .. 13*S-1, in job order, one JSON per line
    summary.json               counts and wall time of the last run

Shard k always holds the same jobs (by position in the jobs list), each shard is written once,
complete, through a temporary file and os.replace, so a killed run leaves only whole shards and
re-running the same command runs exactly the jobs of the missing shards.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import os
import time
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from models.paths import output_folder
from planner.batch.executors import JobFn, run_pool, run_ray, run_serial
from planner.batch.jobs import Job, JobError, check_unique

FORMAT = 1
SHARD_SIZE = 16


@dataclass
class BatchSummary:
    """Counts over the whole jobs list (finished shards of earlier runs included)."""

    jobs: int
    skipped: int  # finished in an earlier run (or reused from one)
    ran: int
    errors: int
    success: int  # the returned grasp holds in validation
    valid: int  # holds and touches the instructed part: what a dataset keeps
    wall_time: float  # s, this run
    backend: str
    workers: int
    ran_valid: int = 0  # valid among the jobs run now

    @property
    def valid_per_hour(self) -> float:
        """Validated grasps per hour of this run (jobs of earlier runs not counted)."""
        return 0.0 if self.wall_time <= 0 else 3600.0 * self.ran_valid / self.wall_time

    def to_dict(self) -> dict[str, Any]:
        return asdict(self) | {"valid_per_hour": self.valid_per_hour}


def jobs_digest(jobs: Sequence[Job]) -> str:
    h = hashlib.sha256()
    for job in jobs:
        h.update(json.dumps(job.to_dict(), sort_keys=True).encode())
        h.update(b"\n")
    return h.hexdigest()


def job_key(job: Job | dict[str, Any]) -> str:
    """What identifies a job's work (its full description, id included), for `reuse`."""
    data = job.to_dict() if isinstance(job, Job) else job
    return json.dumps(data, sort_keys=True)


def shard_path(out_dir: Path, shard: int) -> Path:
    return out_dir / "shards" / f"shard-{shard:06d}.jsonl"


def write_atomic(path: Path, text: str) -> None:
    """Write `text` to a temporary file beside `path`, flush it to disk, then rename."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    with open(tmp, "w") as f:
        f.write(text)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def _check_folder(out_dir: Path, jobs: Sequence[Job], shard_size: int) -> None:
    meta = {
        "format": FORMAT,
        "jobs": len(jobs),
        "digest": jobs_digest(jobs),
        "shard_size": shard_size,
    }
    path = out_dir / "batch.json"
    if path.exists():
        old = _read_json(path, "the batch's description (jobs digest, shard size)")
        if old != meta:
            raise JobError(
                f"{out_dir} holds results of a different batch ({old.get('jobs')} jobs, shard "
                f"size {old.get('shard_size')}); give a new output folder or the same jobs file "
                "and shard size"
            )
        return
    output_folder(out_dir / "shards", "batch output folder", JobError)
    write_atomic(path, json.dumps(meta, indent=1) + "\n")


def _read_json(path: Path, what: str) -> dict[str, Any]:
    """A JSON object file of the batch folder, or a JobError naming it and how to recover."""
    try:
        data = json.loads(path.read_bytes().decode("utf-8"))
    except (ValueError, OSError) as err:
        data, reason = None, f"{type(err).__name__}: {err}"
    else:
        reason = "not a JSON object"
    if not isinstance(data, dict):
        raise JobError(
            f"{path} is damaged ({reason}); it holds {what}: delete it and re-run the same "
            "command (finished shards of the same jobs are kept)"
        )
    return data


def read_shard(path: Path) -> list[dict[str, Any]]:
    """The records of one shard, or a JobError naming it (a shard truncated by a full disk or
    edited by hand) with how to recover."""
    try:
        lines = path.read_bytes().decode("utf-8").splitlines()
        records = [json.loads(line) for line in lines if line.strip()]
    except (ValueError, OSError) as err:
        raise JobError(
            f"{path} is damaged ({type(err).__name__}: {err}); delete it and re-run the same "
            "`drograsp batch` command: only its jobs run again"
        ) from None
    if not all(isinstance(r, dict) and "id" in r for r in records):
        raise JobError(
            f"{path} is damaged (a line is not a job record); delete it and re-run the same "
            "`drograsp batch` command: only its jobs run again"
        )
    return records


def _finished_shards(out_dir: Path, jobs: Sequence[Job], shard_size: int) -> set[int]:
    done = set()
    for shard in range(0, (len(jobs) + shard_size - 1) // shard_size):
        path = shard_path(out_dir, shard)
        if not path.exists():
            continue
        expected = [j.id for j in jobs[shard * shard_size : (shard + 1) * shard_size]]
        if [r["id"] for r in read_shard(path)] != expected:
            raise JobError(f"{path} does not hold the jobs it should; delete it and re-run")
        done.add(shard)
    for stale in (out_dir / "shards").glob(".*.tmp"):  # left by a killed run
        stale.unlink(missing_ok=True)
    return done


def run_batch(
    jobs: Sequence[Job],
    out_dir: str | Path,
    *,
    workers: int = 1,
    ray: bool = False,
    ray_address: str | None = None,
    shard_size: int = SHARD_SIZE,
    job_fn: JobFn | None = None,
    progress: bool = True,
    reuse: Mapping[str, dict[str, Any]] | None = None,
) -> BatchSummary:
    """Solve every job not yet in a finished shard of `out_dir`; return the batch's counts.

    `job_fn(job) -> dict` replaces the planner (default `planner.batch.solve.solve_job`); it
    must be a module-level function so that workers can import it. `ray` starts a local Ray
    instance with `workers` CPUs; `ray_address` joins a running cluster instead. `reuse` maps
    `job_key(job)` to a record made earlier for that very job (another folder's run of the same
    code): such a job is not run again and its record is written as it is."""
    if job_fn is None:
        from planner.batch.solve import solve_job

        job_fn = solve_job
    for what, value in (("workers", workers), ("shard size", shard_size)):
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise JobError(f"{what} must be a whole number of at least 1, got {value!r}")
    check_unique(jobs)
    out = Path(out_dir)
    _check_folder(out, jobs, shard_size)
    done = _finished_shards(out, jobs, shard_size)
    todo = [(i, j) for i, j in enumerate(jobs) if i // shard_size not in done]
    earlier = ((i, reuse.get(job_key(j))) for i, j in todo) if reuse else ()
    reused = [(i, r) for i, r in earlier if r is not None and r.get("error") is None]
    taken = {i for i, _ in reused}
    to_run = [(i, j) for i, j in todo if i not in taken]
    backend = "ray" if (ray or ray_address) else ("pool" if workers > 1 else "serial")
    start = time.perf_counter()
    ran_valid = 0
    bar = _progress(len(jobs), len(jobs) - len(todo), progress)
    try:
        stream: Iterator[tuple[int, dict]]
        if not to_run:
            stream = iter(())
        elif backend == "ray":
            stream = run_ray(job_fn, to_run, workers, ray_address)
        elif backend == "pool":
            stream = run_pool(job_fn, to_run, min(workers, max(len(to_run), 1)))
        else:
            stream = run_serial(job_fn, to_run)
        stream = itertools.chain(iter(reused), stream)
        buffers: dict[int, dict[int, dict]] = {}
        for index, record in stream:
            shard = index // shard_size
            buffers.setdefault(shard, {})[index] = record
            ran_valid += index not in taken and bool(record.get("valid"))
            expected = min(shard_size, len(jobs) - shard * shard_size)
            if len(buffers[shard]) == expected:
                records = buffers.pop(shard)
                lines = [json.dumps(records[i], sort_keys=True) for i in sorted(records)]
                write_atomic(shard_path(out, shard), "".join(f"{line}\n" for line in lines))
            if bar is not None:
                bar.update(1)
                bar.set_postfix(valid=ran_valid, refresh=False)
    finally:
        if bar is not None:
            bar.close()
    ran = len(to_run)
    summary = _summarize(out, len(jobs), len(jobs) - ran, ran, backend, workers)
    summary.wall_time = time.perf_counter() - start
    summary.ran_valid = ran_valid
    write_atomic(out / "summary.json", json.dumps(summary.to_dict(), indent=1) + "\n")
    return summary


def _progress(total: int, initial: int, enabled: bool):
    if not enabled:
        return None
    from tqdm import tqdm

    return tqdm(total=total, initial=initial, unit="job", desc="batch", smoothing=0.05)


def read_results(out_dir: str | Path) -> Iterator[dict[str, Any]]:
    """Every record of the finished shards, in job order (none where the folder is absent)."""
    for path in sorted((Path(out_dir) / "shards").glob("shard-*.jsonl")):
        yield from read_shard(path)


def check_results_folder(out_dir: str | Path) -> Path:
    """A folder written by `run_batch`, or a JobError saying what it is instead."""
    folder = Path(out_dir)
    if not (folder / "shards").is_dir():
        raise JobError(
            f"{out_dir} holds no batch results (no shards folder); give the OUT_DIR of a "
            "`drograsp batch` run"
        )
    return folder


def _summarize(
    out: Path, total: int, skipped: int, ran: int, backend: str, workers: int
) -> BatchSummary:
    errors = success = valid = 0
    for record in read_results(out):
        errors += record.get("error") is not None
        success += bool(record.get("success"))
        valid += bool(record.get("valid"))
    return BatchSummary(total, skipped, ran, errors, success, valid, 0.0, backend, workers)
