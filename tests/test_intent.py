"""Intent definitions (models.objects.intents) and their checks (planner.intent) on constructed
hand placements: each criterion passes where the hand does what the intent asks and fails
where it does not, for every hand."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from models.errors import InstructionError
from models.grasp import Grasp
from models.hands import load_hand
from models.objects import TABLE, make_object
from models.objects.intents import (
    CATEGORY_INTENTS,
    CRITERIA,
    FINGER_ROLES,
    FINGERS,
    RULES,
    check_tables,
    definition,
    definitions,
    resolve_fingers,
)
from models.objects.library import CATEGORIES
from planner import intent as I
from planner.intent import check_configuration, check_intent, intent_definition, mass_centre

REPO = Path(__file__).resolve().parents[1]
X, Y, Z = np.eye(3)


@pytest.fixture(scope="module")
def objects():
    cache = {}

    def get(cat: str, seed: int = 0):
        if (cat, seed) not in cache:
            cache[cat, seed] = make_object(cat, seed)
        return cache[cat, seed]

    return get


def part_points(obj, part: str) -> np.ndarray:
    return obj.points[obj.point_labels == obj.part_names.index(part)]


def placed(hand, palm_at, normal, fingers, q=None) -> tuple[np.ndarray, np.ndarray]:
    """(wrist, q): the hand with its palm centre at `palm_at`, its outward palm normal along
    `normal` and its straight fingers along `fingers` (world), open unless q is given."""
    palm = hand.meta.palm
    rot, _ = Rotation.align_vectors([normal, fingers], [palm.normal, palm.finger_axis])
    pos = np.asarray(palm_at, dtype=float) - rot.apply(palm.center)
    wrist = np.concatenate([pos, rot.as_quat(scalar_first=True)])
    return wrist, hand.open_pose.copy() if q is None else q


def tip_on(hand, obj, finger: str, point: np.ndarray, normal: np.ndarray, row: np.ndarray):
    """(wrist, q): the open hand turned so that its palm faces along -normal and its finger
    row runs along `row`, moved so that `finger`'s fingertip sphere rests on `point`."""
    q = hand.open_pose.copy()
    eye = torch.tensor([[0, 0, 0, 1.0, 0, 0, 0]], dtype=torch.float64)
    names = list(hand.meta.anchor_fingers)
    tips = hand.fingertip_positions(eye, torch.tensor(q[None]), names)[0].numpy()
    lateral = tips[-1] - tips[1]
    rot, _ = Rotation.align_vectors([-normal, row], [hand.meta.palm.normal, lateral])
    tip = hand.meta.fingertip(finger)
    local = tips[names.index(finger)]
    pos = point + normal * tip.radius - rot.apply(local)
    return np.concatenate([pos, rot.as_quat(scalar_first=True)]), q


def role(hand, name: str) -> str:
    return resolve_fingers(hand.meta.anchor_fingers, [t.name for t in hand.meta.fingertips])[name][
        0
    ]


# ---- the definitions ---------------------------------------------------------------------------
def test_tables_are_consistent():
    assert check_tables() == []


def test_every_instruction_has_a_definition():
    rows = {(cat, i, p) for cat, items in TABLE.items() for i, p in items}
    defined = {(d.category, d.intent, d.part) for d in definitions()}
    assert defined == rows
    for d in definitions():
        assert d.criteria, d
        assert set(d.criteria) <= set(CRITERIA[d.intent])
        parts = CATEGORIES[d.category].parts
        assert all(e.part == d.part for e in d.elements)
        assert all(w.part in parts for w in d.working)
        if d.intent == "Handover":
            assert d.receiver and d.part not in d.receiver and set(d.receiver) <= set(parts)
        assert d.describe().startswith(d.intent)


def test_use_definitions_name_the_issue_examples():
    trigger = definition("spray_bottle", "Use", "trigger")
    assert trigger.elements[0].fingers == ("index",)
    pump = definition("lotion_pump", "Use", "pump")
    assert set(pump.elements[0].fingers) == {"index", "thumb"} and pump.elements[0].rule == "any"
    assert definition("scissors", "Use", "handle").elements[0].rule == "split"
    for cat, work in [("knife", "blade"), ("hammer", "head"), ("teapot", "spout"), ("pen", "tip")]:
        part = next(p for i, p in TABLE[cat] if i == "Use")
        assert work in {w.part for w in definition(cat, "Use", part).working}
    shaft = definition("screwdriver", "Use", "handle").working[0]
    assert (shaft.part, shaft.end) == ("shaft", "free")
    # the instructed part is never a whole working part to keep clear
    assert not definition("bottle", "Use", "cap").working


