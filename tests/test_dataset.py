"""Dataset: compaction of batch shards, the torch loader, `dataset info`, the card."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from learned.dataset import DatasetError, GraspDataset, dataset_info, load_split
from models.hands import load_hand
from models.objects import split_of
from planner import cli
from planner.batch import make_jobs, read_results, run_batch
from planner.batch.dataset import compact
from tests.batch_fakes import fake_grasp_solve


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """A tiny set from fake grasps: 2 hands, mug + teapot (held out), 4 variants per pair."""
    root = tmp_path_factory.mktemp("ds")
    jobs = make_jobs(
        hands=["allegro", "shadow"],
        splits=["train", "val", "test", "heldout"],
        category_names=["mug", "teapot"],
        objects_per_category=10,
        variants=4,
    )
    run_batch(jobs, root / "plan", job_fn=fake_grasp_solve, progress=False)
    info = compact([root / "plan"], root / "data", command="drograsp dataset generate X")
    return root, jobs, info


def test_compaction_keeps_valid_unique_grasps_by_split(tiny):
    root, jobs, info = tiny
    records = list(read_results(root / "plan"))
    # variant 2 slips, variant 3 duplicates variant 0: two grasps kept per (object, instr, hand)
    assert info["total"] == len(jobs) // 2
    expected = {s: 0 for s in ("train", "val", "test", "heldout")}
    for job in jobs:
        if job.variant in (0, 1):
            expected[split_of(job.object["category"], job.object["seed"])] += 1
    assert info["splits"] == expected
    assert expected["val"] and expected["test"] and expected["heldout"]
    assert info["hands"] == {"allegro": len(jobs) // 4, "shadow": len(jobs) // 4}
    assert info["sources"] == {"plan": len(jobs) // 2, "transfer": 0}
    # each row carries its record's grasp
    data = load_split(root / "data", "train")
    row = 0
    hand = data.names("hands", "hand")[row]
    seed, instr = int(data.arrays["seed"][row]), data.names("instructions")[row]
    cat = data.names("categories", "category")[row]
    match = next(
        r
        for r in records
        if r["job"]["hand"] == hand
        and r["job"]["object"] == {"category": cat, "seed": seed}
        and r["job"]["instruction"] == instr
        and r["job"]["variant"] == data.arrays["variant"][row]
    )
    dof = load_hand(hand).dof
    assert data.arrays["dof_mask"][row].sum() == dof
    np.testing.assert_allclose(
        data.arrays["q_grasp"][row, :dof], match["grasp"]["grasp"], atol=1e-6
    )
    assert not data.arrays["q_grasp"][row, dof:].any()
    np.testing.assert_allclose(
        data.arrays["wrist"][row],
        match["grasp"]["wrist_pos"] + match["grasp"]["wrist_quat"],
        atol=1e-6,
    )


def test_loader_items(tiny):
    root, _, info = tiny
    ds = GraspDataset(root / "data", "train")
    assert len(ds) == info["splits"]["train"]
    item = ds[0]
    assert item["wrist"].shape == (7,) and item["anchors"].shape == (4, 3)
    assert item["q_grasp"].shape == item["dof_mask"].shape == (load_hand("shadow").dof,)
    assert item["dof_mask"].sum() == load_hand(item["hand"]).dof
    assert item["instruction"].startswith(item["intent"]) and item["part"] in item["instruction"]
    batch = next(iter(torch.utils.data.DataLoader(ds, batch_size=4)))
    assert batch["q_squeeze"].shape == (4, load_hand("shadow").dof)
    only = GraspDataset(root / "data", "train", hands=["allegro"])
    assert {only[i]["hand"] for i in range(len(only))} == {"allegro"}
    with pytest.raises(DatasetError, match="not in the dataset"):
        GraspDataset(root / "data", "train", hands=["leap"])
    with pytest.raises(DatasetError, match="no dataset here"):
        GraspDataset(root, "train")


def test_card_matches_the_data(tiny):
    root, jobs, info = tiny
    card = (root / "data" / "card.md").read_text()
    assert f"{info['total']} validated functional grasps" in card
    for split, n in info["splits"].items():
        assert f"| {split} | {n} |" in card
    for intent, n in info["intents"].items():
        assert f"| {intent} | {n} |" in card
    n_plan = sum(j.hand == "allegro" for j in jobs)
    assert f"| plan:allegro | {n_plan} | 0 | {3 * n_plan // 4} |" in card
    assert "drograsp dataset generate X" in card
    assert "2.00 grasps per group" in card


def test_dataset_info_command(tiny, capsys):
    root, _, info = tiny
    assert cli.main(["dataset", "info", str(root / "data"), "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed["splits"] == info["splits"] and printed["intents"] == info["intents"]
    assert cli.main(["dataset", "info", str(root)]) == 2
    assert dataset_info(root / "data") == printed


@pytest.mark.slow  # real plans for two hands: 20 s, which the default run's 5 minutes lack
def test_generate_a_tiny_real_dataset(tmp_path):
    from planner.batch.generate import GenerateSettings, generate_dataset

    settings = GenerateSettings(
        hands=["allegro", "shadow"],
        splits=["train"],
        category_names=["mug"],
        objects_per_category=1,
        variants=1,
        max_candidates=3,  # Allegro's third proposal holds on this mug (Shadow's fourth)
        progress=False,
    )
    info = generate_dataset(tmp_path / "ds", settings)
    assert info["total"] >= 1
    again = generate_dataset(tmp_path / "ds", settings)  # resumes: nothing to run
    assert again == info
    ds = GraspDataset(tmp_path / "ds", "train")
    assert ds[0]["metrics"][2] < 0.05  # held within 5 cm
    meta = json.loads((tmp_path / "ds" / "meta.json").read_text())
    assert list(meta["blocks"]) == ["seeds-00000"]
    assert meta["code"] and meta["code"][0] in (tmp_path / "ds" / "card.md").read_text()


def test_every_holding_grasp_of_a_validate_all_job_is_kept(tmp_path):
    from planner.batch.dataset import collect

    job = make_jobs(hands=["allegro"], category_names=["mug"], objects_per_category=1)[0]
    assert "validate_all" not in job.to_dict()  # old jobs files keep their digests
    record = fake_grasp_solve(job)
    other = fake_grasp_solve(replace(job, variant=1, id=""))
    entry = {k: record[k] for k in ("anchor_error", "min_distance", "validation", "grasp")}
    second = {**entry, "grasp": other["grasp"]}
    job_dict = replace(job, validate_all=True).to_dict()
    assert job_dict["validate_all"] is True
    with_all = {**record, "job": job_dict, "holding": [entry, second, entry]}
    rows, stats = collect([with_all])
    assert len(rows) == 2  # the repeated entry is a duplicate
    assert stats.grasps["plan:allegro"] == 3 and stats.kept["plan:allegro"] == 2
    assert stats.valid["plan:allegro"] == 1
    none_held = {**with_all, "holding": []}
    assert collect([none_held])[0] == []


def test_blocks_grow_a_dataset_like_one_compaction(tmp_path):
    """Two seed blocks appended one by one give the same splits as compacting both at once;
    the first block's file is untouched by the second (a git commit adds only the new file)."""
    from learned.dataset import block_path
    from planner.batch.dataset import add_block

    settings = {"variants": 2}
    dirs = []
    for start in (0, 2):
        jobs = make_jobs(
            hands=["allegro", "shadow"],
            splits=["train", "val", "test", "heldout"],
            category_names=["mug", "teapot"],
            objects_per_category=2,
            start_seed=start,
            variants=2,
        )
        run_batch(jobs, tmp_path / f"b{start}", job_fn=fake_grasp_solve, progress=False)
        dirs.append(tmp_path / f"b{start}")
    grown = tmp_path / "grown"
    first = add_block(grown, "seeds-0", [dirs[0]], settings=settings, seeds=(0, 2), planned=(0, 4))
    assert "2 of 4 seeds are done" in (grown / "card.md").read_text()
    before = block_path(grown, "seeds-0").read_bytes()
    info = add_block(grown, "seeds-2", [dirs[1]], settings=settings, seeds=(2, 4), planned=(0, 4))
    assert block_path(grown, "seeds-0").read_bytes() == before
    assert info["total"] > first["total"] > 0
    assert "4 of 4 seeds are done" in (grown / "card.md").read_text()
    whole = compact(dirs, tmp_path / "whole")
    assert info["splits"] == whole["splits"] and info["hands"] == whole["hands"]
    assert info["generator"] == whole["generator"]
    counts = []  # rows of the first block, of both blocks
    for split in ("train", "val", "test", "heldout"):
        a, b = load_split(grown, split), load_split(tmp_path / "whole", split)
        assert a.names("instructions") == b.names("instructions")
        np.testing.assert_array_equal(a.arrays["q_grasp"], b.arrays["q_grasp"])
        # the dataset as it stood after its first block: that block's rows, first in the whole
        earlier = load_split(grown, split, blocks=1)
        np.testing.assert_array_equal(
            earlier.arrays["q_grasp"], a.arrays["q_grasp"][: len(earlier.arrays["q_grasp"])]
        )
        counts.append((len(earlier.arrays["q_grasp"]), len(a.arrays["q_grasp"])))
    assert 0 < sum(c[0] for c in counts) < sum(c[1] for c in counts)
    with pytest.raises(DatasetError, match="already holds block seeds-2"):
        add_block(grown, "seeds-2", [dirs[1]], settings=settings, seeds=(2, 4))
    with pytest.raises(DatasetError, match="other settings .differing: variants"):
        add_block(grown, "seeds-4", [dirs[1]], settings={"variants": 3}, seeds=(4, 6))


