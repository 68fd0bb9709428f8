"""What a free-form instruction asks, in the table's terms: the nearest canonical instruction.

The learned planner reads any sentence ("grab the mug by its handle"), but its result, its
records and its intent check speak in "[Intent] a [Object] by [Part]" (the instruction table,
models.objects.instructions.TABLE). `understand` embeds the sentence with the same encoder the
models use (learned.text) and returns the table's instruction whose training rewordings lie
closest on average. Sentence embeddings weigh the object and part far above the verb ("grab
the mug by its handle" sits nearer Liftup than Hold), so where the sentence names an intent's
verbs (learned.paraphrase's training and evaluation verbs, "pick up", "hand"), only that
intent's instructions are considered; where it names several, the first one's: a request's own
verb comes first, and a later one says how the part is held ("hoist this mug? Grasp it at the
handle"). A sentence that already parses keeps its parse: the
table is consulted only for what the parser cannot read.
"""

from __future__ import annotations

import re
import threading
from dataclasses import dataclass

import numpy as np

from learned.paraphrase import EVAL_VERBS, TRAIN_TEMPLATES, TRAIN_VERBS, Request, _render
from models.errors import InstructionError
from models.objects.instructions import Instruction, instructions, parse_instruction
from models.objects.library import CATEGORIES


@dataclass(frozen=True)
class Understood:
    """The sentence, the instruction it was read as, and how (parsed, or nearest by meaning
    with its cosine similarity and the runner-up's)."""

    text: str
    instruction: Instruction
    parsed: bool
    similarity: float = 1.0
    runner_up: str | None = None
    runner_up_similarity: float | None = None

    def to_dict(self) -> dict:
        return {
            "text": self.text,
            "understood_as": self.instruction.text,
            "parsed": self.parsed,
            "similarity": round(self.similarity, 4),
            "runner_up": self.runner_up,
            "runner_up_similarity": (
                None if self.runner_up_similarity is None else round(self.runner_up_similarity, 4)
            ),
        }


_lock = threading.Lock()
_table: tuple[list[Instruction], np.ndarray] | None = None


def _rewordings(instr: Instruction) -> list[str]:
    """The canonical form and one training rewording per sentence frame and verb."""
    req = Request(instr.intent, instr.object, instr.part)
    out = [instr.text]
    for template in TRAIN_TEMPLATES[1:]:
        out += [_render(template, verb, req) for verb in TRAIN_VERBS[instr.intent][:2]]
    return out


def table_embeddings() -> tuple[list[Instruction], np.ndarray]:
    """Every table instruction and the unit mean embedding of its rewordings (cached)."""
    global _table
    with _lock:
        if _table is None:
            from learned.text import encode

            table = [i for name in CATEGORIES for i in instructions(name)]
            groups = [_rewordings(i) for i in table]
            vecs = encode([s for g in groups for s in g])
            means, start = [], 0
            for g in groups:
                m = vecs[start : start + len(g)].mean(axis=0)
                means.append(m / max(float(np.linalg.norm(m)), 1e-12))
                start += len(g)
            _table = (table, np.stack(means).astype(np.float32))
        return _table


# a word after these is a noun, not a verb ("your hand", "the use", "a good grip")
DETERMINERS = ("a", "an", "the", "my", "your", "his", "her", "its", "our", "their", "this", "that")


def named_intents(text: str) -> list[str]:
    """The intents whose verbs (training or evaluation wordings) occur in `text` as verbs, in
    the order they first occur; a verb's word right after a determiner is taken as a noun."""
    words = " " + re.sub(r"[^a-z]+", " ", text.lower()) + " "
    first: dict[str, int] = {}
    for intent in TRAIN_VERBS:
        for verb in TRAIN_VERBS[intent] + EVAL_VERBS[intent]:
            for found in re.finditer(f" {verb} ", words):
                before = words[: found.start()].split()
                if not before or before[-1] not in DETERMINERS:
                    first[intent] = min(found.start(), first.get(intent, found.start()))
                    break
    return sorted(first, key=first.get)


def _named(phrase: str, words: list[str]) -> list[str]:
    """The words (single or several) that `phrase` contains as whole words, longest first."""
    padded = f" {phrase} "
    return sorted((w for w in words if f" {w} " in padded), key=len, reverse=True)


def repaired(instruction: Instruction) -> Instruction | None:
    """A parse as it stands, or mended where it caught a clause in its object or part ("pick
    up the mug and hold it by the handle": object "mug and hold it"; "by the stem and lift it"):
    the library category or part the phrase names, the longest where several match ("spray
    bottle" over "bottle"); None where the phrase names none or is ambiguous (read by meaning
    instead). A user's own object or part word ("Use a widget by knob") stands."""
    ins = instruction
    if ins.category is None:
        by_noun = {c.noun: name for name, c in CATEGORIES.items()}
        by_noun |= {noun + "s": name for noun, name in list(by_noun.items())}
        found = _named(ins.object, list(by_noun))
        if not found:
            return ins
        if len(found) > 1 and found[1] not in found[0]:
            return None
        category = by_noun[found[0]]
        ins = Instruction(ins.intent, CATEGORIES[category].noun, ins.part, category)
    parts = CATEGORIES[ins.category].parts
    if ins.part in parts:
        return ins
    by_word = {p: p for p in parts} | {p + "s": p for p in parts}  # "by their necks"
    found = {by_word[w] for w in _named(ins.part, list(by_word))}
    if len(found) != 1:
        return ins if ins is instruction and not found else None
    return Instruction(ins.intent, ins.object, found.pop(), ins.category)


def understand(text: str) -> Understood:
    """The instruction `text` asks for: its parse where it parses, else the nearest table
    instruction by meaning. Raises InstructionError for an empty or overlong text."""
    from learned.text import encode

    if not isinstance(text, str) or not text.strip():
        raise InstructionError(
            'the instruction is empty; write what to do with which part, e.g. "Use a mug by '
            'handle" or "grab the mug by its handle"'
        )
    try:
        parsed = repaired(parse_instruction(text))
        if parsed is not None:
            return Understood(text, parsed, parsed=True)
    except InstructionError as err:
        if "characters long" in str(err):
            raise
    table, means = table_embeddings()
    sims = means @ encode([text])[0]
    named = named_intents(text)
    if named:  # the request's own verb comes first ("hoist this mug? Grasp it at the handle")
        sims = np.where([i.intent == named[0] for i in table], sims, -2.0)
    order = np.argsort(-sims)
    best, second = int(order[0]), int(order[1])
    return Understood(
        text,
        table[best],
        parsed=False,
        similarity=float(sims[best]),
        runner_up=table[second].text,
        runner_up_similarity=float(sims[second]),
    )
