"""The procedural library: part-labelled, watertight everyday objects, deterministic by seed.

`make_assembly(category, seed)` always returns the same mesh (to the byte, once exported) for the
same pair: the random generator is seeded from (crc32(category), seed), never from Python's hash().
Every object is upright as it rests on a table (+z up) with its bounding box centred at the origin;
long tools lie along x.
"""

from __future__ import annotations

import zlib
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ...errors import ObjectError
from . import drinkware, household, tools
from .assembly import Assembly, assemble
from .shapes import Solid


@dataclass(frozen=True)
class Category:
    """One object category: its id, the word used in instructions, its parts, and its builder."""

    name: str
    noun: str
    parts: tuple[str, ...]
    build: Callable[[np.random.Generator], dict[str, list[Solid]]]
    summary: str


def _cat(name: str, parts: tuple[str, ...], build: Callable, noun: str | None = None) -> Category:
    return Category(
        name, noun or name.replace("_", " "), parts, build, (build.__doc__ or "").strip()
    )


CATEGORIES: dict[str, Category] = {
    c.name: c
    for c in (
        _cat("mug", ("body", "handle"), drinkware.mug),
        _cat("cup", ("body", "rim"), drinkware.cup),
        _cat("bottle", ("body", "neck", "cap"), drinkware.bottle),
        _cat("bowl", ("body", "rim"), drinkware.bowl),
        _cat("wine_glass", ("bowl", "stem", "foot"), drinkware.wine_glass),
        _cat("teapot", ("body", "lid", "spout", "handle"), drinkware.teapot),
        _cat("knife", ("blade", "handle"), tools.knife),
        _cat("hammer", ("handle", "head"), tools.hammer),
        _cat("screwdriver", ("handle", "shaft"), tools.screwdriver),
        _cat("pen", ("tip", "barrel", "cap"), tools.pen),
        _cat("scissors", ("blade", "handle"), tools.scissors),
        _cat("spray_bottle", ("body", "head", "trigger"), household.spray_bottle),
        _cat("lotion_pump", ("body", "pump"), household.lotion_pump),
        _cat("pan", ("body", "handle"), household.pan),
    )
}


def categories() -> tuple[str, ...]:
    """Names of every category in the library, in a fixed order."""
    return tuple(CATEGORIES)


def category(name: str) -> Category:
    """The category called `name` (also accepts its noun, e.g. 'spray bottle')."""
    if not isinstance(name, str):
        raise ObjectError(
            f"the object category must be a name such as 'mug', got {name!r}; choose one of: "
            f"{', '.join(CATEGORIES)}"
        )
    key = name.strip().lower().replace(" ", "_")
    if key not in CATEGORIES:
        raise ObjectError(
            f"unknown object category {name!r}; choose one of: {', '.join(CATEGORIES)}"
        )
    return CATEGORIES[key]


def rng_for(name: str, seed: int) -> np.random.Generator:
    """The generator for (category, seed): stable across runs, machines and Python versions."""
    return np.random.default_rng([zlib.crc32(name.encode("utf-8")), check_seed(seed)])


def check_seed(seed: object) -> int:
    """A library seed: a non-negative integer (Python or numpy), else an ObjectError."""
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer):
        raise ObjectError(
            f"seed must be a non-negative integer (the instance number), got {seed!r}"
        )
    if int(seed) < 0:
        raise ObjectError(f"seed must be a non-negative integer, got {seed}")
    return int(seed)


def make_assembly(name: str, seed: int) -> Assembly:
    """Build the labelled watertight mesh and convex pieces of one instance."""
    cat = category(name)
    parts = cat.build(rng_for(cat.name, seed))
    assert tuple(parts) == cat.parts, (tuple(parts), cat.parts)
    return assemble(parts)


__all__ = ["Assembly", "CATEGORIES", "Category", "categories", "category", "make_assembly"]
