"""Multilateration and Kabsch recover exact answers from exact inputs."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from learned.contact_map import CONTACT_UNIT, contact_map, object_input
from learned.multilateration import (
    MultilaterationError,
    RigidGroups,
    kabsch,
    multilaterate,
    rigid_fit,
)
from models.hands import available_hands, load_hand


def _rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def test_multilateration_recovers_points_from_exact_distances():
    rng = np.random.default_rng(0)
    objects = torch.tensor(rng.uniform(-0.1, 0.1, (2, 300, 3)))
    points = torch.tensor(rng.uniform(-0.12, 0.12, (2, 50, 3)))
    estimate = multilaterate(objects, torch.cdist(points, objects), k=8)
    assert torch.max(torch.abs(estimate - points)) < 1e-4  # 0.1 mm (the ridge's bias)


def test_multilateration_refuses_mismatched_shapes():
    with pytest.raises(MultilaterationError):
        multilaterate(torch.zeros(1, 10, 3), torch.zeros(1, 5, 9))


def test_kabsch_recovers_a_rigid_transform():
    rng = np.random.default_rng(1)
    rot = torch.tensor(_rotation(rng))
    trans = torch.tensor([0.1, -0.2, 0.05], dtype=torch.float64)
    src = torch.tensor(rng.normal(size=(40, 3)))
    r, t = kabsch(src, src @ rot.T + trans)
    assert torch.allclose(r, rot, atol=1e-9) and torch.allclose(t, trans, atol=1e-9)
    assert torch.det(r) > 0


def test_kabsch_returns_a_rotation_for_a_reflected_target():
    rng = np.random.default_rng(2)
    src = torch.tensor(rng.normal(size=(20, 3)))
    r, _ = kabsch(src, src * torch.tensor([1.0, 1.0, -1.0]))
    assert torch.allclose(torch.det(r), torch.tensor(1.0, dtype=r.dtype))


@pytest.mark.parametrize("hand_name", available_hands())
def test_rigid_fit_places_every_hand_point(hand_name):
    """Exact positions of a third of the points (and distances to an object for the rest of
    the pipeline) give every surface point back through the per-body Kabsch."""
    hand = load_hand(hand_name)
    groups = RigidGroups.of_hand(hand)
    wrist = np.array([0.02, -0.01, 0.15, 0.9, 0.1, -0.3, 0.2])
    wrist[3:] /= np.linalg.norm(wrist[3:])
    q = 0.4 * hand.lower + 0.6 * hand.upper
    truth = hand.surface_points(wrist, q).double()
    objects = truth[:, ::3] + 0.01 * torch.randn(1, 171, 3, dtype=torch.float64)
    seen = multilaterate(objects, torch.cdist(truth, objects), k=10)
    placed = rigid_fit(groups, seen)
    assert torch.max(torch.linalg.norm(placed - truth, dim=-1)) < 1e-4
    # half the points, at least 3 on each body (fewer only translate it)
    firsts = [np.flatnonzero(groups.group == g)[:3] for g in np.unique(groups.group)]
    index = np.union1d(np.arange(0, 512, 2), np.concatenate(firsts))
    placed = rigid_fit(groups, truth[:, index], index)
    assert torch.max(torch.linalg.norm(placed - truth, dim=-1)) < 1e-6


def test_contact_map_falls_off_within_centimetres():
    anchors = np.zeros((4, 3))
    pts = np.array([[0, 0, 0], [CONTACT_UNIT, 0, 0], [3 * CONTACT_UNIT, 0, 0]], dtype=float)
    omega = contact_map(pts, anchors)
    assert omega[0] == pytest.approx(1.0)
    assert 0.2 < omega[1] < 0.3 and omega[2] < 0.01


def test_object_input_concentrates_on_anchors():
    rng = np.random.default_rng(3)
    pts = np.c_[rng.uniform(-0.1, 0.1, (16384, 2)), np.zeros(16384)]  # a 20 cm square
    anchors = pts[:4]
    inp = object_input(pts, anchors, np.random.default_rng(0))
    assert inp.features.shape == (512, 4)
    near = np.min(np.linalg.norm(inp.features[:256, None, :3] - anchors[None], axis=2), axis=1)
    assert np.median(near) < 0.02  # importance half near the anchors
    assert len(np.unique(inp.index)) == 512


def test_object_input_without_anchors_is_farthest_points_and_no_contact_map():
    rng = np.random.default_rng(3)
    points = rng.uniform(-0.05, 0.05, (2000, 3))
    first = object_input(points, None, np.random.default_rng(0))
    again = object_input(points, None, np.random.default_rng(0))
    assert first.features.shape == (512, 4) and len(np.unique(first.index)) == 512
    assert np.all(first.features[:, 3] == 0)
    assert np.array_equal(first.index, again.index)  # seeded
    assert np.allclose(first.features[:, :3], points[first.index])
