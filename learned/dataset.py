"""The functional grasp dataset: compact arrays in blocks, a torch Dataset, and its counts.

A dataset folder holds `meta.json` (format, name tables, the list of blocks) and one
`blocks/<name>.npz` per block (no pickle). A block is what one generation step added (a range
of object seeds), so a dataset grows block by block across sessions and machines, and a git
commit of a grown dataset adds only the new block's file. Rows carry their split; a split is the
concatenation of its rows over all blocks, in block order. Name tables only ever grow (new names
are appended), so the indices of earlier blocks stay valid. Objects are not stored: each row
names a library (category, seed), and `models.objects.make_object` regenerates it. Joint arrays
are padded to the largest hand's DoF with a mask, so hands of different DoF share one array.
Written by `planner.batch.dataset` (`drograsp dataset compact|generate`).
"""

from __future__ import annotations

import hashlib
import io
import json
import zipfile
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch.utils.data import Dataset

from models.errors import DrograspError
from models.objects.names import INTENTS

FORMAT = "drograsp-grasps/3"
# formats this code reads: /2 has no intent_ok column (read as -1, unknown)
READABLE_FORMATS: tuple[str, ...] = ("drograsp-grasps/2", FORMAT)
SPLIT_NAMES: tuple[str, ...] = ("train", "val", "test", "heldout")
SOURCES: tuple[str, ...] = ("plan", "transfer")
METRICS: tuple[str, ...] = (
    "anchor_error",  # m, worst anchor fingertip to anchor point
    "min_distance",  # m, hand-object signed distance at the grasp
    "translation",  # m, worst object displacement in validation
    "rotation_deg",  # worst object rotation in validation
    "grasp_penetration",  # m
    "contact_count",  # hand bodies in contact at the grasp
)
# name -> (dtype, trailing shape or None for per-row scalars; "dof" = padded joint count)
ARRAYS: dict[str, tuple[str, tuple]] = {
    "split": ("int8", ()),  # index into SPLIT_NAMES
    "hand": ("int16", ()),
    "category": ("int16", ()),
    "seed": ("int32", ()),
    "instruction": ("int16", ()),
    "intent": ("int8", ()),
    "part": ("int16", ()),  # voted part (equals the instructed part in a valid grasp)
    "source": ("int8", ()),  # index into SOURCES
    "variant": ("int16", ()),  # planner variant; -1 for transfers
    "wrist": ("float32", (7,)),  # xyz + quaternion wxyz
    "q_grasp": ("float32", ("dof",)),
    "q_pregrasp": ("float32", ("dof",)),
    "q_squeeze": ("float32", ("dof",)),
    "dof_mask": ("bool", ("dof",)),
    "anchors": ("float32", (4, 3)),  # object points nearest the 4 anchor fingertips
    "metrics": ("float32", (len(METRICS),)),
    # the grasp meets its intent's definition (planner.intent): 1 yes, 0 no, -1 not checked
    "intent_ok": ("int8", ()),
    # every intent the grasp meets on its part, columns as models.objects.INTENTS: 1 yes, 0 no,
    # -1 not asked of this part by the table or not checked. Kept beside the blocks
    # (intents/NAME.npz, `drograsp dataset check-intents`), not in them.
    "intents_met": ("int8", (len(INTENTS),)),
}
# columns that older formats (or a block without its intents file) lack, and their fill
ADDED_COLUMNS: dict[str, int] = {"intent_ok": -1, "intents_met": -1}


class DatasetError(DrograspError, ValueError):
    """A dataset folder that is missing, of another format, or inconsistent."""


@dataclass
class GraspArrays:
    """One split: the arrays of ARRAYS plus the name tables of meta.json."""

    split: str
    arrays: dict[str, np.ndarray]
    meta: dict[str, Any]

    def __len__(self) -> int:
        return int(len(self.arrays["hand"]))

    def names(self, table: str, column: str | None = None) -> list[str]:
        """Per-row names: e.g. names("hands", "hand") -> ["leap", "shadow", ...]."""
        values = self.meta[table]
        return [values[i] for i in self.arrays[column or table.rstrip("s")]]


def read_meta(root: str | Path) -> dict[str, Any]:
    path = Path(root) / "meta.json"
    if not path.is_file():
        raise DatasetError(
            f"{root}: no dataset here (meta.json missing); make one with `drograsp dataset "
            "generate` or `drograsp dataset compact`"
        )
    try:
        meta = json.loads(path.read_bytes().decode("utf-8"))
    except (ValueError, OSError) as err:
        raise DatasetError(
            f"{path} is damaged ({type(err).__name__}: {err}); restore it (e.g. `git checkout "
            "-- meta.json` for a committed dataset) or make the dataset again"
        ) from None
    if not isinstance(meta, dict):
        raise DatasetError(f"{path} is damaged (not a JSON object); restore it or make it again")
    if meta.get("format") not in READABLE_FORMATS:
        raise DatasetError(
            f"{path}: format {meta.get('format')!r}, this code reads {READABLE_FORMATS}"
        )
    return meta


