"""MuJoCo grasp validation following DexGraspBench's protocol (see protocol.py).

Names resolve on first use, so that `planner.validation.protocol` (settings only) imports
without MuJoCo.
"""

from __future__ import annotations

import importlib
from typing import Any

_WHERE = {
    "HandAdapter": "hands",
    "as_hand": "hands",
    "mjcf_hand": "hands",
    "project_hand": "hands",
    "CollisionObject": "objects",
    "as_collision_object": "objects",
    "find_object": "objects",
    "PRESETS": "protocol",
    "Protocol": "protocol",
    "get_protocol": "protocol",
    "DirectionResult": "validator",
    "ValidationResult": "validator",
    "validate": "validator",
}

__all__ = sorted(_WHERE)


def __getattr__(name: str) -> Any:
    module = _WHERE.get(name)
    if module is None:
        raise AttributeError(f"module 'planner.validation' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_WHERE))
