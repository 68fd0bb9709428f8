"""LEAP as DexGraspBench's hand file builds it (Menagerie's right_hand.xml with DexGraspBench's
simplified meshes): the project's MuJoCo model matches the file body by body, except where
noted: the fingertips (both collide with the vendor's tip meshes, the project's as their convex
hulls in models/hands/leap/meshes, four geoms on the distal links) and three exclusions the grasp program needs (each finger's base and middle links: their
merged convex hulls overlap at the open pose)."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from models.hands import load_hand
from tests.conftest import reference_dir

TIP_LINKS = {"if_ds", "mf_ds", "rf_ds", "th_ds"}
PROGRAM_ONLY_EXCLUSIONS = {("if_bs", "if_md"), ("mf_bs", "mf_md"), ("rf_bs", "rf_md")}


@pytest.fixture(scope="module")
def models():
    from planner.validation.hands import mjcf_hand, project_hand

    xml = reference_dir("dexgraspbench", "hand") / "leap_right_hand.xml"
    ours = project_hand("leap").spec_factory().compile()
    theirs = mjcf_hand(xml).spec_factory().compile()
    return ours, theirs


def _body(model: mujoco.MjModel, link: str, vendor: bool) -> int:
    from planner.validation.hands import MJCF_PREFIX

    return model.body(MJCF_PREFIX + link if vendor else link).id


def _geoms(model: mujoco.MjModel, body: int, kind: int) -> list[tuple]:
    """Colliding geoms of one type on a body: (size, pos, quat), rounded, sorted."""
    out = []
    for g in np.flatnonzero(model.geom_bodyid == body):
        if model.geom_contype[g] == 0 and model.geom_conaffinity[g] == 0:
            continue
        if model.geom_type[g] != kind:
            continue
        out.append(
            tuple(np.round(np.concatenate([model.geom_size[g], model.geom_pos[g]]), 7))
            + tuple(np.round(model.geom_quat[g], 6))
        )
    return sorted(out)


def test_leap_bodies_boxes_and_dynamics_match_dexgraspbench(models):
    ours, theirs = models
    hand = load_hand("leap")
    box = int(mujoco.mjtGeom.mjGEOM_BOX)
    for link in hand.link_names:
        a, b = _body(ours, link, False), _body(theirs, link, True)
        for field in ("body_mass", "body_inertia", "body_ipos"):
            np.testing.assert_allclose(
                getattr(ours, field)[a],
                getattr(theirs, field)[b],
                rtol=1e-5,
                atol=1e-10,
                err_msg=f"{link} {field}",
            )
        # every vendor box is ours, and ours has no other box (a fingertip may add its own)
        vendor_boxes = _geoms(theirs, b, box)
        our_boxes = _geoms(ours, a, box)
        if link in TIP_LINKS:
            assert set(vendor_boxes) <= set(our_boxes), link
        else:
            assert our_boxes == vendor_boxes, link
    for joint in hand.joint_names:
        a, b = ours.joint(joint), theirs.joint("hand/" + joint)
        np.testing.assert_allclose(a.range, b.range)
        for field in ("dof_damping", "dof_armature", "dof_frictionloss"):
            assert getattr(ours, field)[a.dofadr[0]] == getattr(theirs, field)[b.dofadr[0]], (
                joint,
                field,
            )


def test_leap_non_box_collision_is_only_the_fingertips(models):
    """The file's only non-box collision geoms are the four tip meshes; ours are on the same
    four distal links."""
    ours, theirs = models
    hand = load_hand("leap")
    box = int(mujoco.mjtGeom.mjGEOM_BOX)
    for model, vendor in ((ours, False), (theirs, True)):
        links = set()
        for link in hand.link_names:
            body = _body(model, link, vendor)
            for g in np.flatnonzero(model.geom_bodyid == body):
                colliding = model.geom_contype[g] or model.geom_conaffinity[g]
                if colliding and model.geom_type[g] != box:
                    links.add(link)
        assert links == TIP_LINKS, (vendor, links)


def test_leap_actuators_match_dexgraspbench(models):
    """Position actuators with the file's kp 3 and kv 0.01 (biasprm), over the joint ranges."""
    ours, theirs = models
    assert ours.nu == theirs.nu == 16
    for u in range(theirs.nu):
        joint = theirs.joint(theirs.actuator_trnid[u, 0]).name.removeprefix("hand/")
        mine = next(
            v for v in range(ours.nu) if ours.joint(ours.actuator_trnid[v, 0]).name == joint
        )
        for field in ("actuator_gainprm", "actuator_biasprm", "actuator_ctrlrange"):
            np.testing.assert_allclose(
                getattr(ours, field)[mine], getattr(theirs, field)[u], err_msg=f"{joint} {field}"
            )
        assert ours.actuator_biasprm[mine, 2] == pytest.approx(-0.01)


def test_leap_exclusions_are_the_files_and_the_programs(models):
    ours, theirs = models

    def excluded(model):
        pairs = {
            (model.body(s >> 16).name, model.body(s & 0xFFFF).name) for s in model.exclude_signature
        }
        return {tuple(sorted(n.removeprefix("hand/") for n in p)) for p in pairs}

    extra = {tuple(sorted(p)) for p in PROGRAM_ONLY_EXCLUSIONS}
    assert excluded(ours) == excluded(theirs) | extra
    assert not excluded(theirs) & extra
