"""Planning: the Drake grasp program, MuJoCo validation, the functional planner and the CLI.

`from planner import plan_grasp` is the entry point; it is resolved lazily so that light
imports (such as the CLI's argument parsing) do not load Drake and MuJoCo.
"""

from typing import Any

__all__ = ["plan_grasp"]


def __getattr__(name: str) -> Any:
    if name == "plan_grasp":
        from planner.api import plan_grasp  # planner.functional's, with its arguments checked

        return plan_grasp
    raise AttributeError(f"module 'planner' has no attribute {name!r}")
