"""The learned pipeline against its ablations and the model-based planner, on the same pairs.

    python -m eval.benchmark --split test --objects-per-category 1 --workers 2

Every method plans the same (object, instruction, hand) pairs in one run. The learned methods
see the object without its part labels (the same mesh, so the same collision pieces and the
same MuJoCo validation); the part a grasp touches is scored afterwards with the labels they never
saw (the fingertip vote of planner.labels). The model-based planner is given the labels (its
oracle). Methods (METHODS): `learned` (interaction diffusion -> D(R,O) -> Drake -> MuJoCo),
`no_dro` (wrist and anchors straight into Drake), `no_anchors` (D(R,O) trained and run on 512
farthest points with no contact map, learned/weights/dro_no_anchors; Drake still gets the
anchors), `no_drake` (D(R,O)'s targets, joints fitted to them without collision constraints,
as D(R,O) Grasp does: learned.joint_fit), `direct` (one diffusion model draws wrist and joints
with the same encoders, text and data: learned/weights/direct; no anchors, no D(R,O), no solver,
samples validated as drawn: the paper's Scene-Diffuser comparison) and `model`. Per hand and
method:

- first: the first validated candidate holds and touches the instructed part (the paper's
  first-sample success);
- within N: the returned grasp holds and touches the instructed part, N validations at most;
- held: the returned grasp holds, on any part; part accuracy: held on the instructed part
  among the held;
- meets intent: among the grasps held on the instructed part, the share that meet the
  instruction's intent definition (planner.intent, checked on the labelled object); below the
  table, the same over the pairs whose definition can be met on their part at all
  (planner.intent.unmeetable: not Handover by a cup's or a bowl's rim), and per intent;
- time: median wall time per pair, and per stage (summary.json's `stage_median_s`).

`--seeds 0 1 2` plans every pair once per sample seed of the learned methods and pools them:
a solve is chaotic in its inputs (D(R,O) distances changed by 4e-8 m moved Allegro's first
sample from 74% to 60% of 50 pairs), so one seed's 50 pairs move by up to 10-15 points from
another's, and comparisons need several.

`--paraphrase` gives the learned methods an evaluation-only rewording of each instruction
(learned.paraphrase.EVAL_TEMPLATES, never trained on); the model-based planner keeps the
canonical text it needs. `--turn` turns every object (any yaw, a tilt up to 30 degrees, one
turn per pair). `--view single` plans on what a depth camera sees from one viewpoint
(models.objects.views: 320 x 240 rays, 1 mm depth noise; the model-based planner gets the
seen faces' labels) and validates the chosen grasps in MuJoCo against the full object; `--view
cloud` does the same with 4096 random surface points (a complete scan, collision pieces made
from the cloud, as for drograsp demo's clouds). Records go to OUT/records.jsonl as they finish,
so an interrupted run resumes; OUT/summary.json, OUT/table.md and OUT/bars.png are written at
the end. `--join RUN_A RUN_B` prints the table of two runs' records joined (RUN_B's replacing
RUN_A's for the same pair, method and seed: a run of some intents over a whole run); with
`--out DIR` it writes their table and plot there (a run of some methods beside another's).
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from eval.runs import read_records, run_resumable
from models.errors import DrograspError
from models.hands import available_hands, load_hand
from models.objects import ObjectModel, make_object, parse_instruction
from models.objects.names import INTENTS
from models.objects.views import random_turn, sampled_cloud_object, single_view_object, turned
from planner.commands.validate import parse_overrides
from planner.functional import FunctionalPlanner
from planner.intent import check_configuration, intent_definition, unmeetable
from planner.labels import grasp_part
from planner.settings import LearnedSettings, PlannerSettings, ScheduleSettings, with_overrides
from planner.validation import validate

# each method's settings over the defaults, as planner.settings.with_overrides keys
METHODS: dict[str, dict[str, Any]] = {
    "learned": {"proposer": "learned"},  # interaction diffusion -> D(R,O) -> Drake -> MuJoCo
    "no_dro": {"proposer": "learned", "learned.dro": False},  # wrist + anchors into Drake
    # D(R,O) -> every point's target -> joints fitted without collision constraints (D(R,O)
    # Grasp's way; the grasp program is not run)
    "no_drake": {"proposer": "learned", "learned.solver": "fit"},
    # D(R,O) trained and run on a uniformly sampled object cloud (the paper's Table 3)
    "no_anchors": {"proposer": "learned", "learned.dro_weights": "dro_no_anchors"},
    # [wrist, joints] drawn by one diffusion model, validated as drawn (Scene-Diffuser's way)
    "direct": {"proposer": "direct"},
    "model": {"proposer": "model"},  # the model-based planner, part labels given
}


CLOUD_POINTS = 4096  # as drograsp demo's unlabelled clouds
# what the methods are given (MuJoCo always validates the returned grasp on the full object)
VIEWS = {
    "full": "full objects",  # the mesh (the learned methods without its part labels)
    "cloud": f"{CLOUD_POINTS}-point surface clouds",  # a complete scan: pieces from the cloud
    "single": "single-view clouds",  # one depth camera view, completed by the planner
}


@dataclass
class Record:
    method: str
    hand: str
    category: str
    seed: int
    instruction: str  # canonical
    text: str  # what the method was given
    part: str
    view: str = "full"  # VIEWS: the "full" object, a sampled "cloud" or a "single" view
    turn: bool = False
    sample_seed: int = 0  # learned.seed: the learned methods' samples (--seeds)
    first_ok: bool = False
    returned_ok: bool = False
    held: bool = False
    # the returned grasp held on what the method planned on (a cloud: pieces made from it; a
    # single view: its completion); `held` is the same grasp on the full object
    planned: bool = False
    # no grasp passed the cloud checks and the returned one is uncertain (PlanResult.status);
    # `uncertain_held`: it held on the full object
    uncertain: bool = False
    uncertain_held: bool = False
    part_touched: str | None = None
    # the returned grasp, held on the instructed part, against its intent's definition
    # (planner.intent), checked on the labelled object; None: not held on the part
    intent_ok: bool | None = None
    # the intent's definition can be met on the instructed part of the labelled object
    # (planner.intent.unmeetable: not Handover by a cup's rim); None: not recorded
    intent_meetable: bool | None = None
    understood: str | None = None
    candidates: int = 0
    # proposals passed over unsolved in the search for the intent (PlanResult.passed)
    passed: int = 0
    plan_time: float = 0.0
    stage_times: dict[str, float] = field(default_factory=dict)
    # every solved candidate (planner.results.CandidateResult.summary), with the proposal's
    # drawn wrist ("drawn_wrist"), anchors and anchor closure and, where validated and held,
    # the part it touches on the labelled object ("touched") and whether it holds on the full
    # object ("held_full"): what a validation order can be compared on afterwards (with
    # schedule.validate_all=true)
    candidate_summaries: list[dict] = field(default_factory=list)
    error: str = ""

    @property
    def key(self) -> tuple:
        """What tells one record from another: a resumed run skips the tasks with its key."""
        return tuple(getattr(self, name) for name in KEY_FIELDS)


# the fields of a Record's (and its Task's) key
KEY_FIELDS = ("method", "hand", "category", "seed", "instruction", "view", "turn", "sample_seed")


@dataclass(frozen=True)
class Task:
    """One (pair, method, sample seed) to plan: what `run_task` needs, picklable for the pool."""

    method: str
    hand: str
    category: str
    seed: int  # the object's
    instruction: str  # canonical
    text: str  # what the method is given
    max_candidates: int
    samples: int
    view: str = "full"
    turn: bool = False
    overrides: tuple = ()  # (dotted key, value) planner settings for every method
    sample_seed: int = 0

    @property
    def key(self) -> tuple:
        """Its Record.key."""
        return tuple(getattr(self, name) for name in KEY_FIELDS)


def unlabelled(obj: ObjectModel) -> ObjectModel:
    """The same object without part labels: what a method that never sees labels gets."""
    return replace(obj, face_labels=None, cloud_labels=None, part_names=(), _derived={})


def touched_part(grasp, obj: ObjectModel, hand) -> str:
    """The part the grasp's fingertips vote for, on the labelled object."""
    wrist = np.concatenate([grasp.wrist_pos, grasp.wrist_quat])
    return grasp_part(hand, wrist, np.asarray(grasp.grasp), obj)


