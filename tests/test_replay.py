"""eval.replay: the planner's policy run on recorded outcomes gives the planner's own plan."""

import json
from dataclasses import asdict, replace

import pytest

from eval.planner_benchmark import PairRecord
from eval.replay import RecordsError, load_records, replay_pair, with_retry
from models.objects import make_object
from planner.functional import FunctionalPlanner, PlannerSettings
from planner.settings import ProposalSettings, ScheduleSettings

TEXT = "Use a mug by handle"


def _validated(summaries: list[dict]) -> list[dict]:
    """The validated candidates' summaries in validation order."""
    done = (c for c in summaries if c["validated_as"] is not None)
    return sorted(done, key=lambda c: c["validated_as"])


def _record(result, part: str) -> PairRecord:
    return PairRecord(
        hand=result.hand,
        category="mug",
        seed=3,
        instruction=TEXT,
        part=part,
        first_holds=False,
        first_part_ok=False,
        returned_holds=result.success,
        part_ok=result.success,
        candidates=len(result.candidates),
        solve_times=[],
        plan_time=0.0,
        candidate_summaries=[c.summary() for c in result.candidates],
    )


# every hand; LEAP and Shadow (9-12 s each) with the slow tests, to keep the default run in
# its 5 minutes
@pytest.mark.parametrize(
    "hand_name",
    [
        "allegro",
        pytest.param("leap", marks=pytest.mark.slow),
        pytest.param("shadow", marks=pytest.mark.slow),
    ],
)
def test_replay_of_all_validated_records_is_the_plan(hand_name, tmp_path):
    # a small policy whose sweep after 2 failed validations is reached on this handle (here: by
    # every hand, which then solves all 8 proposals; no candidate waits for the gate)
    # (passing over proposals that will miss the intent is not replayed: eval.replay)
    small = PlannerSettings(
        schedule=ScheduleSettings(
            max_candidates=4, sweep_after=2, min_quality=0.0, pass_over_misses=False
        ),
        proposals=ProposalSettings(max_proposals=8),
    )
    obj = make_object("mug", 3)
    planned = FunctionalPlanner(hand_name, small).plan(obj, TEXT)
    everything = replace(
        small, schedule=replace(small.schedule, max_candidates=32, validate_all=True)
    )  # every solved one
    recorded = FunctionalPlanner(hand_name, everything).plan(obj, TEXT)
    path = tmp_path / "records.jsonl"
    path.write_text(json.dumps(asdict(_record(recorded, "handle"))) + "\n")
    (record,) = load_records(path)
    replayed = replay_pair(record, small)
    assert replayed.candidates == len(planned.candidates)
    assert replayed.returned_holds == planned.success
    # held on the part, as eval.planner_benchmark counts it (meeting the intent or not)
    assert replayed.part_ok == (planned.success and planned.part_touched == "handle")
    assert replayed.intent_ok == (bool(planned.intent_ok) if replayed.part_ok else None)
    first = next((c for c in planned.candidates if c.order == 0), None)
    assert replayed.first_holds == bool(first and first.success)

    # the same candidates solved and validated, in the same order, with the same verdicts
    def order(summaries):
        return [(c["rank"], c["success"], c["part"]) for c in _validated(summaries)]

    assert order(replayed.candidate_summaries) == order([c.summary() for c in planned.candidates])
    assert [c["rank"] for c in replayed.candidate_summaries] == [c.rank for c in planned.candidates]


def test_records_without_every_verdict_are_refused(tmp_path):
    summary = {
        "rank": 0,
        "solved": True,
        "success": False,
        "part": None,
        "quality": 0.2,
        "task_quality": 0.3,
        "validated_as": None,
        "times": {"solve": 0.1},
    }
    record = PairRecord("leap", "mug", 3, TEXT, "handle", False, False, False, False, 1, [], 0.0)
    record.candidate_summaries = [summary]
    with pytest.raises(RecordsError, match="validate_all"):
        replay_pair(
            record, PlannerSettings(proposals=ProposalSettings(max_proposals=1, pinch_proposals=0))
        )
    with pytest.raises(RecordsError, match="max_proposals"):
        replay_pair(
            record, PlannerSettings(proposals=ProposalSettings(max_proposals=2, pinch_proposals=0))
        )
    with pytest.raises(RecordsError, match="pinch_proposals"):
        replay_pair(
            record, PlannerSettings(proposals=ProposalSettings(max_proposals=1, pinch_proposals=1))
        )
    path = tmp_path / "broken.jsonl"
    path.write_text("{not json\n")
    with pytest.raises(RecordsError, match="cannot read"):
        load_records(path)


def _summary(rank: int, success: bool, part: str | None = "handle", task: float = 0.3) -> dict:
    return {
        "rank": rank,
        "solved": True,
        "success": success,
        "part": part,
        "quality": 0.2,
        "task_quality": task,
        "validated_as": rank,
        "times": {"solve": 0.1, "validate": 0.5},
    }


