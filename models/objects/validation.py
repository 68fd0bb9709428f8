"""Checks that an object's coordinates can be grasped by a human-size hand, with fix-it messages."""

from __future__ import annotations

import numpy as np

from ..errors import ObjectError

MIN_POINTS = 64
MAX_EXTENT = 1.0  # metres
MIN_EXTENT = 0.01


def check_coordinates(
    points: np.ndarray, what: str = "cloud", min_points: int = MIN_POINTS
) -> np.ndarray:
    """Return the points as an (N, 3) float array, or raise ObjectError saying what to fix."""
    arr = np.asarray(points)
    if arr.ndim != 2 or arr.shape[1] != 3:
        if arr.size == 0:
            raise ObjectError(f"the {what} is empty: it has no points; give at least {min_points}")
        raise ObjectError(
            f"the {what} has shape {arr.shape}; expected (N, 3) coordinates in metres"
            " (drop extra columns such as colours, or reshape a flat array with .reshape(-1, 3))"
        )
    if len(arr) == 0:
        raise ObjectError(f"the {what} is empty: it has no points; give at least {min_points}")
    if not np.issubdtype(arr.dtype, np.number):
        raise ObjectError(f"the {what} has non-numeric dtype {arr.dtype}; give float coordinates")
    arr = arr.astype(float)
    bad = ~np.isfinite(arr).all(axis=1)
    if bad.any():
        raise ObjectError(
            f"the {what} has {int(bad.sum())} of {len(arr)} points with NaN or inf coordinates;"
            " remove them first, e.g. points[np.isfinite(points).all(axis=1)]"
        )
    if len(arr) < min_points:
        raise ObjectError(
            f"the {what} has only {len(arr)} points; at least {min_points} are needed to"
            " estimate its shape (sample the surface more densely)"
        )
    check_extent(arr, what)
    check_not_degenerate(arr, what)
    return arr


def check_extent(arr: np.ndarray, what: str) -> None:
    """Largest bounding-box side between 1 cm and 1 m; otherwise name the likely wrong unit."""
    extent = float(np.ptp(arr, axis=0).max())
    if extent > MAX_EXTENT:
        if extent > 50.0:
            unit, factor = "millimetres", "divide by 1000 (scale=0.001)"
        elif extent > 5.0:
            unit, factor = "centimetres", "divide by 100 (scale=0.01)"
        else:
            unit, factor = "too large for a hand or in another unit", "scale it to metres"
        raise ObjectError(
            f"the {what}'s largest extent {extent:.4g} exceeds 1 m: the input looks like {unit};"
            f" {factor}. Coordinates must be in metres."
        )
    if extent < MIN_EXTENT:
        raise ObjectError(
            f"the {what}'s largest extent {extent:.3g} m is below 1 cm: too small for a hand,"
            " or not in metres (was it normalised or given in another unit?); scale it to metres"
        )


def check_not_degenerate(arr: np.ndarray, what: str) -> None:
    """Reject points that all lie on a line or in a plane: no volume for fingers to close on."""
    centred = arr - arr.mean(axis=0)
    axes = np.linalg.svd(centred, full_matrices=False)[2]
    spans = np.ptp(centred @ axes.T, axis=0)
    floor = max(1e-4, 1e-3 * spans[0])
    if spans[1] < floor:
        raise ObjectError(
            f"the {what} is degenerate: its points are collinear (spread {spans[1]:.2g} m across"
            f" a {spans[0]:.3g} m line); give the surface of a 3-D object"
        )
    if spans[2] < floor:
        raise ObjectError(
            f"the {what} is degenerate: it is flat (thickness {spans[2]:.2g} m across"
            f" {spans[0]:.3g} m x {spans[1]:.3g} m); a single plane has no volume to grasp,"
            " give the full 3-D shape"
        )