# one planner per worker for each method, hand, sample seed and settings
_PLANNERS: dict[tuple, FunctionalPlanner] = {}


def full_object(cat: str, seed: int, turn: bool) -> ObjectModel:
    """The pair's object, turned where asked (the same turn for every method and hand)."""
    obj = make_object(cat, seed)
    if not turn:
        return obj
    from models.objects.names import CATEGORY_NAMES

    return turned(obj, random_turn(1000 * CATEGORY_NAMES.index(cat) + seed))


def run_task(task: Task) -> Record:
    method, cat, seed, view, turn = task.method, task.category, task.seed, task.view, task.turn
    part = task.instruction.rsplit(" by ", 1)[1]
    rec = Record(method, task.hand, cat, seed, task.instruction, task.text, part, view, turn)
    rec.sample_seed = task.sample_seed
    key = (method, task.hand, task.sample_seed, task.max_candidates, task.samples, task.overrides)
    if key not in _PLANNERS:
        settings = PlannerSettings(
            schedule=ScheduleSettings(max_candidates=task.max_candidates),
            learned=LearnedSettings(samples=task.samples, seed=task.sample_seed),
        )
        settings = with_overrides(settings, {**METHODS[method], **dict(task.overrides)})
        _PLANNERS[key] = FunctionalPlanner(task.hand, settings)
    planner = _PLANNERS[key]
    oracle = METHODS[method]["proposer"] == "model"
    try:
        obj = full_object(cat, seed, turn)
        meaning = intent_definition(obj, task.instruction)
        rec.intent_meetable = unmeetable(obj, meaning) is None
        if view == "single":
            given = single_view_object(obj, seed=seed, labelled=oracle)
        elif view == "cloud":
            given = sampled_cloud_object(obj, CLOUD_POINTS, seed=seed, labelled=oracle)
        else:
            given = obj if oracle else unlabelled(obj)
        start = time.perf_counter()
        result = planner.plan(given, task.text)
        rec.plan_time = time.perf_counter() - start
    except Exception as err:  # noqa: BLE001 - a benchmark records failures and goes on
        rec.error = f"{type(err).__name__}: {err}"[:300]
        return rec
    hand = planner.hand

    def judged(cand) -> tuple[bool, str | None]:
        """Held in planning and (planned on a cloud or a view) against the full object too,
        and then the part it touches on the labelled object."""
        if not cand.success:
            return False, None
        held = view == "full" or bool(
            validate(cand.grasp, obj.collision_pieces(), hand, planner.settings.protocol).success
        )
        return held, touched_part(cand.grasp, obj, hand) if held else None

    # each held candidate judged once: the first, the returned one and the records use it
    verdicts = {c.rank: judged(c) for c in result.candidates}
    first = next((c for c in result.candidates if c.order == 0), None)
    rec.first_ok = first is not None and verdicts[first.rank] == (True, part)
    best = result.best
    rec.planned = bool(result.success)
    if result.status == "uncertain":
        rec.uncertain = True
        rec.uncertain_held = bool(
            validate(result.grasp, obj.collision_pieces(), hand, planner.settings.protocol).success
        )
    rec.held = rec.planned and verdicts[best.rank][0]
    if rec.held:
        rec.part_touched = verdicts[best.rank][1]
        rec.returned_ok = rec.part_touched == part
    if rec.returned_ok:
        wrist = np.concatenate([result.grasp.wrist_pos, result.grasp.wrist_quat])
        check = check_configuration(
            wrist, np.asarray(result.grasp.grasp), obj, hand, task.instruction
        )
        rec.intent_ok = bool(check.ok)
    rec.understood = result.instruction.text
    rec.candidates = len(result.candidates)
    rec.passed = len(result.passed)
    rec.stage_times = {k: round(v, 4) for k, v in result.stage_times().items()}
    for cand in result.candidates:
        summary = cand.summary()
        summary["anchor_quality"] = cand.proposal.anchor_quality
        summary["shaped"] = cand.proposal.shaped
        summary["anchors"] = np.round(cand.proposal.anchors, 4).tolist()
        summary["drawn_wrist"] = np.round(cand.proposal.wrist, 4).tolist()
        summary["held_full"], summary["touched"] = verdicts[cand.rank]
        rec.candidate_summaries.append(summary)
    return rec