def test_definition_refuses_unknown_names():
    with pytest.raises(InstructionError):
        definition("mug", "Use", "spout")
    with pytest.raises(InstructionError):
        definition("mug", "Throw", "handle")
    with pytest.raises(InstructionError):
        definition("cauldron", "Use", "handle")


def test_definitions_are_hand_independent():
    names = ("allegro", "leap", "shadow")
    for path in ("models/objects/intents.py", "planner/intent.py"):
        text = (REPO / path).read_text().lower()
        assert not any(n in text for n in names), path
    assert not any(
        "planner" in line
        for line in (REPO / "models/objects/intents.py").read_text().splitlines()
        if line.startswith(("import", "from"))
    )


def test_fingers_resolve_for_every_hand(hand_name):
    hand = load_hand(hand_name)
    tips = [t.name for t in hand.meta.fingertips]
    roles = resolve_fingers(hand.meta.anchor_fingers, tips)
    anchors = hand.meta.anchor_fingers
    assert roles["thumb"] == (anchors[0],) and roles["index"] == (anchors[1],)
    assert roles[FINGERS] == tuple(t for t in tips if t != anchors[0])
    for names in roles.values():
        assert set(names) <= set(tips)
    used = {r for spec in CATEGORY_INTENTS.values() for e in spec.elements for r in e.fingers}
    assert used <= set(roles)
    assert set(roles) - {FINGERS} <= set(FINGER_ROLES)


def test_resolve_fingers_extra_fingertip_is_little():
    roles = resolve_fingers(["t", "a", "b", "c"], ["t", "a", "b", "c", "d"])
    assert roles["little"] == ("d",) and roles[FINGERS] == ("a", "b", "c", "d")
    assert "little" not in resolve_fingers(["t", "a"], ["t", "a"])


def test_mass_centre_and_regions(objects):
    mug = objects("mug")
    com = mass_centre(mug)
    body = part_points(mug, "body").mean(axis=0)
    handle = part_points(mug, "handle").mean(axis=0)
    assert body[0] < com[0] < handle[0]  # the handle pulls it toward +x
    sd = objects("screwdriver")
    facts = I._object_facts(sd)
    tip = facts.region(definition("screwdriver", "Use", "handle").working[0])
    handle_x = part_points(sd, "handle")[:, 0].mean()
    shaft_x = part_points(sd, "shaft")[:, 0]
    far = shaft_x.max() if handle_x < shaft_x.mean() else shaft_x.min()
    assert np.all(np.abs(tip[:, 0] - far) <= 0.021)


# ---- Liftup -----------------------------------------------------------------------------------
def test_liftup_from_above_passes_from_the_side_fails(hand_name, objects):
    hand, mug, bottle = load_hand(hand_name), objects("mug"), objects("bottle")
    # above a bottle's cap: tall enough that an open thumb (LEAP's points 10 cm down) stays
    # above its bottom
    cap = part_points(bottle, "cap")
    top = [cap[:, 0].mean(), cap[:, 1].mean(), cap[:, 2].max() + 0.01]
    above = check_configuration(*placed(hand, top, -Z, X), bottle, hand, "Liftup a bottle by neck")
    assert above.ok, above.reason
    assert above["palm_down"].value < 1.0
    body = part_points(mug, "body")
    top = [body[:, 0].mean(), body[:, 1].mean(), body[:, 2].max() + 0.01]
    over_mug = check_configuration(*placed(hand, top, -Z, X), mug, hand, "Liftup a mug by body")
    assert over_mug["palm_down"].passed and over_mug["wrist_above_com"].passed

    side = [body[:, 0].min() - 0.01, body[:, 1].mean(), 0.0]
    check = check_configuration(*placed(hand, side, X, Z), mug, hand, "Liftup a mug by body")
    assert not check.ok and not check["palm_down"].passed
    assert check["palm_down"].value == pytest.approx(90, abs=1)

    below = [body[:, 0].mean(), 0.0, body[:, 2].min() - 0.03]
    check = check_configuration(*placed(hand, below, Z, X), mug, hand, "Liftup a mug by handle")
    assert not check["above_table"].passed and not check["wrist_above_com"].passed
    assert not check["palm_down"].passed and "palm_down" in check.reason


