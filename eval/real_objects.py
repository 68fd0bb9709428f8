"""The learned pipeline on real scanned meshes: free-form sentences, no part labels.

    python -m eval.real_objects --workers 2 [--view cloud|single|mesh] [--seeds 0 1 2]

The models were trained on the procedural library; a user brings scans. Every mesh under
`--objects` (default: ../shared/reference/objects, 12 YCB and 3 HOI4D meshes, third-party data
that never enters the repository; its manifest.csv gives each mesh's category, else the file's
stem is taken as the category) is planned with the sentences of its category (SENTENCES; any
other category: "pick up the <category>", "hold the <category>") for every hand and sample
seed. What the pipeline is given (`--view`):

- "cloud": 4096 points sampled from the mesh's surface (a fused scan; collision pieces from the
  cloud, and the planner's cloud checks);
- "single": what one depth camera sees (models.objects.views.single_view_object: 320 x 240 rays
  from 30 degrees above, 1 mm depth noise), completed by the planner;
- "mesh": the mesh itself, with pieces from its surface samples (most scans are open meshes,
  on which CoACD may never finish: `drograsp plan --pieces surface`).

MuJoCo then validates the returned grasp against pieces made from the mesh's own surface samples
(`collision_pieces("surface")`, the same for every view, so the "mesh" view's verdict is the
planner's own). These meshes carry no part labels: a grasp counts when it holds, wherever it
holds; Liftup's definition needs no labels and is checked where the sentence is read as Liftup
("pick up the can"). Records go to OUT/records.jsonl as they finish (an interrupted run
resumes); OUT/summary.json and OUT/table.md at the end; with `--pages`, a 3-D page of each
returned grasp on its mesh in OUT/pages (drograsp view's pages). With `--verdicts`, every
candidate the planner validated is validated on the mesh too, and a second table says how often
a candidate that held (or not) on what the planner was given holds on the mesh, per completion
of the view (swept, mirrored, as seen): how far to trust the planner's verdict.
"""

from __future__ import annotations

import argparse
import csv
import json
import statistics
import time
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from eval.runs import run_resumable
from models.hands import available_hands, load_hand
from models.objects import ObjectModel, load_object
from models.objects.intents import label_free
from models.objects.model import OpenMeshWarning
from models.objects.views import sampled_cloud_object, single_view_object
from planner.functional import FunctionalPlanner
from planner.intent import check_configuration
from planner.labels import grasp_part
from planner.settings import LearnedSettings, PlannerSettings
from planner.validation import validate

REFERENCE = Path(__file__).resolve().parents[1].parent / "shared" / "reference" / "objects"
CLOUD_POINTS = 4096  # as eval.benchmark's --view cloud and drograsp demo's clouds
VIEWS = {
    "cloud": f"{CLOUD_POINTS}-point clouds sampled from the meshes",
    "single": "single depth-camera views of the meshes, completed by the planner",
    "mesh": "the meshes, pieces from their surface samples",
}
MESH_SUFFIXES = (".obj", ".ply", ".stl", ".glb")
# categories whose handle is found on the mesh (`handle_labels`), so that a sentence naming the
# handle is scored on the part it touches: the points farther than HANDLE_MARGIN outside the
# body's outer wall at their height (its axis: vertical through the centroid of the points
# within HANDLE_BASE of the bottom, where no handle reaches; the wall: that quantile of the
# distances from the axis in slices of HANDLE_SLICE, the handle being the smaller share)
HANDLED = ("mug",)  # a pitcher's body is no solid of revolution: its spout reads as handle
HANDLE_MARGIN = 0.006  # m
HANDLE_SLICE = 0.01  # m
HANDLE_BASE = 0.003  # m
HANDLE_WALL_QUANTILE = 0.75

