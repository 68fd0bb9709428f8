"""Names of the library's categories, splits and intents, importable without the geometry libraries.

The CLI offers these as choices at start-up, which must not wait for trimesh and manifold3d;
`tests/test_objects_library.py` checks that they equal the library's own.
"""

from __future__ import annotations

CATEGORY_NAMES: tuple[str, ...] = (
    "mug",
    "cup",
    "bottle",
    "bowl",
    "wine_glass",
    "teapot",
    "knife",
    "hammer",
    "screwdriver",
    "pen",
    "scissors",
    "spray_bottle",
    "lotion_pump",
    "pan",
)
HELDOUT: tuple[str, ...] = ("teapot", "screwdriver")
SPLITS: tuple[str, ...] = ("train", "val", "test", "heldout")
INTENTS: tuple[str, ...] = ("Use", "Hold", "Handover", "Liftup")


def categories() -> tuple[str, ...]:
    """Names of every category in the library, in a fixed order (as `library.categories`)."""
    return CATEGORY_NAMES