def tasks(
    split: str,
    per_category: int,
    hands: list[str],
    methods: list[str],
    paraphrase: bool,
    max_candidates: int,
    samples: int,
    category_names: list[str] | None = None,
    view: str = "full",
    turn: bool = False,
    overrides: dict[str, Any] | None = None,
    seeds: tuple[int, ...] = (0,),
    intents: list[str] | None = None,
) -> list[Task]:
    """One task per (pair, method, sample seed); `overrides`: planner settings (dotted keys)
    for every method, over each method's own; `seeds`: the learned methods' sample seeds
    (learned.seed; the model-based planner draws nothing, so it runs once); `intents`: only
    the instructions of these (a pair keeps the rewording it has in the whole run)."""
    from eval.planner_benchmark import pairs
    from learned.paraphrase import eval_paraphrases, request_of

    out = []
    chosen = pairs(split, per_category, hands)
    if category_names:
        chosen = [c for c in chosen if c[1] in category_names]
    over = tuple((overrides or {}).items())
    for i, (hand, cat, seed, instruction) in enumerate(chosen):
        if intents and parse_instruction(instruction).intent not in intents:
            continue
        reworded = eval_paraphrases(request_of(instruction))
        for method in methods:
            learned = METHODS[method]["proposer"] != "model"
            text = reworded[i % len(reworded)] if paraphrase and learned else instruction
            for sample_seed in seeds if learned else seeds[:1]:
                task = (method, hand, cat, seed, instruction, text, max_candidates, samples)
                out.append(Task(*task, view, turn, over, sample_seed))
    return out


