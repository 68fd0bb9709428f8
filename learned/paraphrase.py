"""Paraphrase banks: how people word the table's instructions, for training and (apart) for tests.

The dataset's instructions are all "[Intent] a [Object] by [Part]"; a model trained on those
alone learns the template, not the request. Training rewrites each instruction at random from
TRAIN_TEMPLATES with a verb from TRAIN_VERBS[intent] and a part phrase; the evaluation-only
EVAL_TEMPLATES (other sentence frames, other verbs) measure whether the encoder and the model
generalise to wordings never seen in training. The two template sets are disjoint, and so are
the sentences they produce (tests/test_interaction.py checks both).
"""

from __future__ import annotations

import random
import re
from dataclasses import dataclass

from models.errors import InstructionError

INTENTS: tuple[str, ...] = ("Use", "Hold", "Handover", "Liftup")

# verbs per intent, infinitive form ("to {verb} it")
TRAIN_VERBS: dict[str, tuple[str, ...]] = {
    "Use": ("use", "operate", "work with", "make use of"),
    "Hold": ("hold", "grasp", "grip", "keep hold of"),
    "Handover": ("hand over", "pass", "give", "hand"),
    "Liftup": ("lift up", "pick up", "lift", "raise"),
}
EVAL_VERBS: dict[str, tuple[str, ...]] = {
    "Use": ("employ", "utilise"),
    "Hold": ("clutch", "clasp"),
    "Handover": ("deliver", "hand off"),
    "Liftup": ("hoist", "take up"),
}

# sentence frames; {verb} infinitive, {Verb} capitalised, {obj} noun phrase, {part} part noun
TRAIN_TEMPLATES: tuple[str, ...] = (
    "{Intent} a {obj} by {part}",
    "{Verb} the {obj} by its {part}",
    "{Verb} a {obj} by the {part}",
    "{Verb} the {obj}, holding the {part}",
    "{Verb} the {obj} holding it by the {part}",
    "please {verb} the {obj} by its {part}",
    "Could you {verb} the {obj} by the {part}?",
    "{Verb} {objs} by their {part}s",
    "grab the {obj} by the {part} to {verb} it",
    "by the {part}, {verb} the {obj}",
    "{verb} {obj} {part}",
    "I need you to {verb} that {obj} by the {part}",
    "take the {part} of the {obj} and {verb} it",
    "{Verb} the {obj} with your fingers on the {part}",
)
EVAL_TEMPLATES: tuple[str, ...] = (
    "Would you kindly {verb} this {obj}? Grasp it at the {part}.",
    "The {obj}: {verb} it, fingers around its {part}",
    "My request is that you {verb} the {obj} using the {part}",
    "Go ahead and {verb} one of the {objs}; touch only the {part}",
    "{part} of the {obj} -- {verb} it from there",
    "{Verb} this {obj} gripping the {part} part",
)


@dataclass(frozen=True)
class Request:
    """What an instruction asks: intent, the object's noun (e.g. "wine glass") and the part."""

    intent: str
    noun: str
    part: str


def _plural(noun: str) -> str:
    if noun.endswith(("ss", "sh", "ch", "x")):
        return noun + "es"
    if noun.endswith("s"):  # scissors
        return noun
    if noun.endswith("fe"):
        return noun[:-2] + "ves"
    return noun + "s"


def _render(template: str, verb: str, req: Request) -> str:
    text = template.format(
        Intent=req.intent,
        verb=verb,
        Verb=verb[0].upper() + verb[1:],
        obj=req.noun,
        objs=_plural(req.noun),
        part=req.part,
    )
    return re.sub(r"\b([Aa]) (?=[aeiou])", r"\1n ", text)  # "an item", "an object"


def _check(req: Request) -> None:
    if req.intent not in INTENTS:
        raise InstructionError(f"unknown intent {req.intent!r}; one of {INTENTS}")


def train_paraphrase(req: Request, rng: random.Random) -> str:
    """One training rewording of the request, drawn at random (the canonical form included)."""
    _check(req)
    template = rng.choice(TRAIN_TEMPLATES)
    return _render(template, rng.choice(TRAIN_VERBS[req.intent]), req)


def train_paraphrases(req: Request) -> list[str]:
    """Every training rewording of the request (templates x verbs), canonical form first."""
    _check(req)
    out = [_render(TRAIN_TEMPLATES[0], TRAIN_VERBS[req.intent][0], req)]
    for t in TRAIN_TEMPLATES[1:]:
        out += [_render(t, v, req) for v in TRAIN_VERBS[req.intent]]
    return list(dict.fromkeys(out))


# nouns that name no category: a share of training steps words the request with one of these, so
# the model must find the part from the cloud and the part word, not from the category's name
# (a held-out category's name is a word the model never saw with a grasp)
GENERIC_NOUNS: tuple[str, ...] = ("object", "thing", "item")


def generic_paraphrases(req: Request) -> list[str]:
    """Every training rewording of the request with the object's noun replaced by a generic one."""
    out: list[str] = []
    for noun in GENERIC_NOUNS:
        out += train_paraphrases(Request(req.intent, noun, req.part))
    return list(dict.fromkeys(out))


def eval_paraphrases(req: Request) -> list[str]:
    """The evaluation-only rewordings (never used in training), one per template, verbs cycling."""
    _check(req)
    verbs = EVAL_VERBS[req.intent]
    return [_render(t, verbs[i % len(verbs)], req) for i, t in enumerate(EVAL_TEMPLATES)]


def request_of(instruction: str) -> Request:
    """The request behind a canonical "[Intent] a [Object] by [Part]" instruction."""
    from models.objects.instructions import parse_instruction

    parsed = parse_instruction(instruction)
    return Request(parsed.intent, parsed.object, parsed.part)