# two free-form sentences per category of the reference meshes; none is a table instruction
SENTENCES: dict[str, tuple[str, ...]] = {
    "mug": ("grab the mug by its handle", "pick up the mug"),
    "bottle": ("hold the bottle", "hand me the bottle by its cap"),
    "bowl": ("pick up the bowl", "hold the bowl by its rim"),
    "pitcher": ("grab the pitcher by its handle", "pick up the pitcher"),
    "can": ("pick up the can", "hold the soup can"),
    "box": ("pick up the box", "hold the cracker box"),
    "fruit": ("pick up the banana", "hold the banana"),
    "power_drill": ("hold the drill by its handle", "pick up the drill"),
    "scissors": ("hand me the scissors handles first", "use the scissors"),
    "pen": ("hold the marker", "use the marker"),
    "clamp": ("pick up the clamp", "hold the clamp"),
}


def sentences(category: str) -> tuple[str, ...]:
    """The sentences a mesh of `category` is planned with."""
    words = category.replace("_", " ")
    return SENTENCES.get(category, (f"pick up the {words}", f"hold the {words}"))


@dataclass(frozen=True)
class Task:
    """One (mesh, sentence, hand, sample seed) to plan; picklable for the pool."""

    path: str
    category: str
    text: str
    hand: str
    view: str
    sample_seed: int = 0
    pages: str | None = None  # a folder for a 3-D page of each returned grasp (None: none)
    verdicts: bool = False  # also validate every validated candidate on the mesh

    @property
    def key(self) -> tuple:
        return (
            Path(self.path).stem,
            self.text,
            self.hand,
            self.view,
            self.sample_seed,
            self.verdicts,
        )


@dataclass
class Record:
    mesh: str  # the file's stem
    category: str
    text: str
    hand: str
    view: str
    sample_seed: int
    understood: str | None = None  # the table instruction the sentence was read as
    # where the sentence names a handle found on the mesh (HANDLED): the part the returned
    # grasp's fingertips touch, "body" or "handle" (planner.labels.grasp_part); else None
    part_touched: str | None = None
    status: str = ""  # PlanResult.status: "holds", "uncertain" or "none"
    planned: bool = False  # the planner says its grasp holds (on what it was given)
    # the returned grasp (holding or uncertain) holds on the mesh's own pieces
    held: bool = False
    # Liftup read and checked without labels: the returned grasp meets it (None: not checked,
    # or no grasp)
    intent_ok: bool | None = None
    intent_reason: str = ""
    candidates: int = 0
    plan_time: float = 0.0
    stage_times: dict[str, float] = field(default_factory=dict)
    error: str = ""
    # a single view: how the planner completed it (models.objects.completion.Completion.kind)
    completion: str = ""
    # with --verdicts: per validated candidate, [held on what the planner was given (after
    # its cloud checks), held on the mesh]; None: not asked
    verdicts: list[list[bool]] | None = None

    @property
    def key(self) -> tuple:
        return (
            self.mesh,
            self.text,
            self.hand,
            self.view,
            self.sample_seed,
            self.verdicts is not None,
        )


def categories(folder: Path) -> dict[Path, str]:
    """Every mesh under `folder` with its category: manifest.csv's `file,category` columns
    where it has them, else the file's stem."""
    meshes = sorted(p for p in folder.rglob("*") if p.suffix.lower() in MESH_SUFFIXES)
    named: dict[str, str] = {}
    manifest = folder / "manifest.csv"
    if manifest.is_file():
        with manifest.open(newline="") as f:
            named = {row["file"]: row["category"] for row in csv.DictReader(f) if "file" in row}
    return {p: named.get(p.relative_to(folder).as_posix(), p.stem) for p in meshes}


_MESHES: dict[str, ObjectModel] = {}
_PLANNERS: dict[tuple, FunctionalPlanner] = {}


def mesh_object(path: str) -> ObjectModel:
    """The mesh, its collision pieces from its surface samples (loaded once per worker)."""
    if path not in _MESHES:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", OpenMeshWarning)
            _MESHES[path] = replace(load_object(path), pieces="surface")
    return _MESHES[path]