def summarise(records: list[Record]) -> list[dict]:
    rows = []
    for method in dict.fromkeys(r.method for r in records):
        for hand in sorted({r.hand for r in records if r.method == method}):
            rs = [r for r in records if r.method == method and r.hand == hand]
            held = [r for r in rs if r.held]
            on_part = [r for r in rs if r.returned_ok and r.intent_ok is not None]
            meetable = [r for r in on_part if r.intent_meetable is not False]
            times = [r.plan_time for r in rs if not r.error]
            stages: dict[str, list[float]] = {}
            for r in rs:
                for k, v in r.stage_times.items():
                    stages.setdefault(k, []).append(v)
            rows.append(
                {
                    "method": method,
                    "hand": hand,
                    "pairs": len(rs),
                    "first": 100 * float(np.mean([r.first_ok for r in rs])),
                    "within": 100 * float(np.mean([r.returned_ok for r in rs])),
                    "held": 100 * float(np.mean([r.held for r in rs])),
                    "held_as_planned": 100 * float(np.mean([r.planned for r in rs])),
                    "part_accuracy": (
                        100 * float(np.mean([r.returned_ok for r in held])) if held else 0.0
                    ),
                    "intent": (
                        100 * float(np.mean([r.intent_ok for r in on_part])) if on_part else 0.0
                    ),
                    # the same where the definition can be met on the part (intent_meetable)
                    "intent_meetable": (
                        100 * float(np.mean([r.intent_ok for r in meetable])) if meetable else 0.0
                    ),
                    "unmeetable_pairs": sum(r.intent_meetable is False for r in rs),
                    # the intent column per intent, over the grasps held on the part
                    "intent_by_intent": _by_intent(on_part),
                    "median_s": statistics.median(times) if times else float("nan"),
                    # the sample seeds pooled here, and first / within per seed: how far one
                    # run of the pairs moves from another (--seeds)
                    "seeds": sorted({r.sample_seed for r in rs}),
                    "first_by_seed": _by_seed(rs, "first_ok"),
                    "within_by_seed": _by_seed(rs, "returned_ok"),
                    "stage_median_s": {k: statistics.median(v) for k, v in stages.items()},
                    "errors": sum(bool(r.error) for r in rs),
                    # uncertain grasps returned (counted neither as held nor within) and how
                    # many of them held on the full object
                    "uncertain": sum(r.uncertain for r in rs),
                    "uncertain_held": sum(r.uncertain_held for r in rs),
                }
            )
    return rows


