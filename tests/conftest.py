"""Shared test fixtures: hand names and the optional third-party reference folder."""

from __future__ import annotations

from pathlib import Path

import pytest

from models.hands import available_hands

REFERENCE = Path(__file__).resolve().parents[1].parent / "shared" / "reference"
HANDS = available_hands()


@pytest.fixture(params=HANDS)
def hand_name(request) -> str:
    return request.param


def reference_dir(*parts: str) -> Path:
    """A folder under ../shared/reference, or skip the test where it is absent."""
    path = REFERENCE.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"third-party reference data not present at {path}")
    return path
