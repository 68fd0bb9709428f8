"""The instruction table: which (intent, part) pairs make sense for each category, and its text.

Canonical text is "[Intent] a [Object] by [Part]" (e.g. "Use a mug by handle"), as in the paper.
Handover names the part the giver holds, leaving the other for the receiver ("Handover a knife by
blade"). Paraphrase templates reword the same request for robustness tests of the text encoder.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from ..errors import InstructionError
from .library import CATEGORIES, category
from .names import INTENTS

MAX_INSTRUCTION = 300  # characters: an instruction is a short sentence (and parsing stays fast)

TABLE: dict[str, tuple[tuple[str, str], ...]] = {
    "mug": (
        ("Use", "handle"),
        ("Hold", "body"),
        ("Liftup", "handle"),
        ("Liftup", "body"),
        ("Handover", "body"),
    ),
    "cup": (("Use", "body"), ("Hold", "body"), ("Liftup", "body"), ("Handover", "rim")),
    "bottle": (
        ("Use", "body"),
        ("Use", "cap"),
        ("Hold", "body"),
        ("Liftup", "neck"),
        ("Handover", "neck"),
    ),
    "bowl": (("Use", "body"), ("Hold", "body"), ("Liftup", "rim"), ("Handover", "rim")),
    "wine_glass": (("Use", "stem"), ("Hold", "bowl"), ("Liftup", "stem"), ("Handover", "bowl")),
    "teapot": (("Use", "handle"), ("Hold", "body"), ("Liftup", "handle"), ("Handover", "body")),
    "knife": (("Use", "handle"), ("Hold", "handle"), ("Liftup", "handle"), ("Handover", "blade")),
    "hammer": (("Use", "handle"), ("Hold", "handle"), ("Liftup", "handle"), ("Handover", "head")),
    "screwdriver": (
        ("Use", "handle"),
        ("Hold", "handle"),
        ("Liftup", "handle"),
        ("Handover", "shaft"),
    ),
    "pen": (("Use", "barrel"), ("Hold", "barrel"), ("Liftup", "barrel"), ("Handover", "cap")),
    "scissors": (
        ("Use", "handle"),
        ("Hold", "handle"),
        ("Liftup", "handle"),
        ("Handover", "blade"),
    ),
    "spray_bottle": (
        ("Use", "trigger"),
        ("Hold", "body"),
        ("Liftup", "head"),
        ("Handover", "body"),
    ),
    "lotion_pump": (("Use", "pump"), ("Hold", "body"), ("Liftup", "body"), ("Handover", "body")),
    "pan": (("Use", "handle"), ("Hold", "handle"), ("Liftup", "handle"), ("Handover", "body")),
}

_VERB = {"Use": "use", "Hold": "hold", "Handover": "hand over", "Liftup": "lift up"}
PARAPHRASES: tuple[str, ...] = (
    "{Verb} the {object} by its {part}",
    "Grab the {object} by the {part} to {verb} it",
    "Take hold of the {part} of the {object} and {verb} it",
    "I want to {verb} the {object}; grasp it at the {part}",
    "Please {verb} this {object}, holding the {part}",
)
_INTENT_WORDS = {
    "use": "Use",
    "hold": "Hold",
    "handover": "Handover",
    "hand over": "Handover",
    "liftup": "Liftup",
    "lift up": "Liftup",
    "lift": "Liftup",
    "pick up": "Liftup",
}
_PATTERN = re.compile(
    r"^\s*(?P<intent>hand\s*over|lift\s*up|pick\s+up|use|hold|lift)\s+(?:(?:a|an|the)\s+)?"
    r"(?P<object>.+?)\s+by\s+(?:(?:the|its)\s+)?(?P<part>.+?)[\s.!]*$",
    re.IGNORECASE,
)


@dataclass(frozen=True)
class Instruction:
    """A parsed instruction; category is None when the object is not a library category."""

    intent: str
    object: str
    part: str
    category: str | None = None

    @property
    def text(self) -> str:
        return f"{self.intent} a {self.object} by {self.part}"

    def paraphrases(self) -> list[str]:
        """The same request in each paraphrase template."""
        return [paraphrase(self, i) for i in range(len(PARAPHRASES))]


def instructions(category_name: str) -> list[Instruction]:
    """Every sensible instruction of a category, in table order."""
    cat = category(category_name)
    return [Instruction(i, cat.noun, p, cat.name) for i, p in TABLE[cat.name]]


def instruction_text(intent: str, category_name: str, part: str) -> str:
    """Canonical text, checked against the table: "Use a mug by handle"."""
    cat = category(category_name)
    if (intent, part) not in TABLE[cat.name]:
        raise InstructionError(
            f"({intent}, {part}) is not an instruction for {cat.noun}; choose one of: "
            + "; ".join(f"{i} a {cat.noun} by {p}" for i, p in TABLE[cat.name])
        )
    return f"{intent} a {cat.noun} by {part}"


def paraphrase(instr: Instruction, template: int) -> str:
    """The instruction reworded by template number `template` (wraps around)."""
    verb = _VERB[instr.intent]
    t = PARAPHRASES[template % len(PARAPHRASES)]
    return t.format(
        Verb=verb[0].upper() + verb[1:], verb=verb, object=instr.object, part=instr.part
    )


def parse_instruction(text: str, strict: bool = False) -> Instruction:
    """Parse "[Intent] a [Object] by [Part]" (case-insensitive; a/an/the, "hand over", "lift up").

    The object is matched to a library category where it names one. With strict=True the object
    must be a category and the part one of its parts.
    """
    if not isinstance(text, str) or not text.strip():
        raise InstructionError(
            'the instruction is empty; write "[Intent] a [Object] by [Part]", e.g. "Use a mug by'
            ' handle" (intents: Use, Hold, Handover, Liftup)'
        )
    if len(text) > MAX_INSTRUCTION:
        raise InstructionError(
            f"the instruction is {len(text)} characters long; write one short sentence of at "
            f'most {MAX_INSTRUCTION}, "[Intent] a [Object] by [Part]"'
        )
    m = _PATTERN.match(text)
    if not m:
        first = text.strip().split()[0]
        hint = (
            f"unknown intent {first!r}; use one of {', '.join(INTENTS)}"
            if " by " in f" {text.lower()} "
            else 'it has no " by [Part]"'
        )
        raise InstructionError(
            f'cannot parse {text!r}: {hint}. Expected "[Intent] a [Object] by [Part]",'
            ' e.g. "Use a mug by handle"'
        )
    intent = _INTENT_WORDS[re.sub(r"\s+", " ", m["intent"].lower())]
    obj = re.sub(r"\s+", " ", m["object"].strip().lower())
    part = re.sub(r"\s+", " ", m["part"].strip().lower())
    key = obj.replace(" ", "_")
    cat = key if key in CATEGORIES else None
    if cat is None and key.endswith("s") and key[:-1] in CATEGORIES:
        cat = key[:-1]
    if strict:
        if cat is None:
            raise InstructionError(
                f"unknown object {obj!r}; library objects: "
                + ", ".join(c.noun for c in CATEGORIES.values())
            )
        if part not in CATEGORIES[cat].parts:
            raise InstructionError(
                f"a {CATEGORIES[cat].noun} has no part {part!r}; its parts are: "
                + ", ".join(CATEGORIES[cat].parts)
            )
    noun = CATEGORIES[cat].noun if cat else obj
    return Instruction(intent, noun, part, cat)