def _by_intent(records: list[Record]) -> dict[str, float]:
    """Per intent present, the % of its records meeting it (table order of INTENTS)."""
    intents = [parse_instruction(r.instruction).intent for r in records]
    return {
        i: 100
        * float(np.mean([r.intent_ok for r, j in zip(records, intents, strict=True) if j == i]))
        for i in INTENTS
        if i in intents
    }


def _by_seed(records: list[Record], flag: str) -> dict[int, float]:
    """Per sample seed, the % of its records with `flag` set."""
    seeds = sorted({r.sample_seed for r in records})
    return {
        s: 100 * float(np.mean([getattr(r, flag) for r in records if r.sample_seed == s]))
        for s in seeds
    }


def table(rows: list[dict], max_candidates: int) -> str:
    """The README table; with several sample seeds, "pairs" counts every (pair, seed) and a
    column gives first and within per seed."""
    several = any(len(r.get("seeds", ())) > 1 for r in rows)
    extra = f" first / within {max_candidates} per seed |" if several else ""
    head = (
        f"| method | hand | pairs | first | within {max_candidates} | held | part accuracy "
        f"| meets intent | median s / pair |{extra}\n|---|---|---|---|---|---|---|---|---|"
        + ("---|" if several else "")
        + "\n"
    )

    def per_seed(r: dict) -> str:
        first = ", ".join(f"{v:.0f}" for v in r["first_by_seed"].values())
        within = ", ".join(f"{v:.0f}" for v in r["within_by_seed"].values())
        return f" {first} / {within}% |"

    body = "".join(
        f"| {r['method']} | {r['hand']} | {r['pairs']} | {r['first']:.0f}% | {r['within']:.0f}% "
        f"| {r['held']:.0f}% | {r['part_accuracy']:.0f}% | {r['intent']:.0f}% "
        f"| {r['median_s']:.1f} |{per_seed(r) if several else ''}\n"
        for r in rows
    )
    return head + body


def meetable_line(rows: list[dict]) -> str:
    """Below the table: where some pairs' definitions cannot be met on their part
    (Record.intent_meetable), the intent column over the others; "" if every one can."""
    if not any(r.get("unmeetable_pairs") for r in rows):
        return ""
    shares = ", ".join(
        f"{r['method']} {r['hand']} {r['intent_meetable']:.0f}% ({r['unmeetable_pairs']} "
        "pairs left out)"
        for r in rows
    )
    return (
        "\nMeets intent, of the grasps held on the part where its definition can be met "
        f"(planner.intent.unmeetable): {shares}\n"
    )