# ---- Handover ---------------------------------------------------------------------------------
def test_handover_clear_of_the_handle_passes_touching_it_fails(hand_name, objects):
    hand, mug = load_hand(hand_name), objects("mug")
    body, handle = part_points(mug, "body"), part_points(mug, "handle")
    assert handle[:, 0].mean() > body[:, 0].mean()  # the handle is on +x
    text = "Handover a mug by body"
    away = [body[:, 0].min() - 0.005, body[:, 1].mean(), 0.0]
    check = check_configuration(*placed(hand, away, X, Z), mug, hand, text)
    assert check.ok, check.reason
    assert check["other_parts_clear"].value >= 0.02 and check["away_from_free_end"].value < 0

    at_handle = [handle[:, 0].max() + 0.005, 0.0, handle[:, 2].mean()]
    check = check_configuration(*placed(hand, at_handle, -X, Z), mug, hand, text)
    assert not check.ok
    assert not check["other_parts_clear"].passed and not check["away_from_free_end"].passed
    assert "handle" in check["other_parts_clear"].note


# ---- Use --------------------------------------------------------------------------------------
def test_use_knife_blade_clear(hand_name, objects):
    hand, knife = load_hand(hand_name), objects("knife")
    handle, blade = part_points(knife, "handle"), part_points(knife, "blade")
    out = np.sign(handle[:, 0].mean() - blade[:, 0].mean()) * X  # from the blade to the handle
    end = handle[np.argmax(handle @ out)]
    top = handle[:, 2].max() + 0.005
    check = check_configuration(
        *placed(hand, [end[0], handle[:, 1].mean(), top], -Z, out),
        knife,
        hand,
        "Use a knife by handle",
    )
    assert check.ok, check.reason
    over = [blade[:, 0].mean(), blade[:, 1].mean(), blade[:, 2].max() + 0.005]
    check = check_configuration(*placed(hand, over, -Z, Y), knife, hand, "Use a knife by handle")
    assert not check.ok and check["working_parts_clear"].value < 0.01
    assert "blade" in check.reason


def test_use_index_on_trigger(hand_name, objects):
    hand, spray = load_hand(hand_name), objects("spray_bottle")
    trig = spray.point_labels == spray.part_names.index("trigger")
    pts, nrm = spray.points[trig], spray.normals[trig]
    low = pts[:, 2] < np.median(pts[:, 2])
    k = np.flatnonzero(low)[np.argmax(pts[low, 0])]  # the trigger's front, where a finger pulls
    text = "Use a spray bottle by trigger"
    index = role(hand, "index")
    check = check_configuration(*tip_on(hand, spray, index, pts[k], nrm[k], Y), spray, hand, text)
    assert check["finger_on_element"].passed, check.reason
    ring = role(hand, "ring")  # two fingers off: the middle finger's neighbour may touch it
    check = check_configuration(*tip_on(hand, spray, ring, pts[k], nrm[k], Y), spray, hand, text)
    assert not check["finger_on_element"].passed and not check.ok


@pytest.mark.parametrize("finger", ["thumb", "index"])
def test_use_pump_either_finger(hand_name, objects, finger):
    hand, pump = load_hand(hand_name), objects("lotion_pump")
    head = pump.point_labels == pump.part_names.index("pump")
    pts = pump.points[head]
    k = int(np.argmax(pts[:, 2] - 10 * np.abs(pts[:, 0])))  # the top, over the stem
    wrist, q = tip_on(hand, pump, role(hand, finger), pts[k], Z, X)
    check = check_configuration(wrist, q, pump, hand, "Use a lotion pump by pump")
    assert check["finger_on_element"].passed, check.reason
    far = wrist.copy()
    far[:3] += [0.0, 0.0, 0.2]
    check = check_configuration(far, q, pump, hand, "Use a lotion pump by pump")
    assert not check["finger_on_element"].passed


