"""Typed errors shared by the whole project.

Every error a user can cause derives from DrograspError, so the CLI can print the
message (which says what was wrong and how to fix it) instead of a stack trace.
"""


class DrograspError(Exception):
    """Base class: a user-facing problem with a message that says how to fix it."""


class HandError(DrograspError, ValueError):
    """Unknown hand, malformed hand files, or a joint vector that does not fit the hand."""


class ObjectError(DrograspError, ValueError):
    """An object (mesh or cloud) that cannot be used: empty, NaN, wrong unit, unreadable."""


class GraspError(DrograspError, ValueError):
    """A grasp record that is malformed (wrong lengths, NaN, unknown fields)."""


class InstructionError(DrograspError, ValueError):
    """An empty or unparseable instruction."""


class PlanningError(DrograspError, RuntimeError):
    """No grasp could be found; the message says what was tried."""