def block_path(root: str | Path, name: str) -> Path:
    return Path(root) / "blocks" / f"{name}.npz"


def intents_path(root: str | Path, name: str) -> Path:
    """A block's `intents_met` verdicts (planner.batch.intents)."""
    return Path(root) / "intents" / f"{name}.npz"


def block_digest(root: str | Path, name: str) -> str:
    """SHA-256 of a block's file: the intents verdicts name the block they were made for, so a
    block made again (`dataset refresh`) does not silently keep another block's verdicts."""
    return hashlib.sha256(block_path(root, name).read_bytes()).hexdigest()


def read_intents(root: str | Path, name: str, digest: str | None = None) -> np.ndarray | None:
    """A block's `intents_met` verdicts, or None where it has none made for it as it is now
    (`digest`: the block's `block_digest`, where the caller has read the block already)."""
    side = intents_path(root, name)
    if not side.is_file():
        return None
    try:
        with np.load(side, allow_pickle=False) as npz:
            met, made_for = npz["intents_met"], str(npz["block_sha256"])
    except (ValueError, OSError, EOFError, KeyError, zipfile.BadZipFile) as err:
        raise DatasetError(
            f"{side} is damaged ({type(err).__name__}: {err}); delete it and run "
            "`drograsp dataset check-intents` again"
        ) from None
    return met if made_for == (digest or block_digest(root, name)) else None


def _read_block(root: str | Path, name: str, dof: int) -> dict[str, np.ndarray]:
    path = block_path(root, name)
    if not path.is_file():
        raise DatasetError(f"{path} missing: the dataset folder is incomplete")
    try:
        data = path.read_bytes()  # read once: loaded, and hashed for its intents verdicts
        with np.load(io.BytesIO(data), allow_pickle=False) as npz:
            arrays = {k: npz[k] for k in npz.files}
    except (ValueError, OSError, EOFError, KeyError, zipfile.BadZipFile) as err:
        raise DatasetError(
            f"{path} is damaged ({type(err).__name__}: {err}); restore it (`git checkout` for "
            "a committed dataset) or make its block again (`drograsp dataset generate` resumes)"
        ) from None
    n = len(arrays.get("hand", ()))
    for key, fill in ADDED_COLUMNS.items():
        if key not in arrays:
            dtype, shape = ARRAYS[key]
            arrays[key] = np.full((n, *shape), fill, dtype=dtype)
    met = read_intents(root, name, hashlib.sha256(data).hexdigest())  # made for it as it is
    if met is not None and met.shape == arrays["intents_met"].shape:
        arrays["intents_met"] = met
    missing = set(ARRAYS) - set(arrays)
    if missing:
        raise DatasetError(f"{path} lacks arrays {sorted(missing)}")
    n = len(arrays["hand"])
    for key, arr in arrays.items():
        if len(arr) != n:
            raise DatasetError(f"{path}: {key} has {len(arr)} rows, hand has {n}")
        if ARRAYS.get(key, (None, ()))[1][:1] == ("dof",) and arr.shape[1] < dof:
            arrays[key] = np.pad(arr, ((0, 0), (0, dof - arr.shape[1])))  # a block of smaller hands
    return arrays


def padded_dof(meta: dict[str, Any]) -> int:
    """The joint arrays' width: the largest DoF among the dataset's hands."""
    return max(meta.get("hand_dof", {}).values(), default=1)


# the name tables of meta.json and the array columns that index them
NAME_TABLES: dict[str, str] = {
    "hands": "hand",
    "categories": "category",
    "instructions": "instruction",
    "parts": "part",
}


def load_split(
    root: str | Path | Sequence[str | Path], split: str, blocks: int | None = None
) -> GraspArrays:
    """The arrays of one split over all blocks, or over each folder's first `blocks` in block
    order (the dataset as it stood then: what earlier weights were trained on). An empty split
    has zero rows. Several dataset folders (e.g. v1 and v2) read as one: their name tables are
    merged, so a row's hand, category, instruction and part names are its own folder's."""
    if not isinstance(root, str | Path):
        roots = list(root)
        if not roots:
            raise DatasetError("no dataset folder given")
        return _merged([load_split(r, split, blocks) for r in roots])
    meta = read_meta(root)
    if split not in SPLIT_NAMES:
        raise DatasetError(f"unknown split {split!r}; choose one of {SPLIT_NAMES}")
    dof = padded_dof(meta)
    parts = []
    for name in list(meta["blocks"])[:blocks]:
        block = _read_block(root, name, dof)
        keep = block["split"] == SPLIT_NAMES.index(split)
        parts.append({k: v[keep] for k, v in block.items()})
    if not parts:
        return GraspArrays(split, empty_arrays(dof), meta)
    arrays = {k: np.concatenate([p[k] for p in parts]) for k in ARRAYS}
    return GraspArrays(split, arrays, meta)