def handle_labels(obj: ObjectModel) -> ObjectModel | None:
    """The mesh's surface points as a cloud labelled "body" and "handle" (see HANDLED), or
    None where no point lies outside the wall."""
    pts = obj.points
    base = pts[:, 2] < pts[:, 2].min() + HANDLE_BASE
    centre = pts[base, :2].mean(axis=0)
    radius = np.linalg.norm(pts[:, :2] - centre, axis=1)
    level = np.floor((pts[:, 2] - pts[:, 2].min()) / HANDLE_SLICE).astype(int)
    wall = np.zeros(len(pts))
    for k in np.unique(level):
        wall[level == k] = np.quantile(radius[level == k], HANDLE_WALL_QUANTILE)
    handle = radius > wall + HANDLE_MARGIN
    if not handle.any():
        return None
    return ObjectModel(
        name=obj.name,
        cloud=pts,
        cloud_normals=obj.normals,
        cloud_labels=handle.astype(np.int64),
        part_names=("body", "handle"),
    )


def given(obj: ObjectModel, view: str, seed: int) -> ObjectModel:
    """What the pipeline is given of the mesh (`VIEWS`)."""
    if view == "cloud":
        return sampled_cloud_object(obj, CLOUD_POINTS, seed=seed)
    if view == "single":
        return single_view_object(obj, seed=seed)
    return obj


def run_task(task: Task) -> Record:
    rec = Record(
        Path(task.path).stem, task.category, task.text, task.hand, task.view, task.sample_seed
    )
    key = (task.hand, task.sample_seed)
    if key not in _PLANNERS:
        settings = PlannerSettings(
            proposer="learned", learned=LearnedSettings(seed=task.sample_seed)
        )
        _PLANNERS[key] = FunctionalPlanner(task.hand, settings)
    planner = _PLANNERS[key]
    try:
        obj = mesh_object(task.path)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", OpenMeshWarning)
            seen = given(obj, task.view, task.sample_seed)
            start = time.perf_counter()
            result = planner.plan(seen, task.text)
            rec.plan_time = time.perf_counter() - start
            pieces = obj.collision_pieces()
    except Exception as err:  # noqa: BLE001 - a benchmark records failures and goes on
        rec.error = f"{type(err).__name__}: {err}"[:300]
        return rec
    rec.understood = result.instruction.text
    rec.status = result.status
    rec.planned = bool(result.success)
    rec.candidates = len(result.candidates)
    rec.stage_times = {k: round(v, 4) for k, v in result.stage_times().items()}
    rec.completion = result.completed_by or ""
    judged: dict[int, bool] = {}  # id(grasp) -> held on the mesh, each grasp validated once

    def on_mesh(grasp) -> bool:
        if id(grasp) not in judged:
            judged[id(grasp)] = bool(validate(grasp, pieces, planner.hand, "paper").success)
        return judged[id(grasp)]

    if task.verdicts:
        rec.verdicts = [
            [bool(c.success), on_mesh(c.grasp)]
            for c in result.candidates
            if c.grasp is not None and c.validation is not None
        ]
    if result.grasp is not None and result.status != "none":
        rec.held = on_mesh(result.grasp)
        if rec.held and label_free(result.instruction.intent):
            grasp = result.grasp
            wrist = np.concatenate([grasp.wrist_pos, grasp.wrist_quat])
            check = check_configuration(
                wrist, np.asarray(grasp.grasp), obj, planner.hand, result.instruction
            )
            rec.intent_ok, rec.intent_reason = bool(check.ok), check.reason or ""
    if rec.held and task.category in HANDLED and "handle" in task.text:
        labelled = handle_labels(obj)
        if labelled is not None:
            grasp = result.grasp
            wrist = np.concatenate([grasp.wrist_pos, grasp.wrist_quat])
            rec.part_touched = grasp_part(planner.hand, wrist, np.asarray(grasp.grasp), labelled)
    if task.pages and result.grasp is not None:
        page(task, rec, result.grasp, obj, planner.hand)
    return rec


