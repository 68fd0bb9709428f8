"""`python -m eval.benchmark`: the same pairs for every method, resumable records, the table."""

from __future__ import annotations

import json
from dataclasses import asdict

import pytest

from eval import benchmark


def test_unlabelled_copy_keeps_the_geometry_and_hides_the_parts():
    from models.objects import make_object

    mug = make_object("mug", 3)
    hidden = benchmark.unlabelled(mug)
    assert mug.labelled and not hidden.labelled
    assert hidden.mesh is mug.mesh and hidden.part_names == ()


def test_every_method_gets_the_same_pairs_and_paraphrases_go_to_learned_ones_only():
    tasks = benchmark.tasks("test", 1, ["allegro"], ["learned", "model"], True, 8, 8, ["mug"])
    learned = [t for t in tasks if t.method == "learned"]
    model = [t for t in tasks if t.method == "model"]
    pair = [(t.hand, t.category, t.seed, t.instruction) for t in learned]
    assert pair == [(t.hand, t.category, t.seed, t.instruction) for t in model]
    assert len(learned) == 5
    assert all(t.text == t.instruction for t in model)  # the model-based planner needs it
    assert all(t.text != t.instruction for t in learned)


def test_sample_seeds_repeat_the_learned_methods_only_and_are_told_apart():
    tasks = benchmark.tasks(
        "test", 1, ["allegro"], ["learned", "model"], False, 8, 8, ["mug"], seeds=(0, 1, 2)
    )
    learned = [t for t in tasks if t.method == "learned"]
    assert len(learned) == 15 and {t.sample_seed for t in learned} == {0, 1, 2}
    assert len([t for t in tasks if t.method == "model"]) == 5  # it draws nothing
    assert len({t.key for t in tasks}) == len(tasks)  # resumable: every task its own record


def test_intents_keep_their_instructions_and_each_pair_its_rewording():
    every = benchmark.tasks("test", 1, ["allegro"], ["learned"], True, 8, 8, ["mug", "knife"])
    hold = benchmark.tasks(
        "test", 1, ["allegro"], ["learned"], True, 8, 8, ["mug", "knife"], intents=["Hold"]
    )
    assert hold and all(t.instruction.startswith("Hold ") for t in hold)
    assert hold == [t for t in every if t.instruction.startswith("Hold ")]


def test_the_table_gives_first_and_within_per_seed():
    def rec(seed, first, within):
        r = benchmark.Record("learned", "allegro", "mug", 0, "Use a mug by handle", "t", "handle")
        r.sample_seed, r.first_ok, r.returned_ok = seed, first, within
        return r

    rows = benchmark.summarise(
        [rec(0, True, True), rec(0, False, True), rec(1, False, False), rec(1, False, True)]
    )
    assert rows[0]["first_by_seed"] == {0: 50.0, 1: 0.0} and rows[0]["first"] == 25.0
    assert "| 50, 0 / 100, 50% |" in benchmark.table(rows, 8)


def test_uncertain_grasps_are_counted_apart_from_the_held_ones():
    def rec(uncertain, held_on_object):
        r = benchmark.Record("learned", "leap", "mug", 0, "Use a mug by handle", "t", "handle")
        r.uncertain, r.uncertain_held = uncertain, held_on_object
        return r

    rows = benchmark.summarise([rec(True, True), rec(True, False), rec(False, False)])
    assert rows[0]["uncertain"] == 2 and rows[0]["uncertain_held"] == 1
    assert rows[0]["held"] == 0.0 and rows[0]["within"] == 0.0
    assert "learned leap 1 of 2" in benchmark.uncertain_line(rows)
    rows = benchmark.summarise([rec(False, False)])
    assert benchmark.uncertain_line(rows) == ""


def test_the_sample_seed_is_set_by_seeds_not_by_set(tmp_path):
    with pytest.raises(SystemExit, match="--seeds"):
        benchmark.main(["--set", "learned.seed=3", "--out", str(tmp_path)])


@pytest.mark.slow
def test_a_run_writes_its_records_and_resumes(tmp_path, capsys):
    argv = ["--hands", "allegro", "--categories", "mug", "--methods", "no_dro", "model"]
    argv += ["--samples", "2", "--candidates", "2", "--out", str(tmp_path)]
    assert benchmark.main(argv) == 0
    lines = (tmp_path / "records.jsonl").read_text().splitlines()
    assert len(lines) == 10
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert {r["method"] for r in summary["rows"]} == {"no_dro", "model"}
    assert (tmp_path / "bars.png").stat().st_size > 0
    assert "| model | allegro | 5 |" in (tmp_path / "table.md").read_text()
    records = [json.loads(line) for line in lines]
    for r in records:  # intent judged exactly where the grasp held on the instructed part
        assert (r["intent_ok"] is not None) == r["returned_ok"]
    capsys.readouterr()
    assert benchmark.main(argv) == 0  # nothing left to do: the records are reused
    assert "10 tasks, 10 done before" in capsys.readouterr().out
    assert len((tmp_path / "records.jsonl").read_text().splitlines()) == 10


