"""Grasp files in DexGraspBench's layout: read the arrays, turn row i into (Grasp, object).

The `validate` command, the validation benchmark and the tests all read the reference grasps
this one way.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from models.errors import GraspError
from models.grasp import Grasp, from_dexgraspbench
from planner.validation.hands import HandAdapter
from planner.validation.objects import CollisionObject, find_object

LAYOUT_KEYS = ("object", "scale", "pregrasp_qpos", "grasp_qpos", "squeeze_qpos")


def read_rows(path: Path, limit: int | None = None) -> dict[str, np.ndarray]:
    """The arrays of a grasps NPZ (first `limit` rows), checked for the layout's keys."""
    import zipfile

    from models.paths import input_file

    if not Path(path).expanduser().exists():
        raise GraspError(f"{path}: no such grasps file")
    path = input_file(path, "grasps file", GraspError)
    try:
        with np.load(path, allow_pickle=False) as npz:
            rows = {k: npz[k] for k in npz.files}
    except (ValueError, OSError, EOFError, KeyError, zipfile.BadZipFile) as err:
        raise GraspError(
            f"{path}: not a readable NPZ without pickle ({type(err).__name__}: {err}); is the "
            "file complete?"
        ) from None
    missing = [k for k in LAYOUT_KEYS if k not in rows]
    if missing:
        raise GraspError(f"{path}: missing arrays {missing} of DexGraspBench's layout")
    if rows["scale"].dtype.kind not in "iuf":
        raise GraspError(f"{path}: scale must hold numbers, got {rows['scale'].dtype}")
    for key in ("pregrasp_qpos", "grasp_qpos", "squeeze_qpos"):
        if rows[key].ndim != 2 or rows[key].dtype.kind not in "iuf":
            raise GraspError(
                f"{path}: {key} must be a 2-D array of numbers, got {rows[key].dtype} {rows[key].shape}"
            )
    count = len(rows["grasp_qpos"])
    for key, arr in rows.items():
        if key in LAYOUT_KEYS and (arr.ndim == 0 or len(arr) != count):
            raise GraspError(f"{path}: {key} has {arr.shape} rows, grasp_qpos {count}")
    n = len(rows["grasp_qpos"]) if limit is None else min(limit, len(rows["grasp_qpos"]))
    return {k: v[:n] if v.ndim and len(v) >= n else v for k, v in rows.items()}


def row_case(
    rows: Mapping[str, np.ndarray],
    i: int,
    hand: HandAdapter,
    xml_joint_names: Sequence[str],
    objects_dir: str | Path,
    joint_map: Mapping[str, str] | None = None,
) -> tuple[Grasp, CollisionObject]:
    """Row i as a Grasp for `hand` and its scaled object from `objects_dir`.

    The rows' root pose is taken as the hand's wrist pose as it is (identity root offset): the
    validator simulates `hand` itself, whose free root is the frame the rows place (an MJCF
    file's root frame, as DexGraspBench does, or a project hand's root link).
    """
    grasp = from_dexgraspbench(
        rows["pregrasp_qpos"][i],
        rows["grasp_qpos"][i],
        rows["squeeze_qpos"][i],
        root_offset=np.eye(4),
        hand=hand.name,
        joint_names=hand.joint_names,
        xml_joint_names=xml_joint_names,
        joint_map=joint_map,
    )
    obj = find_object(objects_dir, str(rows["object"][i]), float(rows["scale"][i]))
    return grasp, obj
