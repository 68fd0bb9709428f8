"""How often `learned.understand` reads a reworded instruction as the instruction it rewords.

Every instruction of the table, reworded with the training templates and verbs and with the
evaluation-only ones (learned.paraphrase), and 16 sentences of neither set (WRITTEN) are read
back; the share read with the right intent
and as the right instruction is printed per set, with the commonest intent confusions:

    python -m eval.understanding
"""

from __future__ import annotations

import argparse
from collections import Counter
from dataclasses import dataclass

from learned.paraphrase import eval_paraphrases, request_of, train_paraphrases
from learned.text import encode
from learned.understand import understand
from models.objects.instructions import Instruction, instructions, parse_instruction
from models.objects.library import CATEGORIES


@dataclass
class Reading:
    """One set of rewordings read back: how many, how many with the right intent and the
    right instruction, and the (meant, read) intents of the misreadings."""

    name: str
    sentences: int
    intent_right: int
    instruction_right: int
    confusions: Counter


# sentences of neither rewording set, each with the instruction it asks: two verbs, "hand" as
# a noun, clauses a parse catches
WRITTEN: tuple[tuple[str, str], ...] = (
    ("Please lift the pan, grasping it by the handle", "Liftup a pan by handle"),
    ("hold the cup in your hand by its body", "Hold a cup by body"),
    ("Could you hand me the knife? Hold it by the blade.", "Handover a knife by blade"),
    ("pick up the mug and hold it by the handle", "Liftup a mug by handle"),
    ("use the spray bottle, index finger on the trigger", "Use a spray bottle by trigger"),
    ("grip the hammer handle firmly", "Hold a hammer by handle"),
    ("raise the bottle, hold it around the neck", "Liftup a bottle by neck"),
    ("give me the scissors, keep hold of the blade", "Handover a scissors by blade"),
    ("pass the pen to me holding the cap", "Handover a pen by cap"),
    ("operate the lotion pump, grasp it at the pump", "Use a lotion pump by pump"),
    ("hold the wine glass by the stem and lift it", "Hold a wine glass by stem"),
    ("Grab the mug by its handle so you can lift it up", "Liftup a mug by handle"),
    ("with your hand on the handle, use the knife", "Use a knife by handle"),
    ("keep hold of the pan by its handle", "Hold a pan by handle"),
    ("hand over the bowl by its body", "Handover a bowl by body"),
    ("lift up the spray bottle by its head", "Liftup a spray bottle by head"),
)


def read_back(name: str, reword) -> Reading:
    """Every table instruction's rewordings by `reword` (Request -> sentences), read back."""
    table = [i for category in CATEGORIES for i in instructions(category)]
    return read_sentences(
        name, [(text, ins) for ins in table for text in reword(request_of(ins.text))]
    )


def read_sentences(name: str, pairs: list[tuple[str, Instruction]]) -> Reading:
    """(sentence, the instruction it asks) pairs read back with `understand`."""
    encode([text for text, _ in pairs])  # one batch; understand() then reads the cache
    out = Reading(name, len(pairs), 0, 0, Counter())
    for text, ins in pairs:
        read = understand(text).instruction
        out.intent_right += read.intent == ins.intent
        out.instruction_right += read.text == ins.text
        if read.intent != ins.intent:
            out.confusions[ins.intent, read.intent] += 1
    return out


def main(argv: list[str] | None = None) -> None:
    argparse.ArgumentParser(description=__doc__.split("\n\n")[0]).parse_args(argv)
    print("| rewordings | sentences | intent read right | instruction read right | misread as |")
    print("|---|---|---|---|---|")
    for reading in (
        read_back("training", train_paraphrases),
        read_back("evaluation-only", eval_paraphrases),
        read_sentences("written", [(t, parse_instruction(i)) for t, i in WRITTEN]),
    ):
        n = reading.sentences
        confused = ", ".join(f"{a} as {b} {k}" for (a, b), k in reading.confusions.most_common(4))
        print(
            f"| {reading.name} | {n} | {100 * reading.intent_right / n:.1f}% "
            f"| {100 * reading.instruction_right / n:.1f}% | {confused or 'none'} |"
        )


if __name__ == "__main__":
    main()