def fake(hand, where: dict[str, np.ndarray]) -> I._Config:
    """A configuration with every hand body 10 m away except the named fingertip bodies (and
    "palm"), whose points are all at the given point: for rules a real pose cannot isolate."""
    hf = I._hand_facts(hand)
    points = np.full((len(hf.rigid), 3), 10.0)
    tips = np.full((len(hf.tip_names), 3), 10.0)
    for name, at in where.items():
        mask = hf.palm_body if name == "palm" else hf.tip_points[name]
        points[mask] = at
        if name != "palm":
            tips[hf.tip_names.index(name)] = at
    return I._Config(np.array([0, 0, 0, 1.0, 0, 0, 0]), points, tips, np.zeros(3), Z)


def test_use_scissors_thumb_and_finger_on_the_two_loops(hand_name, objects):
    hand, sc = load_hand(hand_name), objects("scissors")
    facts = I._object_facts(sc)
    a, b = facts.lobes("handle")
    assert abs(a[:, 1].mean() - b[:, 1].mean()) > 0.02  # the two rings, side by side in y
    d = definition("scissors", "Use", "handle")
    hf = I._hand_facts(hand)
    th, ix = role(hand, "thumb"), role(hand, "index")
    lift = np.array([0, 0, 0.004])
    split = I._evaluate(d, facts, hf, fake(hand, {th: a[0] + lift, ix: b[0] + lift}), I.RULES)
    assert split["finger_on_element"].passed and "on one loop" in split["finger_on_element"].note
    same = I._evaluate(d, facts, hf, fake(hand, {th: a[0] + lift, ix: a[5] + lift}), I.RULES)
    assert not same["finger_on_element"].passed
    # through the holes: fingertip centres at the rings' centres
    holes = fake(hand, {th: a.mean(axis=0), ix: b.mean(axis=0)})
    through = I._evaluate(d, facts, hf, holes, I.RULES)
    assert through["finger_on_element"].passed and "through" in through["finger_on_element"].note


# ---- Hold -------------------------------------------------------------------------------------
def test_hold_palm_contact(hand_name, objects):
    hand, mug = load_hand(hand_name), objects("mug")
    body = part_points(mug, "body")
    near = [body[:, 0].min() - 0.003, body[:, 1].mean(), 0.0]
    check = check_configuration(*placed(hand, near, X, Z), mug, hand, "Hold a mug by body")
    assert check["palm_contact"].passed, check.reason
    far = [body[:, 0].min() - 0.05, body[:, 1].mean(), 0.0]
    check = check_configuration(*placed(hand, far, X, Z), mug, hand, "Hold a mug by body")
    assert not check["palm_contact"].passed and not check.ok
    assert not check["force_closure"].passed  # nothing touches
    # a pen's barrel is too narrow for the palm: not required
    pen = objects("pen")
    barrel = part_points(pen, "barrel")
    check = check_configuration(
        *placed(hand, barrel.mean(axis=0) + [0, 0, 0.05], -Z, X), pen, hand, "Hold a pen by barrel"
    )
    assert check["palm_contact"].passed and "not required" in check["palm_contact"].note


def test_hold_force_closure(hand_name, objects):
    hand, mug = load_hand(hand_name), objects("mug")
    facts, hf = I._object_facts(mug), I._hand_facts(hand)
    body = mug.point_labels == mug.part_names.index("body")
    pts, nrm = mug.points[body], mug.normals[body]
    outer = (nrm[:, 2] ** 2 < 0.1) & (np.abs(pts[:, 2] - com_z(mug)) < 0.02)
    names = [*hf.tip_names, "palm"][:4]  # four bodies around the body at the mass centre
    around = {}
    for name, angle in zip(
        names, np.linspace(0, 2 * np.pi, len(names), endpoint=False), strict=True
    ):
        direction = np.array([np.cos(angle), np.sin(angle), 0.0])
        idx = np.flatnonzero(outer)
        k = idx[np.argmax(pts[idx] @ direction + 0.5 * (nrm[idx] @ direction))]
        around[name] = pts[k] + nrm[k] * 0.003
    d = definition("mug", "Hold", "body")
    check = I._evaluate(d, facts, hf, fake(hand, around), I.RULES)
    assert check["force_closure"].passed, check.reason
    side = around[names[0]]  # every body on the same spot: no closure
    check = I._evaluate(d, facts, hf, fake(hand, dict.fromkeys(names, side)), I.RULES)
    assert not check["force_closure"].passed


def com_z(obj) -> float:
    return float(mass_centre(obj)[2])


