"""Train/val/test splits: instances 8:1:1 within each category, and whole held-out categories.

Seeds are split in blocks of ten: every block 0-9, 10-19, ... holds exactly 8 train, 1 val and
1 test seed, at positions shuffled per (category, block), so any seed range is split 8:1:1.
Held-out categories never appear in training; all their instances are "heldout".
"""

from __future__ import annotations

import zlib

import numpy as np

from ..errors import ObjectError
from .library import category, check_seed
from .names import HELDOUT, SPLITS

_BLOCK = ("train",) * 8 + ("val", "test")


def split_of(category_name: str, seed: int) -> str:
    """'train', 'val', 'test' (instance splits) or 'heldout' (the whole category is held out)."""
    name = category(category_name).name
    if name in HELDOUT:
        return "heldout"
    block, pos = divmod(check_seed(seed), len(_BLOCK))
    rng = np.random.default_rng([zlib.crc32(f"split:{name}".encode()), block])
    return _BLOCK[int(rng.permutation(len(_BLOCK))[pos])]


def seeds(category_name: str, split: str, count: int, start: int = 0) -> list[int]:
    """The first `count` seeds from `start` on that fall in `split` (empty if it never can)."""
    if split not in SPLITS:
        raise ObjectError(f"unknown split {split!r}; choose one of {SPLITS}")
    start = check_seed(start)
    name = category(category_name).name
    if (split == "heldout") != (name in HELDOUT):
        return []
    out, s = [], start
    while len(out) < count:
        if split_of(name, s) == split:
            out.append(s)
        s += 1
    return out
