"""MuJoCo grasp validation following DexGraspBench's protocol (see protocol.py)."""

from planner.validation.hands import HandAdapter, as_hand, mjcf_hand, project_hand
from planner.validation.objects import CollisionObject, as_collision_object, find_object
from planner.validation.protocol import PRESETS, Protocol, get_protocol
from planner.validation.validator import DirectionResult, ValidationResult, validate

__all__ = [
    "PRESETS",
    "CollisionObject",
    "DirectionResult",
    "HandAdapter",
    "Protocol",
    "ValidationResult",
    "as_collision_object",
    "as_hand",
    "find_object",
    "get_protocol",
    "mjcf_hand",
    "project_hand",
    "validate",
]
