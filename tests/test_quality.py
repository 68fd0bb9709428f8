"""The epsilon and task metrics of planner.quality on contact sets the planner really meets."""

from __future__ import annotations

import numpy as np
import pytest

from planner.quality import contact_quality

# Six contacts of a solved Allegro grasp (a test object, learned samples): the first two are one
# vertex of a convex piece reached through two hand geometries, 1e-14 apart. As given, Qhull
# stopped with a precision error and the grasp read as no force closure (epsilon -1).
POINTS = [
    [0.019861697, 0.007275875, -0.03684931270756426],
    [0.019861697, 0.007275875, -0.0368493127075646],
    [0.03168171590829805, 0.002428486, -0.030384476304544182],
    [0.044643304, -0.005862885, -0.008541341],
    [0.0456092211177148, 0.0061001389231165794, -0.01331093965045351],
    [0.050885394, 0.002428486, -0.011135441],
]
INWARD = [
    [-0.9785906922999138, -0.20581607552369421, -1.1450036929452238e-14],
    [-0.9785906922999595, -0.2058160755234681, 1.1450036929452238e-14],
    [-0.41135306891381235, -0.3611045747358976, 0.8368943414792505],
    [0.3922433772485828, 0.8381162404333773, -0.37908613866303137],
    [-0.21288169793951572, -0.9713842174980547, 0.10532846091196414],
    [-0.4844568830768845, -0.2739868306257671, 0.8308024705566762],
]
CENTRE = [-0.01294021032224964, 0.0001807873938759826, -0.003837276466649819]


def test_a_contact_reached_twice_keeps_the_grasp_s_force_closure():
    points, inward = np.array(POINTS), np.array(INWARD)
    twice = contact_quality(points, inward, np.array(CENTRE))
    assert twice.epsilon > 0.01 and twice.task > 0.01
    # the second contact made an exact copy of the first: the same wrench set, one answer
    points[1], inward[1] = points[0], inward[0]
    assert contact_quality(points, inward, np.array(CENTRE)).epsilon == pytest.approx(twice.epsilon)


def test_every_contact_given_twice_gives_the_same_quality():
    rng = np.random.default_rng(0)
    points = rng.normal(size=(6, 3)) * 0.03
    inward = -points / np.linalg.norm(points, axis=1, keepdims=True)
    once = contact_quality(points, inward, np.zeros(3))
    # a copy of every contact: the same wrench set, the same mean distance to the centre
    doubled = contact_quality(
        np.repeat(points, 2, axis=0), np.repeat(inward, 2, axis=0), np.zeros(3)
    )
    assert once.epsilon > 0
    assert doubled.epsilon == pytest.approx(once.epsilon, abs=1e-12)
    assert doubled.task == pytest.approx(once.task, abs=1e-12)


@pytest.mark.parametrize(
    "points",
    [
        np.zeros((0, 3)),
        np.array([[0.02, 0, 0]]),
        np.array([[0.02, 0, 0], [0.02, 0, 0], [0.02, 0, 0]]),  # one contact three times
    ],
)
def test_fewer_than_two_distinct_contacts_have_no_closure(points):
    inward = -points / 0.02 if len(points) else points
    assert contact_quality(points, inward, np.zeros(3)).epsilon < 0