def _merged(splits: list[GraspArrays]) -> GraspArrays:
    """Splits of several folders as one: name tables united (the first folder's order first),
    each folder's index columns mapped into them, joint arrays padded to the widest hand."""
    meta = dict(splits[0].meta)
    for table in NAME_TABLES:
        meta[table] = list(dict.fromkeys(n for s in splits for n in s.meta[table]))
    meta["hand_dof"] = {k: v for s in splits for k, v in s.meta.get("hand_dof", {}).items()}
    dof = padded_dof(meta)
    parts = []
    for sp in splits:
        arrays = dict(sp.arrays)
        for table, column in NAME_TABLES.items():
            index = np.array([meta[table].index(n) for n in sp.meta[table]], dtype=np.int64)
            arrays[column] = (
                index[arrays[column]].astype(ARRAYS[column][0]) if len(index) else arrays[column]
            )
        for key, (_, shape) in ARRAYS.items():
            if shape[:1] == ("dof",) and arrays[key].shape[1] < dof:
                arrays[key] = np.pad(arrays[key], ((0, 0), (0, dof - arrays[key].shape[1])))
        parts.append(arrays)
    arrays = {k: np.concatenate([p[k] for p in parts]) for k in ARRAYS}
    return GraspArrays(splits[0].split, arrays, meta)


def empty_arrays(dof: int, n: int = 0) -> dict[str, np.ndarray]:
    """Zeroed arrays of ARRAYS for n rows, joints padded to `dof`."""
    out = {}
    for name, (dtype, shape) in ARRAYS.items():
        shape = tuple(dof if s == "dof" else s for s in shape)
        out[name] = np.zeros((n, *shape), dtype=dtype)
    return out


class GraspDataset(Dataset):
    """Validated functional grasps of one split as tensors, optionally for some hands only.

    An item: instruction text, hand name, category and seed (to regenerate the object), wrist
    (7), padded joints of the three phases with their DoF mask, anchors (4, 3), voted part,
    metrics (see METRICS)."""

    def __init__(self, root: str | Path, split: str = "train", hands: list[str] | None = None):
        self.data = load_split(root, split)
        keep = np.ones(len(self.data), dtype=bool)
        if hands is not None:
            table = self.data.meta["hands"]
            unknown = set(hands) - set(table)
            if unknown:
                raise DatasetError(f"hands {sorted(unknown)} not in the dataset ({table})")
            wanted = [table.index(h) for h in hands]
            keep = np.isin(self.data.arrays["hand"], wanted)
        self.rows = np.flatnonzero(keep)

    def __len__(self) -> int:
        return len(self.rows)

    def __getitem__(self, i: int) -> dict[str, Any]:
        r = int(self.rows[i])
        a, meta = self.data.arrays, self.data.meta
        item: dict[str, Any] = {
            "instruction": meta["instructions"][a["instruction"][r]],
            "hand": meta["hands"][a["hand"][r]],
            "category": meta["categories"][a["category"][r]],
            "seed": int(a["seed"][r]),
            "part": meta["parts"][a["part"][r]],
            "intent": meta["intents"][a["intent"][r]],
            "hand_index": int(a["hand"][r]),
        }
        for key in ("wrist", "q_grasp", "q_pregrasp", "q_squeeze", "anchors", "metrics"):
            item[key] = torch.from_numpy(a[key][r].astype(np.float32))
        item["intent_ok"] = int(a["intent_ok"][r])
        item["dof_mask"] = torch.from_numpy(a["dof_mask"][r].copy())
        return item


def dataset_info(root: str | Path) -> dict[str, Any]:
    """Counts of grasps per split, hand, category, intent and source (and per split x hand),
    and of the grasps meeting each intent's definition."""
    meta = read_meta(root)
    info: dict[str, Any] = {
        "root": str(root),
        "format": FORMAT,
        "total": 0,
        "splits": {},
        "hands": Counter(),
        "categories": Counter(),
        "intents": Counter(),
        "sources": Counter(),
        "split_hands": {},
        # grasps meeting each intent's definition whatever they were made for (intents_met),
        # those meeting none, and those not checked (`drograsp dataset check-intents`)
        "intents_met": dict.fromkeys(INTENTS, 0),
        "meets_none": 0,
        "intents_unchecked": 0,
    }
    for split in SPLIT_NAMES:
        data = load_split(root, split)
        info["splits"][split] = len(data)
        info["total"] += len(data)
        info["hands"].update(data.names("hands", "hand"))
        info["categories"].update(data.names("categories", "category"))
        info["intents"].update(data.names("intents", "intent"))
        info["sources"].update(SOURCES[s] for s in data.arrays["source"])
        info["split_hands"][split] = dict(sorted(Counter(data.names("hands", "hand")).items()))
        met = data.arrays["intents_met"]
        checked = (met >= 0).any(axis=1)
        for k, intent in enumerate(INTENTS):
            info["intents_met"][intent] += int((met[:, k] == 1).sum())
        info["meets_none"] += int((checked & ~(met == 1).any(axis=1)).sum())
        info["intents_unchecked"] += int((~checked).sum())
    for key in ("hands", "categories", "intents", "sources"):
        order = meta[key] if key in meta else SOURCES
        info[key] = {name: info[key].get(name, 0) for name in order}
    info["generator"] = meta.get("generator", {})
    return info
