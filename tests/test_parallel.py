"""A plan's solves shared over forked processes (planner.parallel): the same results."""

from __future__ import annotations

import os

import numpy as np
import pytest

import planner.parallel as parallel
from models.errors import PlanningError
from models.objects import make_object
from planner.functional import FunctionalPlanner
from planner.parallel import forked_map, processes
from planner.settings import LearnedSettings, PlannerSettings, ScheduleSettings

pytestmark = pytest.mark.skipif(not hasattr(os, "fork"), reason="needs os.fork")


def _square_with_pid(x: int) -> tuple[int, int]:
    return x * x, os.getpid()


def test_forked_map_gives_the_serial_results_in_order_and_really_forks():
    answer = forked_map(_square_with_pid, range(7), 3)
    assert [a for a, _ in answer] == [x * x for x in range(7)]
    pids = {pid for _, pid in answer}
    assert os.getpid() in pids and len(pids) == 3  # items 0, 3, 6 here; the rest in children
    assert forked_map(_square_with_pid, [2], 4) == [(4, os.getpid())]  # one item: no fork


def test_an_error_in_a_child_is_raised_here_as_serial_solving_would():
    def fail_on_three(x: int) -> int:
        if x == 3:
            raise PlanningError("three is refused")
        return x

    with pytest.raises(PlanningError, match="three is refused"):
        forked_map(fail_on_three, range(6), 2)  # 3 is a child's

    def fail_from_two(x: int) -> int:
        if x >= 2:
            raise PlanningError(f"{x} is refused")
        return x

    # the first failing item's error, as one by one (2 is this process's, 3 a child's)
    with pytest.raises(PlanningError, match="2 is refused"):
        forked_map(fail_from_two, range(6), 2)


def test_a_child_that_dies_has_its_share_solved_here():
    parent = os.getpid()

    def die_in_children(x: int) -> int:
        if os.getpid() != parent:
            os._exit(3)  # a crashed child: nothing comes back through the pipe
        return x + 1

    assert forked_map(die_in_children, range(5), 2) == [1, 2, 3, 4, 5]


def test_a_silent_child_is_stopped_with_a_warning_and_its_share_solved_here(monkeypatch):
    """A child stuck past CHILD_TIMEOUT (a lock held at the fork, torch's threads) is killed;
    its share is solved here, and the user is told why the plan was slow."""
    import time

    monkeypatch.setattr(parallel, "CHILD_TIMEOUT", 0.5)
    parent = os.getpid()

    def hang_in_children(x: int) -> int:
        if os.getpid() != parent:
            time.sleep(60)
        return x * 2

    start = time.monotonic()
    with pytest.warns(RuntimeWarning, match="silent for 0.5 s"):
        assert forked_map(hang_in_children, range(4), 2) == [0, 2, 4, 6]
    assert time.monotonic() - start < 30


def test_where_no_child_can_be_forked_everything_is_solved_here(monkeypatch):
    def no_fork() -> int:
        raise OSError(12, "Cannot allocate memory")

    monkeypatch.setattr(os, "fork", no_fork)
    assert forked_map(_square_with_pid, range(4), 2) == [(x * x, os.getpid()) for x in range(4)]


def test_processes_follow_the_setting_the_cores_and_pool_workers(monkeypatch):
    monkeypatch.setattr(parallel, "_IN_POOL", False)
    assert processes(3) == 3
    assert processes(None) == parallel.available_cores()
    monkeypatch.setattr(parallel, "_IN_POOL", True)
    assert processes(None) == 1 and processes(2) == 2
    with pytest.raises(PlanningError, match="solve_processes"):
        ScheduleSettings(solve_processes=0)


# one hand in the default run (a plan solved twice: 5-8 s each), the others in the slow run
@pytest.mark.parametrize(
    "hand_name",
    [
        "allegro",
        pytest.param("leap", marks=pytest.mark.slow),
        pytest.param("shadow", marks=pytest.mark.slow),
    ],
)
def test_a_plan_solved_in_two_processes_is_the_plan_solved_in_one(hand_name):
    cloud_mug = make_object("mug", 3)
    results = []
    for count in (1, 2):
        settings = PlannerSettings(
            proposer="learned",
            schedule=ScheduleSettings(max_candidates=2, solve_processes=count),
            learned=LearnedSettings(samples=4, region_proposals=2),
        )
        results.append(
            FunctionalPlanner(hand_name, settings).plan(cloud_mug, "Use a mug by handle")
        )
    serial, forked = results
    assert len(serial.candidates) == len(forked.candidates) >= 4
    for a, b in zip(serial.candidates, forked.candidates, strict=True):
        assert (a.rank, a.solve.ok, a.quality, a.task_quality) == (
            b.rank,
            b.solve.ok,
            b.quality,
            b.task_quality,
        )
        assert np.array_equal(a.solve.wrist, b.solve.wrist) and np.array_equal(a.solve.q, b.solve.q)
        assert (a.order, a.success) == (b.order, b.success)
        if a.proposal.kind == "learned":  # D(R,O)'s targets made here, before the fork
            assert "dro" in a.times and "dro" in b.times


@pytest.mark.slow
def test_the_plan_time_benchmark_plans_each_pair_both_ways(tmp_path):
    import subprocess
    import sys

    argv = [sys.executable, "-m", "eval.plan_time", "--hands", "allegro", "--pairs-per-hand", "1"]
    out = subprocess.run(argv, capture_output=True, text=True, timeout=600, check=True).stdout
    row = out.strip().splitlines()[-1].split()
    assert row[0] == "allegro" and row[1] == "1" and row[-1] == "1/1"  # the same candidates
    assert float(row[2]) > 0 and float(row[3]) > 0


@pytest.mark.slow  # a learned plan, about 10 s: the default run is near its 5 minutes
def test_the_forked_solves_run_no_torch(monkeypatch):
    """torch in a child forked after the parent used its threads hangs (a plan then waits
    CHILD_TIMEOUT): in the children every way into torch from numpy raises, and a learned
    plan whose D(R,O) targets are pooled per link (planner.point_costs) still solves there."""
    import torch

    child = parallel._child

    def guarded_child(fn, items, write):
        def refuse(*args, **kwargs):
            raise AssertionError("torch called in a forked solve process")

        for name in ("from_numpy", "as_tensor", "tensor", "zeros", "ones", "empty"):
            setattr(torch, name, refuse)

        def solve_and_mark(x):
            out = fn(x)
            out.times["in_child"] = 1.0
            return out

        child(solve_and_mark, items, write)

    monkeypatch.setattr(parallel, "_child", guarded_child)
    settings = PlannerSettings(
        proposer="learned",
        schedule=ScheduleSettings(max_candidates=1, solve_processes=2),
        learned=LearnedSettings(samples=4),
    )
    result = FunctionalPlanner("allegro", settings).plan(
        make_object("mug", 4), "Hold a mug by body"
    )
    solved_in_child = [c for c in result.candidates if c.times.get("in_child")]
    assert solved_in_child and all(c.proposal.point_targets is not None for c in solved_in_child)