def page(task: Task, rec: Record, grasp, obj: ObjectModel, hand) -> Path:
    """The returned grasp on the mesh as a 3-D page (planner.viewer.write_html), captioned
    with the sentence, how it was read, the hand and the verdict on the mesh."""
    from planner.viewer import write_html

    slug = "_".join(task.text.lower().split())
    name = f"{rec.mesh}_{task.view}_{task.hand}_{slug}_s{task.sample_seed}.html"
    verdict = "holds on the mesh" if rec.held else f"does not hold on the mesh ({rec.status})"
    text = f'{rec.mesh}: "{task.text}" (read as {rec.understood}), {task.hand}: {verdict}'
    return write_html(grasp, obj, hand, Path(task.pages) / name, text)


def summarise(records: list[Record]) -> list[dict]:
    """Per hand: plans, held on the mesh (a grasp the planner returned as holding, as
    eval.benchmark counts: an uncertain one is counted apart, with how many of those held), the
    planner's own verdict against the mesh's, Liftup met and the handle touched (of the held),
    median time, errors."""
    rows = []
    for hand in sorted({r.hand for r in records}):
        rs = [r for r in records if r.hand == hand]
        said = [r for r in rs if r.planned]
        held = [r for r in said if r.held]
        unsure = [r for r in rs if r.status == "uncertain"]
        lifted = [r for r in held if r.intent_ok is not None]
        scored = [r for r in held if r.part_touched is not None]
        rows.append(
            {
                "hand": hand,
                "plans": len(rs),
                "held": 100.0 * len(held) / len(rs),
                "said_held": 100.0 * len(said) / len(rs),
                "said_and_held": 100.0 * len(held) / max(len(said), 1),
                "uncertain": len(unsure),
                "uncertain_held": sum(r.held for r in unsure),
                "liftup_met": None
                if not lifted
                else 100.0 * sum(bool(r.intent_ok) for r in lifted) / len(lifted),
                "liftup_checked": len(lifted),
                "on_handle": None
                if not scored
                else 100.0 * sum(r.part_touched == "handle" for r in scored) / len(scored),
                "handle_scored": len(scored),
                "median_s": statistics.median([r.plan_time for r in rs if not r.error] or [0.0]),
                "errors": sum(bool(r.error) for r in rs),
                "held_by_mesh": {
                    m: [sum(r in held for r in rs if r.mesh == m), sum(r.mesh == m for r in rs)]
                    for m in sorted({r.mesh for r in rs})
                },
            }
        )
    return rows


def table(rows: list[dict]) -> str:
    lines = [
        "| hand | plans | held on the mesh | said to hold | of those, held on the mesh | "
        "uncertain (held on the mesh) | Liftup met (of held) | on the handle (of held) | "
        "median s / plan | errors |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lift = (
            "-" if r["liftup_met"] is None else f"{r['liftup_met']:.0f}% of {r['liftup_checked']}"
        )
        handle = "-" if r["on_handle"] is None else f"{r['on_handle']:.0f}% of {r['handle_scored']}"
        lines.append(
            f"| {r['hand']} | {r['plans']} | {r['held']:.0f}% | {r['said_held']:.0f}% | "
            f"{r['said_and_held']:.0f}% | {r['uncertain']} ({r['uncertain_held']}) | {lift} | "
            f"{handle} | "
            f"{r['median_s']:.1f} | "
            f"{r['errors']} |"
        )
    per_mesh = "; ".join(
        f"{r['hand']}: " + ", ".join(f"{m} {h}/{n}" for m, (h, n) in r["held_by_mesh"].items())
        for r in rows
    )
    return "\n".join(lines) + f"\n\nHeld on the mesh, per mesh (of its plans): {per_mesh}\n"


def summarise_verdicts(records: list[Record]) -> list[dict]:
    """How far the planner's verdicts on what it was given hold on the mesh, over every
    validated candidate of the records with verdicts: per completion of the view ("" for
    clouds and meshes) and in all. A grasp planned on a guess is judged on the guess."""
    asked = [r for r in records if r.verdicts is not None]
    rows = []
    for kind in sorted({r.completion for r in asked}) + ["all"]:
        pairs = [v for r in asked if kind in ("all", r.completion) for v in r.verdicts]
        held = [mesh for view, mesh in pairs if view]
        slipped = [mesh for view, mesh in pairs if not view]
        rows.append(
            {
                "completion": kind or "none (a cloud or mesh)",
                "plans": sum(kind in ("all", r.completion) for r in asked),
                "candidates": len(pairs),
                "held": len(held),
                "held_on_mesh": sum(held),
                "slipped": len(slipped),
                "slipped_held_on_mesh": sum(slipped),
            }
        )
    return rows