# ---- the entry points -------------------------------------------------------------------------
def test_check_intent_reads_the_grasp_record(objects):
    hand, mug = load_hand("allegro"), objects("mug")
    body = part_points(mug, "body")
    wrist, q = placed(hand, [body[:, 0].mean(), 0.0, body[:, 2].max() + 0.01], -Z, X)
    grasp = Grasp(
        hand=hand.name,
        wrist_pos=wrist[:3],
        wrist_quat=wrist[3:],
        grasp=q,
        pregrasp=q,
        squeeze=q,
        joint_names=tuple(hand.joint_names),
        instruction="Liftup a mug by body",
    )
    check = check_intent(grasp, mug, hand)
    assert check.ok and check.intent == "Liftup"
    assert set(check.to_dict()["criteria"]) == set(CRITERIA["Liftup"])
    with pytest.raises(InstructionError):
        check_intent(grasp, mug, hand, "Use a mug by spout")


def test_unknown_objects_get_the_generic_rules(objects):
    mug = objects("mug")
    d = intent_definition(mug, "Handover a cup by body")  # parts differ from a cup's
    assert d.receiver == ("handle",) and d.criteria == CRITERIA["Handover"]
    assert intent_definition(mug, "Use a cup by handle").criteria == ()


def test_liftup_is_checked_without_part_labels_the_others_are_refused(objects):
    from dataclasses import replace

    hand, mug = load_hand("allegro"), objects("mug")
    bare = replace(mug, face_labels=None, cloud_labels=None, part_names=(), _derived={})
    assert not bare.labelled
    body = part_points(mug, "body")
    top = [body[:, 0].mean(), body[:, 1].mean(), body[:, 2].max() + 0.01]
    pose = placed(hand, top, -Z, X)
    labelled = check_configuration(*pose, mug, hand, "Liftup a mug by body")
    unlabelled = check_configuration(*pose, bare, hand, "Liftup a mug by body")
    assert unlabelled.ok == labelled.ok and unlabelled["palm_down"].passed
    assert [c.value for c in unlabelled.criteria] == [c.value for c in labelled.criteria]
    with pytest.raises(InstructionError, match="part-labelled"):
        check_configuration(*pose, bare, hand, "Hold a mug by body")


def test_hold_is_measured_on_a_region_standing_in_for_the_part(objects):
    """On a cloud without labels the learned samples' region stands in for the part: a region
    that is exactly the mug's body measures Hold as the labelled mug does (the object's own
    centre of mass kept). Only Hold is measured this way: Handover's other parts and Use's
    elements need real labels, Liftup needs none."""
    from dataclasses import replace

    from models.objects import ObjectModel
    from models.objects.intents import region_checked

    assert region_checked("Hold")
    assert not any(region_checked(i) for i in ("Use", "Handover", "Liftup"))
    hand, mug = load_hand("allegro"), objects("mug")
    bare = replace(mug, face_labels=None, cloud_labels=None, part_names=(), _derived={})
    body = mug.point_labels == mug.part_names.index("body")
    region = ObjectModel(
        name="mug",
        cloud=bare.points,
        cloud_normals=bare.normals,
        cloud_labels=np.where(body, 0, 1),
        part_names=("pointed", "rest"),
        category="mug",
    )
    pts = part_points(mug, "body")
    for x, touching in ((pts[:, 0].min() - 0.003, True), (pts[:, 0].min() - 0.05, False)):
        pose = placed(hand, [x, pts[:, 1].mean(), 0.0], X, Z)
        labelled = check_configuration(*pose, mug, hand, "Hold a mug by body")
        on_region = check_configuration(*pose, bare, hand, "Hold a mug by body", region=region)
        assert on_region.intent == "Hold" and on_region.ok == labelled.ok
        assert on_region["palm_contact"].passed == touching
        assert [c.name for c in on_region.criteria] == [c.name for c in labelled.criteria]
        assert [c.value for c in on_region.criteria] == pytest.approx(
            [c.value for c in labelled.criteria]
        )


