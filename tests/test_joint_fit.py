"""The joint fit of the ablation without Drake recovers a configuration from its own points."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from learned.joint_fit import JointFitError, fit_configuration
from models.errors import PlanningError
from models.hands import available_hands, load_hand
from planner.settings import LearnedSettings, PlannerSettings


@pytest.mark.parametrize("hand_name", available_hands())
def test_fit_recovers_a_configuration_from_its_points(hand_name):
    hand = load_hand(hand_name)
    rng = np.random.default_rng(0)
    q = hand.couple(hand.lower + rng.uniform(0.2, 0.8, hand.dof) * (hand.upper - hand.lower))
    rot = Rotation.random(random_state=1)
    wrist = np.concatenate([[0.05, -0.02, 0.1], rot.as_quat(scalar_first=True)])
    targets = hand.surface_points(wrist, q)[0].numpy()
    turned = Rotation.from_rotvec([0.15, 0.0, 0.0]) * rot
    start = np.concatenate([wrist[:3] + 0.01, turned.as_quat(scalar_first=True)])
    fit = fit_configuration(hand, start, hand.open_pose, np.arange(512), targets)
    assert fit.rms_error < 1e-3  # from 1 cm and 9 degrees off, and the open pose
    assert np.all(fit.q >= hand.lower) and np.all(fit.q <= hand.upper)
    assert hand.coupling_violation(fit.q) < 1e-9
    assert np.linalg.norm(fit.wrist[:3] - wrist[:3]) < 2e-3
    assert abs(np.linalg.norm(fit.wrist[3:]) - 1) < 1e-9


def test_fit_refuses_targets_of_the_wrong_shape():
    hand = load_hand(available_hands()[0])
    wrist = np.array([0, 0, 0, 1.0, 0, 0, 0])
    with pytest.raises(JointFitError, match="expected"):
        fit_configuration(hand, wrist, hand.open_pose, np.arange(4), np.zeros((3, 3)))


def test_fit_solver_needs_dro_targets():
    with pytest.raises(PlanningError, match=r"learned\.dro=True"):
        PlannerSettings(learned=LearnedSettings(solver="fit", dro=False))
    with pytest.raises(PlanningError, match=r"unknown learned\.solver"):
        PlannerSettings(learned=LearnedSettings(solver="ik"))
