"""Point targets pooled per link: four points with the same cost for every pose of the link."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from models.hands import available_hands, load_hand
from planner.point_costs import pooled


def _cost(local, targets, weights, link, pose_of):
    """sum w |X_link(p) - target|^2 with one rigid pose per link."""
    total = 0.0
    for p, t, w, k in zip(local, targets, weights, link, strict=True):
        rot, shift = pose_of[k]
        total += w * float(np.sum((rot @ p + shift - t) ** 2))
    return total


@pytest.mark.parametrize("hand_name", available_hands())
def test_pooled_costs_equal_the_per_point_costs(hand_name):
    """Rigidly moved targets of many points on several links: the pooled costs (four per link
    with more than four points) equal the per-point sum at random poses of every link."""
    hand = load_hand(hand_name)
    link, local = hand.surface
    link, local = np.asarray(link), np.asarray(local, dtype=float)
    rng = np.random.default_rng(0)
    index = rng.choice(len(link), 120, replace=False)
    weights = rng.uniform(0.05, 1.0, len(index))
    truth = {
        k: (Rotation.random(random_state=int(k)).as_matrix(), rng.normal(size=3) * 0.1)
        for k in np.unique(link)
    }
    targets = np.array([truth[link[i]][0] @ local[i] + truth[link[i]][1] for i in index])
    costs = pooled(link, local, index, targets, weights)
    assert len(costs.point) < len(index)
    for seed in range(5):
        poses = {
            k: (
                Rotation.random(random_state=100 + seed + int(k)).as_matrix(),
                rng.normal(size=3) * 0.1,
            )
            for k in np.unique(link)
        }
        full = _cost(local[index], targets, weights, link[index], poses)
        pooled_cost = _cost(costs.local, costs.targets, costs.weights, link[costs.point], poses)
        assert pooled_cost == pytest.approx(full, rel=1e-9)


def test_targets_that_do_not_move_rigidly_keep_a_cost_each():
    """Targets with noise on one link: no rigid motion carries the points onto them, so
    each keeps its own cost; zero weights are dropped."""
    rng = np.random.default_rng(1)
    local = rng.normal(size=(10, 3)) * 0.02
    link = np.zeros(10, dtype=int)
    targets = local + 0.05 + rng.normal(size=(10, 3)) * 0.003
    weights = np.r_[np.zeros(2), np.ones(8)]
    costs = pooled(link, local, np.arange(10), targets, weights)
    assert list(costs.point) == list(range(2, 10))
    np.testing.assert_allclose(costs.targets, targets[2:])


def test_pooling_runs_no_torch(monkeypatch):
    """The solves run in forked processes, where torch hangs after the parent used its
    threads (planner.parallel): pooling must not call it. Every torch entry point the
    Kabsch fit would use raises here."""
    import torch

    def refuse(*args, **kwargs):
        raise AssertionError("torch called while pooling point costs")

    for name in ("from_numpy", "as_tensor", "tensor"):
        monkeypatch.setattr(torch, name, refuse)
    monkeypatch.setattr(torch.linalg, "svd", refuse)
    rng = np.random.default_rng(2)
    local = rng.normal(size=(12, 3)) * 0.02
    rot = Rotation.random(random_state=3).as_matrix()
    costs = pooled(np.zeros(12, dtype=int), local, np.arange(12), local @ rot.T + 0.1, np.ones(12))
    assert len(costs.point) == 4


def test_rigid_fit_matches_the_batched_kabsch():
    """The numpy fit the pooling uses gives learned.multilateration.kabsch's motion."""
    import torch

    from learned.multilateration import kabsch
    from planner.point_costs import _rigid_motion

    rng = np.random.default_rng(4)
    for _ in range(5):
        p = rng.normal(size=(20, 3))
        t = rng.normal(size=(20, 3))  # no exact motion: the fits must agree anyway
        w = rng.uniform(0.1, 1.0, 20)
        rot, shift = _rigid_motion(p, t, w)
        ref_rot, ref_shift = kabsch(torch.from_numpy(p), torch.from_numpy(t), torch.from_numpy(w))
        np.testing.assert_allclose(rot, ref_rot.numpy(), atol=1e-12)
        np.testing.assert_allclose(shift, ref_shift.numpy(), atol=1e-12)