def test_generate_refuses_other_settings_before_any_work(tmp_path, monkeypatch):
    from planner.batch import generate
    from planner.batch.dataset import add_block

    settings = generate.GenerateSettings(hands=["allegro"], category_names=["mug"], progress=False)
    add_block(tmp_path, "seeds-00000", [], settings=settings.dataset_settings(), seeds=(0, 1))
    monkeypatch.setattr(generate, "run_batch", lambda *a, **k: pytest.fail("ran jobs"))
    with pytest.raises(DatasetError, match="differing: variants"):
        generate.generate_dataset(tmp_path, replace(settings, variants=5))


SHIPPED = Path(__file__).resolve().parents[1] / "data" / "grasps_v2"
needs_shipped = pytest.mark.skipif(
    not (SHIPPED / "meta.json").is_file(), reason="no dataset in data/grasps_v2"
)


def _copy_blocks(dst: Path, names: list[str], old_format: bool = False) -> Path:
    """A dataset folder holding some of the shipped dataset's blocks; `old_format` writes it
    as drograsp-grasps/2 did (no intent_ok column)."""
    meta = json.loads((SHIPPED / "meta.json").read_text())
    meta["blocks"] = {n: meta["blocks"][n] for n in names}
    (dst / "blocks").mkdir(parents=True)
    for n in names:
        with np.load(SHIPPED / "blocks" / f"{n}.npz") as z:
            arrays = {k: z[k] for k in z.files if not (old_format and k == "intent_ok")}
        np.savez(dst / "blocks" / f"{n}.npz", **arrays)
    if old_format:
        meta["format"] = "drograsp-grasps/2"
    (dst / "meta.json").write_text(json.dumps(meta))
    return dst


