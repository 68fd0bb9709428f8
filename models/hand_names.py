"""The built-in hands' names, and a hand argument checked, without importing the hand models.

`models.hands` imports torch (seconds); the CLI offers and checks hand names at start-up, and a
jobs file is checked before a batch starts, so the names are read from the folders here.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

from models.errors import HandError


def hands_folder() -> Path:
    spec = importlib.util.find_spec("models.hands")  # imports `models`, not `models.hands`
    assert spec is not None and spec.submodule_search_locations
    return Path(list(spec.submodule_search_locations)[0])


def builtin_hands() -> list[str]:
    """Names of the built-in hands (folders holding hand.json), as `available_hands()`."""
    return sorted(p.parent.name for p in hands_folder().glob("*/hand.json"))


def check_hand_name(hand: object) -> str:
    """A built-in hand's name or a folder holding hand.json and hand.urdf, else a HandError."""
    if not isinstance(hand, str) or not hand.strip():
        raise HandError(f"a hand is a built-in name or a hand folder, got {hand!r}")
    if hand in builtin_hands():
        return hand
    folder = Path(hand).expanduser()
    try:
        if (folder / "hand.json").is_file() and (folder / "hand.urdf").is_file():
            return hand
    except (OSError, RuntimeError):
        pass
    raise HandError(
        f"unknown hand {hand!r}: use one of the built-in hands ({', '.join(builtin_hands())}) "
        "or a folder holding hand.urdf and hand.json"
    )
