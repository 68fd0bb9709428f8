"""Issue 28's rule, fuzzed: every input a user can give is a clean DrograspError or a correct
result; never another exception, a hang, a crash of the process, or bad input accepted.

The cases (tests/fuzz_cases.py, seeded) cover load_object's arrays and files, make_object,
instructions, grasp records, validation settings, plan_grasp's settings, jobs and batch folders,
the CLI (in process: an exception escaping `main` is a traceback), malformed hand folders (every
hand.json field and URDF element of the wrong kind, hands only MuJoCo or Drake would refuse, the
error naming the file) and the hand API's joint vectors and wrists, each crash kind of the issue
among them. They run in a worker subprocess with a time limit per case, so an abort or a hang is
recorded, not suffered.
"""

from __future__ import annotations

import pytest

from tests.fuzz_cases import GROUPS, run_fuzz


def _check(report, minimum: int) -> None:
    figures = report.figures()
    print(figures)
    failures = "\n".join(f"{o.kind} [{o.group}] {o.name}: {o.detail}" for o in report.failures())
    assert not failures, f"{figures}\n{failures}"
    assert figures["cases"] >= minimum
    assert set(GROUPS) == {o.group for o in report.outcomes}


@pytest.mark.slow  # every entry point with every bad input: 17-27 s, beyond the default run's 5 minutes
def test_fuzz_every_entry_point(tmp_path):
    """About 750 cases in about 20-40 s."""
    _check(run_fuzz(seed=0, scale=1, timeout=60.0, tmp=tmp_path), 700)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2])
def test_fuzz_more_seeds(tmp_path, seed):
    """The random families (clouds, instructions, library seeds) four times over."""
    _check(run_fuzz(seed=seed, scale=4, timeout=120.0, tmp=tmp_path), 450)