@pytest.mark.slow  # data-dependent: the whole shipped dataset read and counted (5-6 s)
@needs_shipped
def test_shipped_dataset_loads_and_matches_its_card():
    """The committed dataset: every row valid (held, on the instructed part, in its object's
    split, its intent checked), the loader's counts equal `dataset info`, and the card is what
    the data says."""
    from models.objects import parse_instruction
    from planner.batch.dataset import dataset_card

    info = dataset_info(SHIPPED)
    meta = json.loads((SHIPPED / "meta.json").read_text())
    assert (SHIPPED / "card.md").read_text() == dataset_card(SHIPPED, info, meta)
    assert sum(b["grasps"] for b in meta["blocks"].values()) == info["total"] > 0
    for split, n in info["splits"].items():
        data = load_split(SHIPPED, split)
        assert len(GraspDataset(SHIPPED, split)) == n == len(data)
        a = data.arrays
        for cat, seed in {
            (c, int(s))
            for c, s in zip(data.names("categories", "category"), a["seed"], strict=True)
        }:
            assert split_of(cat, seed) == split
        texts, parts = data.names("instructions"), data.names("parts", "part")
        assert all(parse_instruction(t).part == p for t, p in zip(texts, parts, strict=True))
        assert np.isin(a["intent_ok"], (0, 1)).all()  # every grasp checked against its intent
        translation, rotation = a["metrics"][:, 2], a["metrics"][:, 3]
        assert (translation < 0.05).all() and (rotation < 15).all()
        for hand in set(data.names("hands", "hand")):
            rows = np.array(data.names("hands", "hand")) == hand
            assert (a["dof_mask"][rows].sum(axis=1) == load_hand(hand).dof).all()
        _anchors_lie_on_their_objects(data)