def test_guessed_labels_are_measured_about_the_object_s_own_mass_centre(objects):
    """On a bare object the interaction model's labels come as a labelled cloud of its points
    (planner.model_labels); checked with `labels=`, Hold's epsilon is taken about the object's
    mass centre (its pieces'), not the cloud's point mean, even where the cloud's own facts were
    made first (as `unmeetable` and the keep-outs make them): with the true labels guessed, the
    verdict is the labelled knife's."""
    from dataclasses import replace

    from models.objects import ObjectModel

    hand, knife = load_hand("allegro"), objects("knife")
    bare = replace(knife, face_labels=None, cloud_labels=None, part_names=(), _derived={})
    guess = ObjectModel(
        name="knife",
        cloud=bare.points,
        cloud_normals=bare.normals,
        cloud_labels=knife.point_labels,
        part_names=knife.part_names,
        category="knife",
    )
    cloud_centre = I._object_facts(guess).com  # made first, as a plan does
    assert np.linalg.norm(cloud_centre - mass_centre(knife)) > 0.005
    handle = part_points(knife, "handle")
    pose = placed(
        hand, [handle[:, 0].mean(), handle[:, 1].mean(), handle[:, 2].max() + 0.004], -Z, X
    )
    text = "Hold a knife by handle"
    truth = check_configuration(*pose, knife, hand, text)
    guessed = check_configuration(*pose, bare, hand, text, labels=guess)
    assert [c.value for c in guessed.criteria] == pytest.approx([c.value for c in truth.criteria])
    assert truth["force_closure"].value != pytest.approx(
        check_configuration(*pose, guess, hand, text)["force_closure"].value
    )


def test_faces_intent_reads_the_wrist_criteria_only(objects):
    from planner.intent import faces_intent

    hand, mug = load_hand("leap"), objects("mug")
    body = part_points(mug, "body")
    top = [body[:, 0].mean(), body[:, 1].mean(), body[:, 2].max() + 0.01]
    wrist, _ = placed(hand, top, -Z, X)
    assert faces_intent(wrist, mug, hand, "Liftup a mug by body")
    side = [body[:, 0].min() - 0.01, body[:, 1].mean(), 0.0]
    wrist_side, _ = placed(hand, side, X, Z)
    assert not faces_intent(wrist_side, mug, hand, "Liftup a mug by body")
    # no criterion of Hold is decided by the wrist alone
    assert faces_intent(wrist_side, mug, hand, "Hold a mug by body")


# ---- definitions no grasp on the part can meet -------------------------------------------------
def test_handover_by_a_rim_cannot_be_met_and_says_why(objects):
    cup = objects("cup")
    reason = I.unmeetable(cup, intent_definition(cup, "Handover a cup by rim"))
    assert reason is not None and "rim" in reason and "the body" in reason and "20 mm" in reason
    # every rim point lies nearer the body than the clearance less a touch's reach
    rim, body = part_points(cup, "rim"), part_points(cup, "body")
    gaps = cKDTree(body).query(rim)[0]
    assert gaps.max() + I.TOUCH_REACH < RULES.handover.other_part_clearance + 0.002


@pytest.mark.parametrize(
    "cat, text",
    [
        ("mug", "Handover a mug by body"),
        ("bottle", "Handover a bottle by neck"),  # 2-3 cm long: not ruled out by the shape
        ("knife", "Use a knife by handle"),
        ("mug", "Hold a mug by body"),
        ("mug", "Liftup a mug by handle"),
    ],
)
def test_definitions_that_a_grasp_on_the_part_may_meet(objects, cat, text):
    obj = objects(cat)
    assert I.unmeetable(obj, intent_definition(obj, text)) is None


def test_a_use_part_inside_a_working_parts_clearance_cannot_be_met(objects):
    """Use keeps the working parts 1 cm clear: a part no deeper than that from one is ruled
    out, with a looser rule nothing is."""
    from dataclasses import replace as changed

    from models.objects.intents import Region, UseRule

    cup = objects("cup")
    meaning = changed(
        intent_definition(cup, "Use a cup by body"), part="rim", working=(Region("body", "wall"),)
    )
    assert "wall" in I.unmeetable(cup, meaning, changed(RULES, use=UseRule(working_clearance=0.02)))
    assert I.unmeetable(cup, meaning) is None  # 10 mm: within a touch's reach of 8 mm deep