def verdicts_table(rows: list[dict]) -> str:
    lines = [
        "| completion of the view | plans | candidates validated | held on the view | of those, "
        "held on the mesh | not held on the view | of those, held on the mesh |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        share = 100.0 * r["held_on_mesh"] / max(r["held"], 1)
        lines.append(
            f"| {r['completion']} | {r['plans']} | {r['candidates']} | {r['held']} | "
            f"{r['held_on_mesh']} ({share:.0f}%) | {r['slipped']} | {r['slipped_held_on_mesh']} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m eval.real_objects", description=__doc__.split("\n")[0]
    )
    p.add_argument(
        "--objects",
        default=str(REFERENCE),
        help="a folder of meshes (obj, ply, stl, glb), metres, z up; a manifest.csv with "
        "file,category columns names their categories (default: ../shared/reference/objects)",
    )
    p.add_argument("--view", default="cloud", choices=VIEWS, help="what the pipeline is given")
    p.add_argument("--categories", nargs="+", default=None, help="default: every mesh's")
    p.add_argument("--hands", nargs="+", default=None, help="default: every built-in hand")
    p.add_argument("--seeds", type=int, nargs="+", default=[0], help="sample seeds (learned.seed)")
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--out", default="runs/real_objects", help="records, summary, table")
    p.add_argument(
        "--pages",
        action="store_true",
        help="also write a 3-D page of each returned grasp on its mesh to OUT/pages",
    )
    p.add_argument(
        "--verdicts",
        action="store_true",
        help="also validate every validated candidate on the mesh: how far the planner's "
        "verdicts on what it was given hold, per completion of the view",
    )
    args = p.parse_args(argv)
    folder = Path(args.objects)
    if not folder.is_dir():
        raise SystemExit(
            f"--objects: no folder {folder}; give a folder of meshes (the default is the "
            "third-party reference data at ../shared/reference/objects)"
        )
    found = categories(folder)
    if args.categories:
        found = {p: c for p, c in found.items() if c in args.categories}
    if not found:
        raise SystemExit(
            f"--objects: no mesh (obj, ply, stl, glb) under {folder}"
            + (f" of the categories {', '.join(args.categories)}" if args.categories else "")
        )
    hands = args.hands or available_hands()
    for h in hands:
        load_hand(h)  # an unknown hand fails here, before any work
    out = Path(args.out)
    pages = str(out / "pages") if args.pages else None
    todo_all = [
        Task(str(path), cat, text, hand, args.view, seed, pages, args.verdicts)
        for path, cat in found.items()
        for text in sentences(cat)
        for hand in hands
        for seed in args.seeds
    ]
    out.mkdir(parents=True, exist_ok=True)
    records_path = out / "records.jsonl"
    records = run_resumable(todo_all, run_task, records_path, Record, args.workers, "real objects")
    rows = summarise(records)
    title = (
        f"{len(found)} meshes under {folder}, {VIEWS[args.view]}, "
        f"sample seeds {', '.join(map(str, args.seeds))}"
    )
    text = table(rows)
    summary = {"objects": str(folder), "view": args.view, "seeds": args.seeds, "rows": rows}
    if args.verdicts:
        summary["verdicts"] = summarise_verdicts(records)
        text += (
            "\nThe planner's verdicts against the mesh's, every validated candidate:\n\n"
            + verdicts_table(summary["verdicts"])
        )
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    (out / "table.md").write_text(f"{title}\n\n{text}")
    print(f"\n{title}\n\n{text}")
    print(f"wrote {out / 'summary.json'}, {out / 'table.md'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