def test_the_intent_share_counts_grasps_held_on_the_part_only():
    def rec(returned_ok, intent_ok):
        r = benchmark.Record("learned", "allegro", "mug", 0, "Use a mug by handle", "t", "handle")
        r.held = r.returned_ok = returned_ok
        r.intent_ok = intent_ok
        return r

    rows = benchmark.summarise(
        [rec(True, True), rec(True, False), rec(True, True), rec(False, None)]
    )
    assert rows[0]["intent"] == pytest.approx(200 / 3) and rows[0]["within"] == 75.0
    assert "| 67% |" in benchmark.table(rows, 8)


def test_benchmark_settings_are_checked_before_any_work(tmp_path):
    from eval import benchmark

    with pytest.raises(SystemExit, match="learned.bogus"):
        benchmark.main(["--set", "learned.bogus=1", "--out", str(tmp_path)])
    with pytest.raises(SystemExit, match="no interaction.safetensors"):
        benchmark.main(["--set", f"learned.interaction_weights={tmp_path}", "--out", str(tmp_path)])


@pytest.mark.parametrize("view", ["full", "cloud"])
def test_each_view_gives_the_planner_its_input_and_judges_on_the_object(view, monkeypatch):
    """`--view cloud` plans on surface samples (no mesh, no labels for learned methods); the
    grasp is then judged on the full object, whose mesh the benchmark keeps."""
    given = []

    class Stop(Exception):
        pass

    def plan(self, obj, text):
        given.append(obj)
        raise Stop

    monkeypatch.setattr(benchmark.FunctionalPlanner, "plan", plan)
    monkeypatch.setattr(benchmark, "_PLANNERS", {})
    task = ("learned", "allegro", "mug", 3, "Use a mug by handle", "Use a mug by handle")
    rec = benchmark.run_task(benchmark.Task(*task, 8, 4, view, False, ()))
    assert rec.error.startswith("Stop") and rec.view == view
    (obj,) = given
    assert not obj.labelled
    if view == "cloud":
        assert obj.mesh is None and len(obj.points) == benchmark.CLOUD_POINTS
    else:
        assert obj.mesh is not None


def test_cloud_checks_table_counts_what_each_number_of_checks_keeps():
    from eval.cloud_checks import table

    key = {"hand": "leap", "category": "mug", "seed": 3, "instruction": "Use a mug by handle"}
    rows = [
        key | {"rank": 0, "checks": [True, True], "real": True},
        key | {"rank": 1, "checks": [True, False], "real": False},
        key | {"rank": 2, "checks": [False, True], "real": True},
    ]
    lines = table(rows, 2).splitlines()
    assert lines[2] == "| leap | 0 | 3 | 3 | 2 (67%) | 0 of 0 |"
    assert lines[3] == "| leap | 1 | 3 | 2 | 1 (50%) | 1 of 1 |"
    assert lines[4] == "| leap | 2 | 3 | 1 | 1 (100%) | 1 of 2 |"


def test_intent_is_also_given_where_the_definition_can_be_met():
    def rec(ok, meetable):
        r = benchmark.Record("model", "leap", "cup", 0, "Handover a cup by rim", "t", "rim")
        r.returned_ok, r.intent_ok, r.intent_meetable = True, ok, meetable
        return r

    rows = benchmark.summarise([rec(True, True), rec(False, True), rec(False, False)])
    assert round(rows[0]["intent"]) == 33 and rows[0]["intent_meetable"] == 50.0
    assert "model leap 50% (1 pairs left out)" in benchmark.meetable_line(rows)
    # records made before the field count as meetable; none left out, no line
    assert benchmark.meetable_line(benchmark.summarise([rec(True, None)])) == ""
    # and the column per intent, in the table's order of intents
    hold = benchmark.Record("model", "leap", "cup", 0, "Hold a cup by body", "t", "body")
    hold.returned_ok, hold.intent_ok = True, True
    rows = benchmark.summarise([rec(True, True), rec(False, True), hold])
    assert "model leap Hold 100%, Handover 50%" in benchmark.intent_line(rows)


def test_join_prints_runs_joined_a_later_record_replacing_an_earlier(tmp_path, capsys):
    def run(name, *records):
        folder = tmp_path / name
        folder.mkdir()
        lines = [json.dumps(asdict(r)) for r in records]
        (folder / "records.jsonl").write_text("\n".join(lines) + "\n")
        return str(folder)

    def rec(instruction, first):
        r = benchmark.Record("learned", "leap", "mug", 0, instruction, "t", "handle")
        r.first_ok = r.returned_ok = first
        return r

    whole = run("whole", rec("Use a mug by handle", True), rec("Liftup a mug by handle", False))
    liftup = run("liftup", rec("Liftup a mug by handle", True))
    assert benchmark.main(["--join", whole, liftup]) == 0
    assert "| learned | leap | 2 | 100% | 100% |" in capsys.readouterr().out
    assert not (tmp_path / "joined").exists()  # nothing written without --out
    assert benchmark.main(["--join", whole, liftup, "--out", str(tmp_path / "joined")]) == 0
    assert "| learned | leap | 2 | 100% | 100% |" in (tmp_path / "joined" / "table.md").read_text()
    assert (tmp_path / "joined" / "bars.png").stat().st_size > 0
    with pytest.raises(SystemExit, match="no records"):
        benchmark.main(["--join", str(tmp_path / "none")])