def _anchors_lie_on_their_objects(data) -> None:
    """Anchors are points of the object regenerated from (category, seed): a changed object
    generator that left stale rows behind fails here (`drograsp dataset refresh` mends it).
    A generator change touches every seed of a category, so the lowest seed of each is checked
    (regenerating all of them would take minutes)."""
    from scipy.spatial import cKDTree

    from models.objects import make_object

    cats = np.array(data.names("categories", "category"))
    seeds, anchors = data.arrays["seed"], data.arrays["anchors"]
    first = {c: int(seeds[cats == c].min()) for c in set(cats.tolist())}
    for cat, seed in sorted(first.items()):
        rows = (cats == cat) & (seeds == seed)
        dist, _ = cKDTree(make_object(cat, seed).points).query(anchors[rows].reshape(-1, 3))
        assert dist.max() < 1e-6, f"{cat} seed {seed}: anchors {1000 * dist.max():.1f} mm off"


def _shipped_progress() -> tuple[int, int]:
    meta = json.loads((SHIPPED / "meta.json").read_text())
    first, end = meta["planned_seeds"]
    held = {s for b in meta["blocks"].values() for s in range(*b["seeds"])}
    return len(held & set(range(first, end))), end - first


@needs_shipped
def test_shipped_dataset_meets_the_v2_counts_once_complete():
    """Dataset v2's bar: 32 seeds of every category, 25,000 grasps over the three hands, every
    category and instruction."""
    from models.objects import categories, instructions

    done, planned = _shipped_progress()
    assert planned >= 32
    if done < planned:
        pytest.skip(f"dataset v2 generation in progress: {done} of {planned} seeds done")
    info = dataset_info(SHIPPED)
    assert info["total"] >= 25_000
    assert all(n >= 5_000 for n in info["hands"].values()) and len(info["hands"]) == 3
    assert all(info["categories"][c] > 0 for c in categories())
    texts = set()
    for split in info["splits"]:
        texts |= set(load_split(SHIPPED, split).names("instructions"))
    assert texts == {i.text for c in categories() for i in instructions(c)}


def test_topup_jobs_add_variants_only_where_nothing_was_found():
    from planner.batch.generate import topup_jobs

    jobs = make_jobs(hands=["allegro"], category_names=["mug"], objects_per_category=1, variants=2)
    valid_text = jobs[0].instruction  # its first variant finds a grasp, the others find none
    records = [
        {"id": j.id, "job": j.to_dict(), "valid": j.instruction == valid_text and j.variant == 0}
        for j in jobs
    ]
    extra = topup_jobs(records, variants=2, extra=2)
    texts = {j.instruction for j in jobs} - {valid_text}
    assert {j.instruction for j in extra} == texts and len(extra) == 2 * len(texts)
    assert {j.variant for j in extra} == {2, 3}
    assert not {j.id for j in extra} & {j.id for j in jobs}
    assert topup_jobs(records, variants=2, extra=0) == []


def _solver(calls: list[str], changed: str | None = None):
    """fake_grasp_solve, recording the categories it is called for; `changed`: that category's
    grasps come out otherwise (as after a change to its objects)."""

    def solve(job):
        name = job.object["category"]
        calls.append(name)
        record = fake_grasp_solve(job)
        if name == changed:
            record["grasp"]["grasp"] = [0.5 * v for v in record["grasp"]["grasp"]]
        return record

    return solve


