"""What each intent means, as measurable data: one rule per intent with its numbers, and per
category the functional elements and working parts that the Use rule needs.

The instruction table (models.objects.instructions.TABLE) says which (intent, part) pairs make
sense; this module says what a grasp must do for each of them. `planner.intent.check_intent`
measures a grasp against it. Nothing here depends on a hand: fingers are named by role (thumb,
index = the first anchor finger after the thumb, middle, ring, then fingertips that are not
anchors, little) and `resolve_fingers` maps the roles onto a hand's hand.json `anchor_fingers`
and `fingertips`.

The rules (distances are between the hand's fixed surface points, or a fingertip link's points,
and the object's dense labelled surface points):

- Use: the grasp enables the object's function. Where the category names a functional element
  on the instructed part (a spray bottle's trigger), the named finger is on it (its distal link
  within `finger_contact` of the element, which is the nearest object surface there); each
  working part other than the instructed one (a knife's blade, a pan's body, a mug's lip) stays
  clear of the hand: no hand point within `working_clearance`.
- Hold: a firm power grasp on the part: the palm touches the part (a palm-face point within
  `palm_contact`) where the part allows it (wider than `palm_min_width` across its long axis),
  and the contacts reach force closure (epsilon of at least `min_epsilon`).
- Handover: the named part is held and the rest is free and reachable for the receiver: no hand
  point within `other_part_clearance` (2 cm) of any other part, and the palm centre on the side
  of the held part away from the object's free end (the receiver's parts).
- Liftup: taken as from a table: the wrist above the object's centre of mass, the palm facing
  down within `max_palm_tilt_deg` (30 degrees), no hand point below the object's lowest point.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from ..errors import InstructionError
from .instructions import INTENTS, TABLE
from .library import CATEGORIES

# Finger roles, hand-independent. The first four are the hand's anchor fingers in hand.json
# order (thumb first); "little" is the first fingertip that is not an anchor finger.
FINGER_ROLES: tuple[str, ...] = ("thumb", "index", "middle", "ring", "little")
# A group role: every fingertip except the thumb.
FINGERS = "fingers"


# ---- the rules and their numbers -----------------------------------------------------------
@dataclass(frozen=True)
class UseRule:
    """Use: named fingers on the functional element, working parts clear of the hand."""

    finger_contact: float = 0.01  # m: a finger's distal link this close to the element is on it
    working_clearance: float = 0.01  # m: no hand point this close to a working part
    # scissors loops: a fingertip centre within the loop's hole (inner radius) and this close
    # to the loop's plane is through the loop
    loop_depth: float = 0.02


@dataclass(frozen=True)
class HoldRule:
    """Hold: palm contact where the part is wide enough for the palm, and force closure."""

    palm_contact: float = 0.01  # m: a palm-face point this close to the part touches it
    # m: the part's wider extent across its long axis; narrower parts (a pen's barrel) need
    # no palm contact
    palm_min_width: float = 0.02
    # m: palm-face points are the palm body's surface points at most this far behind the
    # palm plane (hand.json palm centre and normal): not the back of the hand
    palm_face_depth: float = 0.01
    # m: hand surface points this close to the object are in contact; the points are 3-6 mm
    # apart, so this is about the planner's 6 mm on the exact geometry (Drake): on 135 solved
    # Hold candidates of the three hands, epsilon from these contacts correlates 0.67 with the
    # planner's and agrees with it on ">= 0.1" for 78% (6 mm: 0.45 and 81%, but a third of
    # the planner's passes)
    contact_distance: float = 0.01
    min_epsilon: float = 0.1  # force closure (epsilon, planner.quality) at least this
    friction: float = 0.6  # friction coefficient of the contacts' cones


@dataclass(frozen=True)
class HandoverRule:
    """Handover: other parts clear by 2 cm, the hand away from the free end."""

    other_part_clearance: float = 0.02  # m: no hand point this close to any other part
    # m: the palm centre's offset from the held part's centre toward the free end, at most
    max_side_offset: float = 0.0


@dataclass(frozen=True)
class LiftupRule:
    """Liftup: from above, palm down, nothing below the object."""

    wrist_above_com: float = 0.0  # m: the wrist at least this far above the centre of mass
    max_palm_tilt_deg: float = 30.0  # palm normal within this of straight down
    table_tolerance: float = 0.0  # m: hand points at most this far below the object's bottom


@dataclass(frozen=True)
class Rules:
    use: UseRule = field(default_factory=UseRule)
    hold: HoldRule = field(default_factory=HoldRule)
    handover: HandoverRule = field(default_factory=HandoverRule)
    liftup: LiftupRule = field(default_factory=LiftupRule)


RULES = Rules()

# The sub-criteria of each intent, in the order checks report them.
CRITERIA: dict[str, tuple[str, ...]] = {
    "Use": ("finger_on_element", "working_parts_clear"),
    "Hold": ("palm_contact", "force_closure"),
    "Handover": ("other_parts_clear", "away_from_free_end"),
    "Liftup": ("wrist_above_com", "palm_down", "above_table"),
}
# Criteria measured on the object's shape alone (centre of mass, lowest point, contacts), so
# they can be checked on a cloud without part labels; an intent all of whose criteria are here
# is checked on unlabelled objects too (the learned proposer prefers its samples that meet it).
LABEL_FREE_CRITERIA: frozenset[str] = frozenset(
    {"wrist_above_com", "palm_down", "above_table", "force_closure"}
)


# Criteria the wrist pose alone decides: a learned sample is known to face its intent (or not)
# before it is solved, since the grasp program keeps the drawn wrist rotation.
WRIST_CRITERIA: frozenset[str] = frozenset({"wrist_above_com", "palm_down"})

# ... and with the part labels, Handover's palm on the held part's side away from the free end
# (the palm is rigid with the wrist): what a proposal's drawn wrist already decides
# (planner.intent.proposal_misses)
PALM_CRITERIA: frozenset[str] = WRIST_CRITERIA | {"away_from_free_end"}


# Criteria measured on a part's own points alone (how wide it is, how near the palm is to it):
# on a cloud without labels the region the learned samples point at stands in for the part
# (planner.learned_proposer.region_object). Criteria about the other parts (Handover's
# clearance from them, the receiver's side) or a named element (Use) need the real labels: a
# region is a patch of its part, the rest of which would count as "another part".
REGION_CRITERIA: frozenset[str] = frozenset({"palm_contact"})


def label_free(intent: str) -> bool:
    """Whether every criterion of the intent can be measured without part labels."""
    return set(CRITERIA[intent]) <= LABEL_FREE_CRITERIA


def region_checked(intent: str) -> bool:
    """Whether, on a cloud without labels, the intent is measured with the pointed region as
    its part (Hold: the palm on the region, force closure); not intents measured without any
    part (label_free)."""
    criteria = set(CRITERIA[intent])
    return not label_free(intent) and criteria <= LABEL_FREE_CRITERIA | REGION_CRITERIA


# ---- per category: functional elements, working parts, the receiver's parts ----------------
@dataclass(frozen=True)
class FunctionalElement:
    """A part that a named finger operates.

    rule "all": every finger in `fingers` is on the part; "any": at least one of them is;
    "split": the part has two lobes (scissors loops): the thumb in one and another finger in
    the other (through the loops where that is measured, else on them, one on each side).
    """

    part: str
    fingers: tuple[str, ...]
    rule: str = "all"
    what: str = ""


@dataclass(frozen=True)
class Region:
    """A working part, or the working end of one, that Use keeps clear of the hand.

    end None: the whole part; "+x", "-x", "+y", "-y", "+z", "-z": the part's points within
    `length` of its extreme along that object axis (objects are upright, long tools along x);
    "free": the part's points within `length` of its farthest point from every other part
    (a screwdriver's shaft tip).
    """

    part: str
    what: str
    end: str | None = None
    length: float = 0.0


@dataclass(frozen=True)
class CategoryIntents:
    elements: tuple[FunctionalElement, ...] = ()
    working: tuple[Region, ...] = ()
    # Handover: held part -> the parts the receiver takes (the object's free end); a held part
    # not listed leaves every other part to the receiver
    receiver: Mapping[str, tuple[str, ...]] = field(default_factory=dict)


CATEGORY_INTENTS: dict[str, CategoryIntents] = {
    # a mug's opening is no part of its own: its lip, the top centimetre of the body
    "mug": CategoryIntents(working=(Region("body", "lip", "+z", 0.01),)),
    "cup": CategoryIntents(working=(Region("rim", "opening"),)),
    "bottle": CategoryIntents(
        elements=(FunctionalElement("cap", ("thumb", "index"), "all", "cap (twisted)"),),
        working=(Region("cap", "opening"),),
    ),
    "bowl": CategoryIntents(working=(Region("rim", "opening"),)),
    "wine_glass": CategoryIntents(working=(Region("bowl", "bowl"),)),
    # the receiver of a teapot takes its handle, not its lid or spout
    "teapot": CategoryIntents(working=(Region("spout", "spout"),), receiver={"body": ("handle",)}),
    "knife": CategoryIntents(working=(Region("blade", "blade"),)),
    "hammer": CategoryIntents(working=(Region("head", "head"),)),
    "screwdriver": CategoryIntents(working=(Region("shaft", "shaft tip", "free", 0.02),)),
    "pen": CategoryIntents(working=(Region("tip", "tip"),)),
    "scissors": CategoryIntents(
        elements=(FunctionalElement("handle", ("thumb", FINGERS), "split", "loops"),),
        working=(Region("blade", "blades"),),
    ),
    "spray_bottle": CategoryIntents(
        elements=(FunctionalElement("trigger", ("index",), "all", "trigger"),),
        working=(Region("head", "nozzle", "+x", 0.01),),
    ),
    "lotion_pump": CategoryIntents(
        elements=(FunctionalElement("pump", ("index", "thumb"), "any", "pump head"),),
        working=(Region("pump", "nozzle", "+x", 0.01),),
    ),
    "pan": CategoryIntents(working=(Region("body", "cooking surface"),)),
}

REGION_ENDS = ("+x", "-x", "+y", "-y", "+z", "-z", "free")
ELEMENT_RULES = ("all", "any", "split")


@dataclass(frozen=True)
class Definition:
    """What one (category, intent, part) asks of a grasp: the intent's criteria and, for Use,
    the functional elements on the part and the working parts to keep clear."""

    category: str
    intent: str
    part: str
    criteria: tuple[str, ...]
    elements: tuple[FunctionalElement, ...] = ()
    working: tuple[Region, ...] = ()
    receiver: tuple[str, ...] = ()  # Handover: the free end's parts

    def describe(self) -> str:
        """One line, e.g. 'Use a knife by handle: blade clear'."""
        cat = CATEGORIES[self.category]
        head = f"{self.intent} a {cat.noun} by {self.part}: "
        if self.intent == "Use":
            bits = [
                f"{'/'.join(e.fingers) if e.rule != 'split' else 'thumb | fingers'} on "
                f"{e.what or e.part}" + (" (either)" if e.rule == "any" else "")
                for e in self.elements
            ]
            bits += [f"{w.what} clear" for w in self.working]
            return head + "; ".join(bits)
        if self.intent == "Handover":
            return head + f"other parts clear; hand away from {'/'.join(self.receiver)}"
        if self.intent == "Hold":
            return head + "palm on the part where wide enough; force closure"
        return head + "wrist above the centre of mass; palm down; nothing below the object"


def definition(category_name: str, intent: str, part: str) -> Definition:
    """The definition for one instruction of a library category (any intent and part of it)."""
    if category_name not in CATEGORIES:
        raise InstructionError(f"{category_name!r} is not a library category")
    if intent not in INTENTS:
        raise InstructionError(f"unknown intent {intent!r}; use one of {', '.join(INTENTS)}")
    parts = CATEGORIES[category_name].parts
    if part not in parts:
        raise InstructionError(f"a {category_name} has no part {part!r}; its parts: {parts}")
    spec = CATEGORY_INTENTS.get(category_name, CategoryIntents())
    criteria = CRITERIA[intent]
    if intent == "Use":
        elements = tuple(e for e in spec.elements if e.part == part)
        # a whole working part that is the instructed part is where the hand must be; the
        # working end of the instructed part (a pump head's nozzle) still stays clear
        working = tuple(w for w in spec.working if w.part != part or w.end is not None)
        criteria = tuple(
            c
            for c, present in zip(criteria, (elements, working), strict=True)
            if present  # a criterion with nothing to measure is left out
        )
        return Definition(category_name, intent, part, criteria, elements, working)
    if intent == "Handover":
        receiver = spec.receiver.get(part, tuple(p for p in parts if p != part))
        return Definition(category_name, intent, part, criteria, receiver=receiver)
    return Definition(category_name, intent, part, criteria)


def definitions() -> list[Definition]:
    """The definition of every (category, intent, part) in the instruction table."""
    return [definition(cat, i, p) for cat, rows in TABLE.items() for i, p in rows]


def resolve_fingers(
    anchor_fingers: Sequence[str], fingertips: Sequence[str]
) -> dict[str, tuple[str, ...]]:
    """Finger roles -> fingertip names of one hand, from its hand.json `anchor_fingers` (thumb
    first) and `fingertips` (names, file order). Every role maps to a tuple; roles the hand
    lacks are absent; "fingers" is every fingertip but the thumb."""
    if not anchor_fingers:
        raise InstructionError("a hand needs anchor fingers (thumb first) to resolve fingers")
    extra = [t for t in fingertips if t not in anchor_fingers]
    named = list(anchor_fingers[:4]) + extra[:1]
    roles = {role: (tip,) for role, tip in zip(FINGER_ROLES, named, strict=False)}
    roles[FINGERS] = tuple(t for t in fingertips if t != anchor_fingers[0])
    return roles


def check_tables() -> list[str]:
    """Problems in the data above (empty when consistent): unknown categories, parts, finger
    roles, element rules and region ends, and Use rows with nothing to measure."""
    problems = []
    roles = set(FINGER_ROLES) | {FINGERS}
    for cat, spec in CATEGORY_INTENTS.items():
        if cat not in CATEGORIES:
            problems.append(f"{cat}: not a library category")
            continue
        parts = CATEGORIES[cat].parts
        for e in spec.elements:
            if e.part not in parts:
                problems.append(f"{cat}: element on unknown part {e.part!r}")
            if e.rule not in ELEMENT_RULES:
                problems.append(f"{cat}: element rule {e.rule!r}")
            if not set(e.fingers) <= roles:
                problems.append(f"{cat}: unknown finger roles in {e.fingers}")
        for w in spec.working:
            if w.part not in parts:
                problems.append(f"{cat}: working part {w.part!r} unknown")
            if w.end is not None and (w.end not in REGION_ENDS or w.length <= 0):
                problems.append(f"{cat}: region {w.what!r} end {w.end!r} length {w.length}")
        for held, takes in spec.receiver.items():
            if held not in parts or not takes or not set(takes) <= set(parts) - {held}:
                problems.append(f"{cat}: receiver {held!r} -> {takes!r}")
    for d in definitions():
        if not d.criteria:
            problems.append(f"{d.category}: {d.intent} by {d.part} has nothing to measure")
    return problems


__all__ = [
    "CATEGORY_INTENTS",
    "CRITERIA",
    "CategoryIntents",
    "Definition",
    "FINGERS",
    "FINGER_ROLES",
    "FunctionalElement",
    "Region",
    "RULES",
    "Rules",
    "check_tables",
    "definition",
    "definitions",
    "resolve_fingers",
]
