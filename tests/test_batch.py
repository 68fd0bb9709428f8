"""Batch solving: jobs files, shards, resumption after a kill, errors, worker-count blindness,
Ray, real planner and transfer jobs, and the CLI."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from models.errors import DrograspError
from planner import cli
from planner.batch import Job, JobError, make_jobs, read_jobs, read_results, run_batch, write_jobs
from planner.batch.runner import job_key, shard_path
from tests.batch_fakes import fake_jobs, fake_solve

REPO = Path(__file__).resolve().parents[1]


def comparable(out_dir: Path) -> list[dict]:
    """Records without their measured timings."""
    return [{k: v for k, v in r.items() if k != "times"} for r in read_results(out_dir)]


# ---------------------------------------------------------------------- jobs
def test_make_jobs_counts_order_and_roundtrip(tmp_path):
    jobs = make_jobs(
        hands=["allegro", "leap"], category_names=["mug", "knife"], objects_per_category=3
    )
    from models.objects import instructions, split_of

    expected = sum(
        len(instructions(c)) * 2 * 2
        for c in ("mug", "knife")
        for s in range(3)
        if split_of(c, s) in ("train", "val", "test")
    )
    assert len(jobs) == expected
    assert len({j.id for j in jobs}) == len(jobs)
    assert jobs[0].id == "allegro/mug_00000/Use-a-mug-by-handle/v0"
    assert jobs[1].variant == 1 and jobs[1].object == jobs[0].object
    path = write_jobs(jobs, tmp_path / "jobs.jsonl")
    assert read_jobs(path) == jobs
    # held-out categories appear only when asked for
    assert not make_jobs(hands=["leap"], category_names=["teapot"], objects_per_category=2)
    held = make_jobs(
        hands=["leap"], splits=["heldout"], category_names=["teapot"], objects_per_category=2
    )
    assert {j.object["seed"] for j in held} == {0, 1}


def test_jobs_file_errors(tmp_path):
    path = tmp_path / "bad.jsonl"
    path.write_text(
        '{"object": {"category": "mug", "seed": 0}, "instruction": "x", "hand": "leap", "colour": 1}\n'
    )
    with pytest.raises(JobError, match="unknown job fields"):
        read_jobs(path)
    job = Job({"category": "mug", "seed": 0}, "Use a mug by handle", "leap")
    with pytest.raises(JobError, match="duplicate"):
        write_jobs([job, job], tmp_path / "dup.jsonl")
    with pytest.raises(JobError, match="no such jobs file"):
        read_jobs(tmp_path / "missing.jsonl")


# ---------------------------------------------------------------------- runner
def test_error_is_recorded_and_the_rest_complete(tmp_path):
    jobs = fake_jobs(6, {2: "Use a mug by raise"})
    summary = run_batch(jobs, tmp_path, shard_size=4, job_fn=fake_solve, progress=False)
    records = list(read_results(tmp_path))
    assert [r["id"] for r in records] == [j.id for j in jobs]
    assert records[2]["error"]["type"] == "ValueError"
    assert "cannot solve" in records[2]["error"]["message"]
    assert records[2]["success"] is False and records[2]["valid"] is False
    assert all(r["error"] is None for i, r in enumerate(records) if i != 2)
    assert summary.errors == 1 and summary.ran == 6
    assert json.loads((tmp_path / "summary.json").read_text())["errors"] == 1


def test_results_do_not_depend_on_worker_count(tmp_path):
    jobs = fake_jobs(10, {7: "Use a mug by raise"})
    run_batch(jobs, tmp_path / "one", shard_size=3, job_fn=fake_solve, progress=False)
    run_batch(jobs, tmp_path / "two", workers=2, shard_size=3, job_fn=fake_solve, progress=False)
    assert comparable(tmp_path / "one") == comparable(tmp_path / "two")
    assert len(list((tmp_path / "two" / "shards").glob("shard-*.jsonl"))) == 4


def test_reused_records_are_not_run_again_but_errors_are(tmp_path):
    jobs = fake_jobs(8, {5: "Use a mug by raise"})
    run_batch(jobs, tmp_path / "first", shard_size=3, job_fn=fake_solve, progress=False)
    earlier = {job_key(r["job"]): r for r in read_results(tmp_path / "first")}
    assert job_key(jobs[0]) in earlier
    del earlier[job_key(jobs[1])]
    summary = run_batch(
        jobs, tmp_path / "again", shard_size=3, job_fn=fake_solve, progress=False, reuse=earlier
    )
    assert summary.ran == 2 and summary.skipped == 6  # job 1 (not given) and job 5 (an error)
    first, again = list(read_results(tmp_path / "first")), list(read_results(tmp_path / "again"))
    taken = [i for i in range(8) if again[i] == first[i]]  # timings too: the very record
    assert taken == [0, 2, 3, 4, 6, 7]
    assert comparable(tmp_path / "again") == comparable(tmp_path / "first")


def test_worker_crash_is_recorded_and_the_rest_complete(tmp_path):
    jobs = fake_jobs(6, {1: "Use a mug by crash"})
    summary = run_batch(jobs, tmp_path, workers=2, shard_size=2, job_fn=fake_solve, progress=False)
    records = list(read_results(tmp_path))
    assert [r["id"] for r in records] == [j.id for j in jobs]
    assert records[1]["error"]["type"] == "WorkerCrashed"
    assert summary.errors == 1


def test_rerun_skips_finished_and_refuses_other_jobs(tmp_path):
    jobs = fake_jobs(5)
    run_batch(jobs, tmp_path, shard_size=2, job_fn=fake_solve, progress=False)
    before = shard_path(tmp_path, 1).read_text()
    shard_path(tmp_path, 2).unlink()
    summary = run_batch(jobs, tmp_path, shard_size=2, job_fn=fake_solve, progress=False)
    assert (summary.skipped, summary.ran) == (4, 1)
    assert shard_path(tmp_path, 1).read_text() == before
    with pytest.raises(JobError, match="different batch"):
        run_batch(fake_jobs(6), tmp_path, shard_size=2, job_fn=fake_solve, progress=False)
    with pytest.raises(JobError, match="different batch"):
        run_batch(jobs, tmp_path, shard_size=3, job_fn=fake_solve, progress=False)


def test_killed_run_restarts_without_loss_or_duplicates(tmp_path):
    jobs_file = write_jobs(fake_jobs(24, {5: "Use a mug by raise"}), tmp_path / "jobs.jsonl")
    out = tmp_path / "out"
    code = "import sys; from planner import cli; sys.exit(cli.main(sys.argv[1:]))"
    argv = [sys.executable, "-c", code, "batch", str(jobs_file), str(out), "--workers", "2"]
    argv += ["--shard-size", "2", "--job-fn", "tests.batch_fakes:fake_solve", "--no-progress"]
    env = dict(os.environ, BATCH_FAKE_SLEEP="0.25", PYTHONPATH=str(REPO))
    proc = subprocess.Popen(argv, cwd=REPO, env=env, start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while len(list(out.glob("shards/shard-*.jsonl"))) < 3:
            assert proc.poll() is None, "the batch ended before it could be killed"
            assert time.monotonic() < deadline, "no shard appeared within 120 s"
            time.sleep(0.05)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    finished = {p.name: p.read_text() for p in out.glob("shards/shard-*.jsonl")}
    assert 3 <= len(finished) < 12, "the kill should land midway"
    env["BATCH_FAKE_SLEEP"] = "0"
    result = subprocess.run(argv + ["--json"], cwd=REPO, env=env, capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["skipped"] == 2 * len(finished) and summary["jobs"] == 24
    for name, text in finished.items():  # finished shards are kept as they were
        assert (out / "shards" / name).read_text() == text
    ids = [r["id"] for r in read_results(out)]
    assert ids == [j.id for j in read_jobs(jobs_file)]  # every job exactly once, in order
    assert not list(out.glob("shards/.*.tmp"))
    assert summary["errors"] == 1


@pytest.mark.slow  # starting a local Ray cluster takes most of a minute here
def test_local_ray_gives_the_pool_results(tmp_path):
    import ray

    jobs = fake_jobs(8, {3: "Use a mug by raise"})
    run_batch(jobs, tmp_path / "pool", workers=2, shard_size=3, job_fn=fake_solve, progress=False)
    summary = run_batch(
        jobs, tmp_path / "ray", workers=2, ray=True, shard_size=3, job_fn=fake_solve, progress=False
    )
    assert summary.backend == "ray" and summary.errors == 1
    assert comparable(tmp_path / "ray") == comparable(tmp_path / "pool")
    assert not ray.is_initialized()  # the instance it started is shut down


@pytest.mark.slow
def test_real_jobs_on_ray_match_serial(tmp_path):
    jobs = [
        Job({"category": "mug", "seed": 0}, "Hold a mug by body", "allegro", v, max_candidates=1)
        for v in (0, 1)
    ]
    run_batch(jobs, tmp_path / "serial", progress=False)
    run_batch(jobs, tmp_path / "ray", workers=2, ray=True, progress=False)
    records = comparable(tmp_path / "ray")
    assert records == comparable(tmp_path / "serial")
    assert all(r["error"] is None for r in records)


# ---------------------------------------------------------------------- real planner jobs
def test_variants_rotate_the_ranked_proposals():
    from models.objects import make_object
    from planner.batch.variants import VariantPlanner
    from planner.functional import PlannerSettings
    from planner.settings import ScheduleSettings

    obj = make_object("mug", 0)
    base = VariantPlanner("allegro", PlannerSettings(schedule=ScheduleSettings(max_candidates=100)))
    ranked = base.propose(obj, "body")
    shifted = VariantPlanner(
        "allegro", PlannerSettings(schedule=ScheduleSettings(max_candidates=3)), variant=2
    )
    got = shifted.propose(obj, "body")
    assert len(got) == 3  # the third window of 3: ranked proposals 6, 7, 8
    for p, q in zip(got, ranked[6:9], strict=True):
        assert (p.wrist == q.wrist).all() and (p.anchors == q.anchors).all()
    assert shifted.proposal_index(0) == 6
    wrapped = VariantPlanner(
        "allegro",
        PlannerSettings(schedule=ScheduleSettings(max_candidates=1)),
        variant=len(ranked) - 1,
    )
    assert (wrapped.propose(obj, "body")[0].wrist == ranked[-1].wrist).all()
    wrapped = VariantPlanner(
        "allegro",
        PlannerSettings(schedule=ScheduleSettings(max_candidates=2)),
        variant=len(ranked) // 2,
    )
    wrapped.propose(obj, "body")
    assert wrapped.proposal_index(1) == 1  # window wrapped to the start


def test_real_planner_and_transfer_jobs(tmp_path):
    from models.grasp import Grasp
    from planner.batch.transfer import transfer_jobs

    jobs = [
        # up to the planner's usual 8 validations: which proposal holds first varies with the
        # machine (models.reproducible), that one does not
        Job({"category": "mug", "seed": 0}, "Hold a mug by body", "allegro", 0, max_candidates=8),
        Job({"category": "mug", "seed": 0}, "Hold a mug by spout", "allegro", 0, max_candidates=1),
    ]
    run_batch(jobs, tmp_path / "plan", progress=False)
    good, bad = read_results(tmp_path / "plan")
    assert good["error"] is None and good["valid"], good
    assert good["part_voted"] == good["part_instructed"] == "body"
    assert good["validation"]["success"] and "wall_time" not in good["validation"]
    grasp = Grasp.from_dict(good["grasp"])
    assert grasp.hand == "allegro" and grasp.anchors.shape == (4, 3)
    assert good["proposal"] >= 0 and good["times"]["job"] > 0
    assert bad["error"]["type"] == "InstructionError"  # a mug has no spout

    tjobs = transfer_jobs(read_results(tmp_path / "plan"), ["allegro", "shadow"])
    assert [j.hand for j in tjobs] == ["shadow"]
    assert tjobs[0].source["id"] == good["id"]
    run_batch(tjobs, tmp_path / "transfer", progress=False)
    (moved,) = read_results(tmp_path / "transfer")
    assert moved["error"] is None and moved["part_instructed"] == "body"
    if moved["grasp"] is not None:
        assert Grasp.from_dict(moved["grasp"]).hand == "shadow"


def test_transfer_sources_are_every_holding_grasp_up_to_per_pair():
    from planner.batch.transfer import transfer_jobs
    from tests.batch_fakes import fake_grasp_solve

    job = Job({"category": "mug", "seed": 0}, "Hold a mug by body", "allegro", validate_all=True)
    record = fake_grasp_solve(job)
    others = [fake_grasp_solve(Job(job.object, job.instruction, "allegro", v)) for v in (1, 4)]
    holding = [{"grasp": g["grasp"]} for g in [record, *others]]
    record = {**record, "id": job.id, "job": job.to_dict(), "valid": True, "holding": holding}
    every = transfer_jobs([record], ["allegro", "leap", "shadow"])
    assert len(every) == 3 * 2 and len({j.id for j in every}) == 6
    assert [j.source["grasp"] for j in every[::2]] == [h["grasp"] for h in holding]
    assert every[0].source["id"] == job.id and every[2].source["id"] == f"{job.id}/h1"
    assert len(transfer_jobs([record], ["allegro", "shadow"], per_pair=2)) == 2


def test_hand_size_is_read_from_geometry():
    from models.hands import load_hand
    from planner.batch.transfer import hand_size, scale_between

    sizes = {h: hand_size(str(load_hand(h).folder)) for h in ("allegro", "leap", "shadow")}
    assert all(0.05 < s < 0.4 for s in sizes.values())
    assert scale_between(load_hand("leap"), load_hand("leap")) == 1.0


# ---------------------------------------------------------------------- CLI
def test_cli_jobs_make_and_batch(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("BATCH_FAKE_SLEEP", "0")
    jobs_file = tmp_path / "jobs.jsonl"
    argv = ["jobs", "make", str(jobs_file), "--categories", "mug", "--hands", "leap"]
    assert cli.main(argv + ["--objects-per-category", "2", "--variants", "1"]) == 0
    jobs = read_jobs(jobs_file)
    assert len(jobs) == 2 * 5 and {j.hand for j in jobs} == {"leap"}
    argv = ["batch", str(jobs_file), str(tmp_path / "out"), "--no-progress", "--json"]
    assert cli.main(argv + ["--job-fn", "tests.batch_fakes:fake_solve"]) == 0
    assert cli.main(argv + ["--job-fn", "tests.batch_fakes:nothing"]) == 2
    out = capsys.readouterr()
    assert json.loads(out.out[out.out.index("{") :])["jobs"] == 10
    assert "cannot load job function" in out.err


def _processes_with(marker: str) -> list[int]:
    """Pids of live processes whose environment holds `marker` (this test's batch and the
    workers it started)."""
    pids = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            if marker.encode() in (entry / "environ").read_bytes():
                stat = (entry / "stat").read_text()
                if stat.rsplit(")", 1)[1].split()[0] != "Z":  # zombies are gone already
                    pids.append(int(entry.name))
        except OSError:
            continue
    return pids


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads /proc")
def test_killing_the_batch_ends_its_workers(tmp_path):
    """kill -9 of `drograsp batch` alone (not its process group): its pool workers end too,
    instead of running on (about 385 MB each with the planner)."""
    jobs_file = write_jobs(fake_jobs(8), tmp_path / "jobs.jsonl")
    marker = f"DROGRASP_TEST_MARKER={os.getpid()}_{time.monotonic_ns()}"
    code = "import sys; from planner import cli; sys.exit(cli.main(sys.argv[1:]))"
    argv = [sys.executable, "-c", code, "batch", str(jobs_file), str(tmp_path / "out")]
    argv += ["--workers", "2", "--job-fn", "tests.batch_fakes:fake_solve", "--no-progress"]
    key, value = marker.split("=")
    env = dict(os.environ, BATCH_FAKE_SLEEP="60", PYTHONPATH=str(REPO), **{key: value})
    proc = subprocess.Popen(argv, cwd=REPO, env=env)
    try:
        deadline = time.monotonic() + 120
        while len(_processes_with(marker)) < 4:  # the batch, the forkserver, two workers
            assert proc.poll() is None, "the batch ended early"
            assert time.monotonic() < deadline, "the workers did not start within 120 s"
            time.sleep(0.2)
        time.sleep(0.5)  # the workers are in their jobs
    finally:
        proc.kill()
        proc.wait()
    deadline = time.monotonic() + 15
    while _processes_with(marker) and time.monotonic() < deadline:
        time.sleep(0.2)
    left = _processes_with(marker)
    for pid in left:  # do not leave them behind if the test fails
        os.kill(pid, signal.SIGKILL)
    assert not left, f"{len(left)} worker processes outlived the killed batch"


@pytest.mark.parametrize("damage", ["shard", "batch.json", "utf8"])
def test_a_damaged_batch_file_is_named_with_how_to_recover(tmp_path, damage):
    jobs = fake_jobs(4)
    run_batch(jobs, tmp_path, shard_size=2, job_fn=fake_solve, progress=False)
    if damage == "shard":
        path = shard_path(tmp_path, 0)
        path.write_text(path.read_text()[:-30])  # cut mid-line, as by a full disk
    elif damage == "utf8":
        path = shard_path(tmp_path, 1)
        path.write_bytes(b"\xff\xfe garbage\n")
    else:
        path = tmp_path / "batch.json"
        path.write_text(path.read_text()[:10])
    with pytest.raises(JobError, match=f"{path.name} is damaged.*delete it and re-run"):
        run_batch(jobs, tmp_path, shard_size=2, job_fn=fake_solve, progress=False)
    path.unlink()  # what the message says: delete it and re-run
    summary = run_batch(jobs, tmp_path, shard_size=2, job_fn=fake_solve, progress=False)
    assert summary.jobs == 4 and [r["id"] for r in read_results(tmp_path)] == [j.id for j in jobs]


def test_jobs_are_checked_field_by_field(tmp_path):
    base = {"object": {"category": "mug", "seed": 0}, "instruction": "Use a mug by handle"}
    base["hand"] = "allegro"
    for change in (
        {"variant": "x"},
        {"variant": True},
        {"max_candidates": 1.5},
        {"hand": 5},
        {"object": {"category": "mug", "seed": "a"}},
        {"object": {"category": "mug", "seed": 1.5}},
    ):
        with pytest.raises(JobError):
            Job.from_dict(base | change)
    path = tmp_path / "bad.jsonl"
    path.write_bytes(b"\xff\xfe{}\n")
    with pytest.raises(JobError, match="not UTF-8"):
        read_jobs(path)
    path.write_text(json.dumps(base) + "\n" + json.dumps(base | {"variant": -1}) + "\n")
    with pytest.raises(JobError, match=r"bad.jsonl:2: job variant"):
        read_jobs(path)
    with pytest.raises(DrograspError, match="unknown hand 'unicorn'"):
        make_jobs(hands=["unicorn"], objects_per_category=1)