@pytest.mark.slow  # 7 s: a dataset made twice (the default run reached 4m49s)
def test_refresh_makes_one_category_again_and_keeps_the_others(tmp_path, monkeypatch):
    """After a change to teapots, refresh re-runs only teapot jobs, and the dataset is then what
    generating it from scratch with the changed code gives; a second refresh runs nothing."""
    from planner.batch import generate, solve
    from planner.batch.generate import GenerateSettings, generate_dataset, refresh_dataset

    settings = GenerateSettings(
        hands=["allegro", "shadow"],
        category_names=["mug", "teapot"],
        objects_per_category=2,
        variants=2,
        extra_variants=1,
        progress=False,
    )
    calls: list[str] = []
    monkeypatch.setattr(solve, "solve_job", _solver(calls))
    generate_dataset(tmp_path / "ds", settings)
    assert {"mug", "teapot"} <= set(calls)
    before = {s: load_split(tmp_path / "ds", s).arrays for s in ("train", "heldout")}

    calls.clear()
    monkeypatch.setattr(solve, "solve_job", _solver(calls, changed="teapot"))
    info = refresh_dataset(tmp_path / "ds", ["teapot"], progress=False)
    assert calls and set(calls) == {"teapot"}
    after = {s: load_split(tmp_path / "ds", s).arrays for s in ("train", "heldout")}
    np.testing.assert_array_equal(after["train"]["q_grasp"], before["train"]["q_grasp"])  # mugs
    assert not np.allclose(after["heldout"]["q_grasp"], before["heldout"]["q_grasp"])  # teapots
    meta = json.loads((tmp_path / "ds" / "meta.json").read_text())
    version = generate.code_version()
    for block in meta["blocks"].values():
        assert block["refreshed"] == [{"categories": ["teapot"], "code": version}]
    assert (
        "rows of teapot were made again in 2 block(s)" in (tmp_path / "ds" / "card.md").read_text()
    )

    calls.clear()
    assert refresh_dataset(tmp_path / "ds", ["teapot"], progress=False) == info
    assert calls == []  # every block already refreshed by this code

    scratch = tmp_path / "scratch"
    generate_dataset(scratch, settings)
    for split in ("train", "heldout"):
        a, b = load_split(tmp_path / "ds", split), load_split(scratch, split)
        for key in a.arrays:
            np.testing.assert_array_equal(a.arrays[key], b.arrays[key], err_msg=key)


def test_refresh_needs_a_generated_dataset(tiny, tmp_path):
    from planner.batch.generate import refresh_dataset

    root, _, _ = tiny
    with pytest.raises(DatasetError, match="not made by `drograsp dataset generate`"):
        refresh_dataset(root / "data", ["mug"])
    with pytest.raises(DatasetError, match="no dataset"):
        refresh_dataset(tmp_path, ["mug"])
    code = cli.main(["dataset", "refresh", str(tmp_path), "--categories", "mug"])
    assert code == 2


def test_intent_verdicts_become_the_intent_ok_column():
    """A grasp's metrics["intent_ok"] is the row's intent_ok: 1 met, 0 missed, -1 not checked
    (records made before intent checks, and every row of a drograsp-grasps/2 dataset)."""
    from planner.batch.dataset import _row

    job = {"object": {"category": "mug", "seed": 0}, "instruction": "Liftup a mug by handle"}
    job |= {"hand": "allegro", "variant": 0}
    grasp = {
        "wrist_pos": [0.0, 0.0, 0.1],
        "wrist_quat": [1.0, 0.0, 0.0, 0.0],
        "grasp": [0.0] * 16,
        "pregrasp": [0.0] * 16,
        "squeeze": [0.0] * 16,
        "anchors": [[0.0, 0.0, 0.0]] * 4,
    }
    for metrics, expected in (({"intent_ok": True}, 1), ({"intent_ok": False}, 0), ({}, -1)):
        record = {"job": job, "grasp": grasp | {"metrics": metrics}, "part_voted": "handle"}
        assert _row(record)["intent_ok"] == expected


@needs_shipped
def test_a_dataset_without_intent_verdicts_reads_as_not_checked(tmp_path):
    old_root = _copy_blocks(tmp_path / "old", ["seeds-00000"], old_format=True)
    old = load_split(old_root, "test")
    assert old.meta["format"] == "drograsp-grasps/2" and len(old) > 0
    assert (old.arrays["intent_ok"] == -1).all()
    assert GraspDataset(old_root, "test")[0]["intent_ok"] == -1


