"""eval.runs: a stopped evaluation run loses no finished record and continues where it stopped."""

from __future__ import annotations

from dataclasses import dataclass

from eval.runs import read_records, run_resumable


@dataclass
class Square:
    n: int
    value: int = 0

    @property
    def key(self) -> int:
        return self.n


@dataclass(frozen=True)
class Job:
    n: int

    @property
    def key(self) -> int:
        return self.n


CALLS: list[int] = []


def square(job: Job) -> Square:
    CALLS.append(job.n)
    return Square(job.n, job.n * job.n)


def test_a_run_appends_as_it_goes_and_a_second_run_plans_only_what_is_missing(tmp_path, capsys):
    path = tmp_path / "out" / "records.jsonl"
    CALLS.clear()
    first = run_resumable([Job(1), Job(2)], square, path, Square)
    assert [r.value for r in first] == [1, 4] and CALLS == [1, 2]
    assert read_records(path, Square) == first
    # a larger run in another order: the two finished ones are read back, not planned again
    again = run_resumable([Job(3), Job(2), Job(1)], square, path, Square)
    assert CALLS == [1, 2, 3]
    assert [(r.n, r.value) for r in again] == [(3, 9), (2, 4), (1, 1)]
    assert "3 tasks, 2 done before" in capsys.readouterr().out
    assert len(read_records(path, Square)) == 3


def test_no_records_file_reads_as_no_records(tmp_path):
    assert read_records(tmp_path / "none.jsonl", Square) == []