def test_a_squeeze_retry_holds_where_the_deeper_squeeze_held():
    """with_retry: a slip is judged by the deeper squeeze's verdict and costs its validation;
    a hold stays as it is, and records that differ in more than the squeeze are refused."""
    settings = PlannerSettings(
        schedule=ScheduleSettings(max_candidates=3),
        proposals=ProposalSettings(max_proposals=3, pinch_proposals=0),
    )
    base = PairRecord("leap", "mug", 3, TEXT, "handle", False, False, False, False, 3, [], 0.0)
    base.candidate_summaries = [_summary(0, False), _summary(1, False), _summary(2, True)]
    deeper = replace(
        base, candidate_summaries=[_summary(0, True), _summary(1, False), _summary(2, False)]
    )
    assert not replay_pair(base, settings).first_part_ok
    (merged,) = with_retry([base], [deeper])
    assert [c["success"] for c in merged.candidate_summaries] == [True, False, True]
    assert [("retry" in c["times"]) for c in merged.candidate_summaries] == [True, True, False]
    assert replay_pair(merged, settings).first_part_ok
    assert base.candidate_summaries[0]["success"] is False  # the records themselves unchanged
    # a second retry (another depth) judges what still slips, and its validation adds up
    shallow = replace(
        base, candidate_summaries=[_summary(0, False), _summary(1, True), _summary(2, False)]
    )
    (twice,) = with_retry([merged], [shallow])
    assert [c["success"] for c in twice.candidate_summaries] == [True, True, True]
    assert [c["times"].get("retry") for c in twice.candidate_summaries] == [0.5, 1.0, None]

    solved_otherwise = replace(deeper, candidate_summaries=[_summary(0, True, task=0.9)])
    with pytest.raises(RecordsError, match="solved differently"):
        with_retry([base], [solved_otherwise])
    with pytest.raises(RecordsError, match="same pairs"):
        with_retry([base], [replace(deeper, instruction="Hold a mug by body")])


@pytest.mark.slow  # two learned benchmark plans, one with every candidate validated (7 s)
def test_replay_of_a_learned_benchmark_record_is_the_plan(tmp_path):
    """An eval.benchmark record of the learned pipeline with every candidate validated, replayed
    with the plan's own settings, gives the plan eval.benchmark recorded with them: the
    policy sees no part labels, the pair is scored on the labelled object."""
    from eval import benchmark
    from eval.replay import load_benchmark_records

    def task(overrides: tuple, candidates: int):
        pair = ("learned", "allegro", "mug", 3, TEXT, TEXT)
        # no gate: with fewer proposals than gate_solves the weak ones would wait unvalidated
        small = (
            ("learned.region_proposals", 2),
            ("schedule.sweep_after", 2),
            ("schedule.min_quality", 0.0),
        ) + overrides
        return benchmark.run_task(benchmark.Task(*pair, candidates, 4, "full", False, small))

    planned = task((("schedule.pass_over_misses", False),), 3)  # not replayed: eval.replay
    everything = task((("schedule.validate_all", True),), 32)
    path = tmp_path / "records.jsonl"
    path.write_text(json.dumps(asdict(everything)) + "\n")
    (record,), labelled = load_benchmark_records(path, None)
    assert not labelled
    settings = PlannerSettings(
        schedule=ScheduleSettings(
            max_candidates=3, sweep_after=2, min_quality=0.0, pass_over_misses=False
        )
    )
    replayed = replay_pair(record, settings, labelled, ordered=True)
    assert replayed.candidates == planned.candidates
    assert replayed.first_part_ok == planned.first_ok
    assert replayed.part_ok == planned.returned_ok
    assert replayed.returned_holds == planned.held
    assert [c["rank"] for c in _validated(replayed.candidate_summaries)] == [
        c["rank"] for c in _validated(planned.candidate_summaries)
    ]


def test_an_unlabelled_plan_stops_at_the_first_grasp_that_holds_anywhere():
    """Replaying a learned record: a grasp that holds on another part ends the search (the
    planner saw no labels) and is scored as held off the part."""
    record = PairRecord("leap", "mug", 3, TEXT, "handle", False, False, False, False, 3, [], 0.0)
    record.candidate_summaries = [
        _summary(0, True, None, task=0.9) | {"held_full": True, "touched": "body"},
        _summary(1, True, None, task=0.5) | {"held_full": True, "touched": "handle"},
    ]
    settings = PlannerSettings(schedule=ScheduleSettings(max_candidates=3))
    blind = replay_pair(record, settings, labelled=False, ordered=True)
    assert (blind.first_holds, blind.first_part_ok, blind.part_ok) == (True, False, False)
    assert blind.candidates == 2 and blind.intent_ok is None