# ---- proposals that will miss the intent as drawn -----------------------------------------------
def test_proposal_misses_anchors_beside_a_part_kept_clear_and_wrists_that_do_not_face(
    hand_name, objects
):
    """The search for the intent passes over proposals whose anchor lies beside a part the
    definition keeps clear (Handover's other parts, Use's working parts) and whose drawn wrist
    fails Liftup's wrist criteria; anchors and wrists clear of both pass."""
    hand, knife, mug = load_hand(hand_name), objects("knife"), objects("mug")
    handover = intent_definition(knife, "Handover a knife by handle")
    handle, blade = part_points(knife, "handle"), part_points(knife, "blade")
    gaps = cKDTree(blade).query(handle)[0]
    near, far = handle[np.argsort(gaps)[:4]], handle[np.argsort(gaps)[-4:]]
    # the palm above the handle's far end: away from the blade, the receiver's
    wrist, _ = placed(hand, far.mean(axis=0) + [0, 0, 0.03], -Z, Y)
    why = I.proposal_misses(wrist, near, knife, hand, handover, knife, 0.25)
    assert why is not None and "the blade" in why
    assert I.proposal_misses(wrist, far, knife, hand, handover, knife, 0.25) is None
    # a pinch leaves its last anchor finger free (NaN): only the placed anchors count
    pinch = np.vstack([near[:3], np.full((1, 3), np.nan)])
    assert I.proposal_misses(wrist, pinch, knife, hand, handover, knife, 0.25) is not None
    pinch = np.vstack([far[:3], np.full((1, 3), np.nan)])
    assert I.proposal_misses(wrist, pinch, knife, hand, handover, knife, 0.25) is None
    # no labels to measure the anchors on: nothing is said of them
    assert I.proposal_misses(wrist, near, knife, hand, handover, None, 0.25) is None
    use = intent_definition(knife, "Use a knife by handle")  # the blade kept clear
    assert I.proposal_misses(wrist, near, knife, hand, use, knife, 0.25) is not None

    liftup = intent_definition(mug, "Liftup a mug by body")
    body = part_points(mug, "body")
    top = [body[:, 0].mean(), body[:, 1].mean(), body[:, 2].max() + 0.01]
    side = [body[:, 0].min() - 0.01, body[:, 1].mean(), 0.0]
    anchors = body[:4]
    assert (
        I.proposal_misses(placed(hand, top, -Z, X)[0], anchors, mug, hand, liftup, mug, 0.25)
        is None
    )
    why = I.proposal_misses(placed(hand, side, X, Z)[0], anchors, mug, hand, liftup, mug, 0.25)
    assert why is not None and "palm_down" in why
    # drawn 45 degrees from down: passed over with no margin, solved within a 30-degree one
    tilted = np.array([np.sin(np.radians(45)), 0.0, -np.cos(np.radians(45))])
    wrist45 = placed(hand, top, tilted, np.cross(tilted, Y))[0]
    assert I.proposal_misses(wrist45, anchors, mug, hand, liftup, mug, 0.25) is not None
    assert I.proposal_misses(wrist45, anchors, mug, hand, liftup, mug, 0.25, 30.0) is None
    assert I.proposal_misses(wrist45, anchors, mug, hand, liftup, mug, 0.25, 10.0) is not None
    # Handover: a palm beyond the held part's centre toward the free end (the mug's body
    # handed over, its handle on +x the receiver's) is decided by the drawn wrist
    handover = intent_definition(mug, "Handover a mug by body")
    clear = body[np.argsort(body[:, 0])[:4]]  # anchors on the body's -x side, far from the handle
    away = [body[:, 0].min() - 0.005, body[:, 1].mean(), 0.0]
    assert (
        I.proposal_misses(placed(hand, away, X, Z)[0], clear, mug, hand, handover, mug, 0.25)
        is None
    )
    toward = [body[:, 0].max() + 0.03, body[:, 1].mean() + 0.05, body[:, 2].max() + 0.02]
    why = I.proposal_misses(placed(hand, toward, -X, Z)[0], clear, mug, hand, handover, mug, 0.25)
    assert why is not None and "away_from_free_end" in why
    # ... which needs the labels
    assert (
        I.proposal_misses(placed(hand, toward, -X, Z)[0], clear, mug, hand, handover, None, 0.25)
        is None
    )
    # Hold asks nothing of the drawn wrist or of the anchors' distance to other parts
    hold = intent_definition(mug, "Hold a mug by body")
    assert (
        I.proposal_misses(placed(hand, side, X, Z)[0], anchors, mug, hand, hold, mug, 0.25) is None
    )
