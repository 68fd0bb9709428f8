"""Every intent each dataset grasp meets, not only its own: `drograsp dataset check-intents`.

A grasp planned for one intent often meets another's definition on the same part (a mug body
grasp made for Hold may also leave the handle free enough for Handover). The learned stages
can then learn it for every intent it serves (`drograsp train interaction --relabel`), and
learn less from grasps that meet none. The verdicts are written beside the blocks, one file
per block (`DIR/intents/NAME.npz`, array `intents_met`, rows x the dataset's intents: 1 met,
0 not, -1 no instruction of the table asks that intent of that part; columns as
models.objects.INTENTS), so the committed blocks
stay as they were made and the job resumes block by block; each file names the block's SHA-256,
so a block made again is checked again. `drograsp dataset generate` checks each block it adds.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from learned.dataset import block_digest, block_path, intents_path, read_intents, read_meta
from models.hands import HandModel, load_hand
from models.objects import INTENTS, TABLE, ObjectModel, instruction_text, make_object
from planner.batch.executors import one_thread
from planner.intent import check_configuration


def block_intents(root: str | Path, name: str) -> np.ndarray:
    """(rows, 4) verdicts for one block, columns in the order of models.objects.INTENTS."""
    meta = read_meta(root)
    with np.load(block_path(root, name), allow_pickle=False) as npz:
        a = {k: npz[k] for k in ("category", "seed", "hand", "part", "wrist", "q_grasp")}
    out = np.full((len(a["hand"]), len(INTENTS)), -1, dtype=np.int8)
    objects: dict[tuple[str, int], ObjectModel] = {}
    hands: dict[str, HandModel] = {}
    for r in range(len(out)):
        cat = meta["categories"][a["category"][r]]
        part = meta["parts"][a["part"][r]]
        asked = [i for i, p in TABLE.get(cat, ()) if p == part]
        if not asked:
            continue
        key = (cat, int(a["seed"][r]))
        if key not in objects:
            objects[key] = make_object(*key)
        name_ = meta["hands"][a["hand"][r]]
        if name_ not in hands:
            hands[name_] = load_hand(name_)
        hand = hands[name_]
        wrist, q = a["wrist"][r].astype(float), a["q_grasp"][r][: hand.dof].astype(float)
        for intent in asked:
            text = instruction_text(intent, cat, part)
            ok = check_configuration(wrist, q, objects[key], hand, text).ok
            out[r, INTENTS.index(intent)] = int(ok)
    return out


def _write(root: str, name: str) -> tuple[str, int]:
    path = intents_path(root, name)
    path.parent.mkdir(parents=True, exist_ok=True)
    digest = block_digest(root, name)
    met = block_intents(root, name)
    tmp = path.with_suffix(".tmp.npz")
    np.savez_compressed(tmp, intents_met=met, block_sha256=np.array(digest))
    os.replace(tmp, path)  # a stopped job leaves no half-written file
    return name, len(met)


def pending_blocks(root: str | Path) -> list[str]:
    """The blocks without verdicts, or whose verdicts were made for another version of them."""
    return [name for name in read_meta(root)["blocks"] if read_intents(root, name) is None]


def check_intents(
    root: str | Path,
    workers: int = 1,
    progress: Callable[[str, int], None] | None = None,
    blocks: list[str] | None = None,
) -> list[str]:
    """Write the verdicts of `blocks` (default: `pending_blocks`); returns the blocks written.
    `progress(block, rows)` is called as each block is done."""
    root = str(root)
    todo = pending_blocks(root) if blocks is None else blocks
    many = workers > 1 and len(todo) > 1
    pool = ProcessPoolExecutor(workers, initializer=one_thread) if many else None
    done = []
    try:
        for name, rows in (pool.map if pool else map)(_write, [root] * len(todo), todo):
            done.append(name)
            if progress:
                progress(name, rows)
    finally:
        if pool:
            pool.shutdown()
    return done
