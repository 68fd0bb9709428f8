"""Planning: the Drake grasp program, MuJoCo validation, the functional planner and the CLI.

`from planner import plan_grasp, PlannerSettings` is the entry point; names are resolved
lazily so that light imports (such as the CLI's argument parsing) do not load Drake and MuJoCo.
"""

from typing import Any

# the settings (planner.settings) by name, beside plan_grasp
SETTINGS = (
    "PlannerSettings",
    "ScheduleSettings",
    "ProposalSettings",
    "IntentSettings",
    "LearnedSettings",
    "ProgramSettings",
    "with_overrides",
)
__all__ = ["plan_grasp", *SETTINGS]


def __getattr__(name: str) -> Any:
    if name == "plan_grasp":
        from planner.api import plan_grasp  # planner.functional's, with its arguments checked

        return plan_grasp
    if name in SETTINGS:
        import planner.settings

        return getattr(planner.settings, name)
    raise AttributeError(f"module 'planner' has no attribute {name!r}")
