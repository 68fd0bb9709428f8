"""Argument types and checks shared by the commands, light to import (no numpy, torch, Drake).

Argparse reports a bad value of these types as a usage error (exit code 2) before any work.
"""

from __future__ import annotations

import argparse
import math


def _int(text: str, low: int, what: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if value < low:
        raise argparse.ArgumentTypeError(f"must be {what}, got {value}")
    return value


def positive_int(text: str) -> int:
    """A whole number of at least 1."""
    return _int(text, 1, "at least 1")


def non_negative_int(text: str) -> int:
    """A whole number of at least 0 (seeds, counts that may be zero)."""
    return _int(text, 0, "0 or more")


def positive_float(text: str) -> float:
    """A finite number above 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text}")
    return value


def share(text: str) -> float:
    """A fraction from 0 to 1 (shares of steps, probabilities)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"must be between 0 and 1, got {text}")
    return value


PRESET_NAMES = ("dexgraspbench", "paper")  # planner.validation.protocol.PRESETS, checked in tests
