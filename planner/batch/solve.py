"""The default job function: one Job -> one result record (plain JSON data).

Everything in a record except `times` depends only on the job, so a batch gives the same
records on any number of workers. Objects and planners are cached per worker process, and jobs
arrive ordered by (object, hand), so Drake programs and MuJoCo scenes are built once per pair.
"""

from __future__ import annotations

import json
from functools import lru_cache
from typing import Any

import numpy as np

from models.grasp import Grasp
from models.hands import load_hand
from models.objects import ObjectModel, parse_instruction
from planner.batch.jobs import Job
from planner.batch.transfer import transfer_grasp
from planner.batch.variants import VariantPlanner
from planner.intent import check_intent
from planner.objectref import resolve_object
from planner.settings import PlannerSettings, ScheduleSettings

NONDETERMINISTIC_KEYS = ("wall_time",)  # measured, not computed: moved into `times`


def jsonable(value: Any) -> Any:
    """Numpy scalars and arrays, tuples and nested dicts as plain JSON data."""
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating):
        return float(value)
    return value


def _strip_measured(validation: dict[str, Any] | None, times: dict[str, float]) -> dict | None:
    if validation is None:
        return None
    out = dict(validation)
    for key in NONDETERMINISTIC_KEYS:
        if key in out:
            times[f"validation_{key}"] = float(out.pop(key))
    return out


@lru_cache(maxsize=8)
def cached_object(key: str) -> ObjectModel:
    return resolve_object(json.loads(key))


def job_object(job: Job) -> ObjectModel:
    return cached_object(json.dumps(job.object, sort_keys=True))


@lru_cache(maxsize=64)
def cached_planner(
    hand: str, max_candidates: int, protocol: str, variant: int, validate_all: bool
) -> VariantPlanner:
    settings = PlannerSettings(
        protocol=protocol,
        schedule=ScheduleSettings(max_candidates=max_candidates, validate_all=validate_all),
    )
    return VariantPlanner(hand, settings, variant)


def _grasp_record(grasp: Grasp | None) -> dict[str, Any] | None:
    if grasp is None:
        return None
    data = grasp.to_dict()
    metrics = dict(data["metrics"])
    metrics["validation"] = _strip_measured(metrics.get("validation"), {})
    data["metrics"] = metrics
    return jsonable(data)


def solve_job(job: Job) -> dict[str, Any]:
    """Plan (or transfer) one job and describe the outcome. Raises on bad input; the runner
    records the error."""
    obj = job_object(job)
    instruction = parse_instruction(job.instruction)
    times: dict[str, float] = {}
    if job.source is not None:
        return _transfer(job, obj, instruction.part, times)
    planner = cached_planner(
        job.hand, job.max_candidates, job.protocol, job.variant, job.validate_all
    )
    result = planner.plan(obj, instruction)
    for key, value in result.stage_times().items():
        times[key] = float(value)
    best = result.best
    validation = _strip_measured(None if best is None else best.validation, times)
    record = {
        "success": bool(result.success),
        "part_voted": result.part_touched,
        "part_instructed": instruction.part,
        "valid": bool(result.success and result.part_touched == instruction.part),
        "intent_ok": result.intent_ok,
        "proposal": None if best is None else planner.proposal_index(best.rank),
        "candidates_tried": len(result.candidates),
        "anchor_error": None if best is None else float(best.solve.anchor_error),
        "min_distance": None if best is None else float(best.solve.min_distance),
        "validation": jsonable(validation),
        "grasp": _grasp_record(result.grasp),
        "notes": list(result.notes),
        "times": times,
    }
    if job.validate_all:  # every holding grasp on the part, the returned one first
        record["holding"] = [
            {
                "proposal": planner.proposal_index(c.rank),
                "anchor_error": float(c.solve.anchor_error),
                "min_distance": float(c.solve.min_distance),
                "validation": jsonable(_strip_measured(c.validation, {})),
                "grasp": _grasp_record(c.grasp),
            }
            for c in result.holding
        ]
    return record


def _transfer(job: Job, obj: ObjectModel, part: str, times: dict[str, float]) -> dict[str, Any]:
    assert job.source is not None
    source = Grasp.from_dict(job.source["grasp"])
    done = transfer_grasp(source, job.hand, obj, source=job.source["hand"], protocol=job.protocol)
    times.update({k: float(v) for k, v in done.times.items()})
    if done.grasp is not None and obj.labelled:  # the transferred grasp against its intent
        check = check_intent(done.grasp, obj, load_hand(job.hand), job.instruction)
        done.grasp.metrics.update(intent_ok=check.ok, intent=check.to_dict())
    validation = _strip_measured(done.validation, times)
    return {
        "success": done.success,
        "part_voted": done.part,
        "part_instructed": part,
        "valid": bool(done.success and done.part == part),
        "intent_ok": None if done.grasp is None else done.grasp.metrics.get("intent_ok"),
        "proposal": None,
        "candidates_tried": 1,
        "anchor_error": float(done.solve.anchor_error),
        "min_distance": float(done.solve.min_distance),
        "validation": jsonable(validation),
        "grasp": _grasp_record(done.grasp),
        "notes": [] if done.solve.ok else [f"transfer solve rejected: {done.solve.message}"],
        "times": times,
    }