def intent_line(rows: list[dict]) -> str:
    """Below the table: the intent column per intent, per method and hand."""
    shares = "; ".join(
        f"{r['method']} {r['hand']} "
        + ", ".join(f"{i} {v:.0f}%" for i, v in r.get("intent_by_intent", {}).items())
        for r in rows
        if r.get("intent_by_intent")
    )
    return (
        f"\nMeets intent per intent, of the grasps held on the part: {shares}\n" if shares else ""
    )


def uncertain_line(rows: list[dict]) -> str:
    """Below the table: per method and hand, the uncertain grasps returned (PlanResult.status;
    counted neither as held nor within) and how many held on the object; "" if none."""
    unsure = [r for r in rows if r.get("uncertain")]
    if not unsure:
        return ""
    counts = ", ".join(
        f"{r['method']} {r['hand']} {r['uncertain_held']} of {r['uncertain']}" for r in unsure
    )
    return (
        "\nUncertain grasps returned (held on the cloud, slipped on a cloud check; not counted "
        f"above), held on the object: {counts}\n"
    )


def report(rows: list[dict], candidates: int) -> str:
    """The table and the lines printed below it (meetable, per intent, uncertain)."""
    return table(rows, candidates) + meetable_line(rows) + intent_line(rows) + uncertain_line(rows)


