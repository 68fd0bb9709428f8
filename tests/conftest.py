"""Shared test fixtures: hand names and the optional third-party reference folder."""

from __future__ import annotations

from pathlib import Path

import pytest

from models.errors import ObjectError
from models.hands import available_hands
from models.objects.loading import import_open3d

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


@pytest.fixture
def needs_open3d() -> None:
    """Skip where Open3D cannot load its system libraries (libusb, libGL): single views are
    rendered with its ray casting, and a slim machine may lack them."""
    try:
        import_open3d("rendering single views")
    except ObjectError as err:
        pytest.skip(str(err))