@needs_shipped
def test_several_folders_read_as_one_with_each_rows_own_names(tmp_path):
    v1 = _copy_blocks(tmp_path / "old", ["seeds-00000"], old_format=True)
    v2 = _copy_blocks(tmp_path / "new", ["seeds-00001"])
    meta = json.loads((v1 / "meta.json").read_text())  # tables in another order, one hand less
    meta["instructions"] = meta["instructions"][::-1]
    with np.load(v1 / "blocks" / "seeds-00000.npz") as z:
        arrays = {k: z[k] for k in z.files}
    keep = arrays["hand"] != meta["hands"].index("shadow")
    arrays = {k: v[keep] for k, v in arrays.items()}
    n = len(meta["instructions"]) - 1
    arrays["instruction"] = (n - arrays["instruction"]).astype(arrays["instruction"].dtype)
    meta["hand_dof"].pop("shadow")
    arrays["q_grasp"] = arrays["q_grasp"][:, :16]
    for key in ("q_pregrasp", "q_squeeze", "dof_mask"):
        arrays[key] = arrays[key][:, :16]
    np.savez(v1 / "blocks" / "seeds-00000.npz", **arrays)
    meta["blocks"]["seeds-00000"]["grasps"] = int(keep.sum())
    (v1 / "meta.json").write_text(json.dumps(meta))
    a, b = load_split(v1, "val"), load_split(v2, "val")
    assert a.arrays["q_grasp"].shape[1] == 16 and len(a) and len(b)
    original = load_split(_copy_blocks(tmp_path / "orig", ["seeds-00000"]), "val")
    shadow = np.array(original.names("hands", "hand")) == "shadow"
    assert a.names("instructions", "instruction") == list(
        np.array(original.names("instructions", "instruction"))[~shadow]
    )
    both = load_split([v1, v2], "val")
    assert len(both) == len(a) + len(b)
    for table, column in (("hands", "hand"), ("instructions", "instruction"), ("parts", "part")):
        assert both.names(table, column) == a.names(table, column) + b.names(table, column)
    assert both.arrays["q_grasp"].shape[1] == max(a.arrays["q_grasp"].shape[1], 22)
    assert (both.arrays["intent_ok"][: len(a)] == -1).all()  # the old format has no verdicts
    assert np.isin(both.arrays["intent_ok"][len(a) :], (0, 1)).all()


@needs_shipped
def test_check_intents_writes_every_intent_each_grasp_meets(tmp_path):
    """`dataset check-intents`: each row is checked against every intent the table asks of
    its part; its own intent's verdict is its intent_ok, and a second run has nothing to do."""
    from models.objects import INTENTS, TABLE

    root = _copy_blocks(tmp_path / "ds", ["seeds-00001"])
    with np.load(root / "blocks" / "seeds-00001.npz") as z:  # 60 rows keep the test quick
        np.savez(root / "blocks" / "seeds-00001.npz", **{k: z[k][:60] for k in z.files})
    meta = json.loads((root / "meta.json").read_text())
    meta["blocks"]["seeds-00001"]["grasps"] = 60
    (root / "meta.json").write_text(json.dumps(meta))
    assert (load_split(root, "train").arrays["intents_met"] == -1).all()  # not checked yet
    assert dataset_info(root)["intents_unchecked"] == 60
    assert cli.main(["dataset", "check-intents", str(root)]) == 0
    info = dataset_info(root)
    assert info["intents_unchecked"] == 0 and info["meets_none"] <= 60
    assert (root / "intents" / "seeds-00001.npz").is_file()
    rows = {s: load_split(root, s) for s in ("train", "val", "test", "heldout")}
    checked = 0
    for data in rows.values():
        a, m = data.arrays, data.meta
        for r in range(len(data)):
            cat, part = m["categories"][a["category"][r]], m["parts"][a["part"][r]]
            asked = {i for i, p in TABLE[cat] if p == part}
            met = a["intents_met"][r]
            assert [met[k] >= 0 for k in range(len(INTENTS))] == [i in asked for i in INTENTS]
            own = m["intents"][a["intent"][r]]
            assert met[INTENTS.index(own)] == a["intent_ok"][r]
            checked += 1
    assert checked == 60
    from planner.batch.intents import pending_blocks

    assert pending_blocks(root) == []
    # a block made again (here: one grasp moved) gets no stale verdicts
    with np.load(root / "blocks" / "seeds-00001.npz") as z:
        arrays = {k: z[k] for k in z.files}
    arrays["wrist"][0, 0] += 0.01
    np.savez(root / "blocks" / "seeds-00001.npz", **arrays)
    assert pending_blocks(root) == ["seeds-00001"]
    assert (load_split(root, "train").arrays["intents_met"] == -1).all()