def write_report(out: Path, title: str, text: str, rows: list[dict]) -> None:
    """OUT/table.md and OUT/bars.png: what a run, or runs joined, leave beside their records."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "table.md").write_text(f"{title}\n\n{text}")
    bars(rows, out / "bars.png", title)


def bars(rows: list[dict], path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    methods = list(dict.fromkeys(r["method"] for r in rows))
    hands = sorted({r["hand"] for r in rows})
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6), sharey=True)
    width = 0.8 / max(len(methods), 1)
    for ax, metric, label in ((axes[0], "first", "first sample"), (axes[1], "within", "within N")):
        for k, method in enumerate(methods):
            values = [
                next((r[metric] for r in rows if r["method"] == method and r["hand"] == h), 0)
                for h in hands
            ]
            ax.bar(np.arange(len(hands)) + k * width, values, width, label=method)
        ax.set_xticks(np.arange(len(hands)) + width * (len(methods) - 1) / 2, hands)
        ax.set_title(f"{label}: held on the instructed part")
        ax.set_ylim(0, 100)
    axes[0].set_ylabel("% of pairs")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=len(methods), fontsize=8)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout(rect=(0, 0.08, 1, 1))
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m eval.benchmark", description=__doc__.split("\n")[0])
    p.add_argument("--split", default="test", choices=("train", "val", "test", "heldout"))
    p.add_argument("--objects-per-category", type=int, default=1)
    p.add_argument("--hands", nargs="+", default=None, help="default: every built-in hand")
    p.add_argument("--methods", nargs="+", default=list(METHODS), choices=list(METHODS))
    p.add_argument("--categories", nargs="+", default=None, help="default: every category")
    p.add_argument(
        "--intents", nargs="+", default=None, choices=INTENTS, help="default: every intent"
    )
    p.add_argument("--paraphrase", action="store_true", help="evaluation-only rewordings")
    p.add_argument("--view", default="full", choices=VIEWS, help="what the methods are given")
    p.add_argument("--turn", action="store_true", help="turn every object (yaw, tilt <= 30 deg)")
    p.add_argument("--candidates", type=int, default=8, help="validations per pair at most")
    p.add_argument("--samples", type=int, default=16, help="learned proposals per pair")
    p.add_argument(
        "--seeds",
        type=int,
        nargs="+",
        default=[0],
        help="the learned methods' sample seeds (learned.seed): each pair is planned once per "
        "seed and the table pools them, with first / within per seed (the model-based "
        "planner draws nothing and runs once)",
    )
    p.add_argument(
        "--set",
        nargs="+",
        default=[],
        metavar="KEY=VALUE",
        help="planner settings for every method (dotted keys, planner.settings.with_overrides), "
        "e.g. learned.interaction_weights=runs/interaction to try a training run's weights",
    )
    p.add_argument("--workers", type=int, default=1)
    p.add_argument(
        "--out",
        default=None,
        help="records, summary, table, plot (default runs/benchmark); with --join: the joined "
        "table and plot only",
    )
    p.add_argument(
        "--join",
        nargs="+",
        default=None,
        metavar="DIR",
        help="plan nothing: print the table of these runs' records (their --out folders) "
        "joined, a later run's record replacing an earlier one's of the same pair, method and "
        "sample seed (a run of some intents, --intents, over a whole run)",
    )
    args = p.parse_args(argv)
    if args.join:
        missing = [f for f in args.join if not (Path(f) / "records.jsonl").is_file()]
        if missing:
            raise SystemExit(f"--join: no records.jsonl in {', '.join(missing)}")
        joined = {
            r.key: r
            for folder in args.join
            for r in read_records(Path(folder) / "records.jsonl", Record)
        }
        rows = summarise(list(joined.values()))
        text = report(rows, args.candidates)
        print(text)
        if args.out:  # the joined runs' table and plot, as one run writes its own
            out = Path(args.out)
            first = Path(args.join[0]) / "table.md"  # the first run's title: split, view, seeds
            title = first.read_text().split("\n")[0] if first.is_file() else "joined runs"
            write_report(out, title, text, rows)
            print(f"wrote {out / 'table.md'}, {out / 'bars.png'}")
        return 0
    hands = args.hands or available_hands()
    for h in hands:
        load_hand(h)  # an unknown hand fails here, before any work
    out = Path(args.out or "runs/benchmark")
    out.mkdir(parents=True, exist_ok=True)
    records_path = out / "records.jsonl"
    overrides = parse_overrides(args.set)
    try:  # an unknown key or a bad value fails here, before any work
        with_overrides(PlannerSettings(), overrides)
    except DrograspError as err:
        raise SystemExit(f"--set: {err}") from None
    if "learned.seed" in overrides:
        raise SystemExit("--set learned.seed: give the sample seeds with --seeds instead")
    folder = overrides.get("learned.interaction_weights")
    if folder and not (Path(folder) / "interaction.safetensors").is_file():
        raise SystemExit(
            f"--set learned.interaction_weights: no interaction.safetensors in {folder}"
        )
    todo_all = tasks(
        args.split,
        args.objects_per_category,
        hands,
        args.methods,
        args.paraphrase,
        args.candidates,
        args.samples,
        args.categories,
        args.view,
        args.turn,
        overrides,
        tuple(args.seeds),
        args.intents,
    )
    records = run_resumable(todo_all, run_task, records_path, Record, args.workers, "benchmark")
    rows = summarise(records)
    text = report(rows, args.candidates)
    words = "evaluation-only rewordings" if args.paraphrase else "canonical instructions"
    seen = VIEWS[args.view]
    title = (
        f"{args.split} split, {args.objects_per_category} object(s) per category, {words}, "
        f"{seen}{', turned' if args.turn else ''}"
        + (f", {' and '.join(args.intents)} only" if args.intents else "")
        + (f", sample seeds {', '.join(map(str, args.seeds))}" if len(args.seeds) > 1 else "")
    )
    summary = {
        "split": args.split,
        "objects_per_category": args.objects_per_category,
        "paraphrase": args.paraphrase,
        "intents": args.intents,
        "view": args.view,
        "turn": args.turn,
        "candidates": args.candidates,
        "samples": args.samples,
        "seeds": args.seeds,
        "settings": overrides,
        "rows": rows,
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    write_report(out, title, text, rows)
    print(f"\n{title}\n\n{text}")
    print(f"wrote {out / 'summary.json'}, {out / 'table.md'}, {out / 'bars.png'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
