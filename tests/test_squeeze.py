"""Balanced squeeze forces (planner.squeeze): the net wrench cancels within the friction cones."""

from __future__ import annotations

import numpy as np
import pytest

from planner.squeeze import balanced_forces


def _net(points: np.ndarray, forces: np.ndarray) -> np.ndarray:
    centre = points.mean(axis=0)
    return np.concatenate([forces.sum(axis=0), np.cross(points - centre, forces).sum(axis=0)])


def _check_cones(forces: np.ndarray, inward: np.ndarray, mu: float) -> None:
    normal = np.einsum("ij,ij->i", forces, inward)
    tangential = np.linalg.norm(forces - normal[:, None] * inward, axis=1)
    assert np.all(normal >= 1 - 1e-9)
    assert np.all(tangential <= mu * normal + 1e-9)


def test_opposed_pinch_keeps_equal_pushes():
    points = np.array([[-0.02, 0, 0], [0.02, 0, 0]])
    inward = np.array([[1.0, 0, 0], [-1.0, 0, 0]])
    forces, residual = balanced_forces(points, inward)
    np.testing.assert_allclose(forces, inward, atol=1e-9)
    assert residual == pytest.approx(0.0, abs=1e-9)


def test_thumb_against_three_fingers_pushes_three_times_harder():
    # equal unit pushes leave a net force of 2 toward the thumb side: the thumb must match the row
    points = np.array([[0.02, 0, 0], [-0.02, -0.02, 0], [-0.02, 0, 0], [-0.02, 0.02, 0]])
    inward = np.array([[-1.0, 0, 0], [1.0, 0, 0], [1.0, 0, 0], [1.0, 0, 0]])
    forces, residual = balanced_forces(points, inward, regularization=1e-6)
    assert residual < 1e-3
    assert forces[0] @ inward[0] == pytest.approx(3.0, rel=1e-2)
    np.testing.assert_allclose(_net(points, forces), 0.0, atol=1e-3)
    _check_cones(forces, inward, 0.5)


def test_offset_opposition_is_untwisted_by_friction():
    # two pushes along x that miss each other by 1 cm make a couple about z; friction along y
    # at both contacts can cancel it (that is what the squeeze must not leave to the object)
    points = np.array([[-0.02, 0.005, 0], [0.02, -0.005, 0]])
    inward = np.array([[1.0, 0, 0], [-1.0, 0, 0]])
    forces, residual = balanced_forces(points, inward, regularization=1e-6)
    plain = np.linalg.norm(_net(points, inward)[3:])
    assert np.linalg.norm(_net(points, forces)[3:]) < 0.05 * plain
    assert residual < 0.05
    _check_cones(forces, inward, 0.5)


def test_unbalanceable_set_reports_its_residual():
    # every push along +x: no friction cone can cancel it
    points = np.array([[0.0, 0, 0], [0.0, 0.02, 0]])
    inward = np.array([[1.0, 0, 0], [1.0, 0, 0]])
    forces, residual = balanced_forces(points, inward)
    assert residual == pytest.approx(1.0, abs=1e-6)
    np.testing.assert_allclose(forces, inward, atol=1e-9)
