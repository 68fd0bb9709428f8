"""How often `learned.understand` reads a reworded instruction as the instruction it rewords.

Every instruction of the table, reworded with the training templates and verbs and with the
evaluation-only ones (learned.paraphrase), is read back; the share read with the right intent
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
from models.objects.instructions import instructions
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


def read_back(name: str, reword) -> Reading:
    """Every table instruction's rewordings by `reword` (Request -> sentences), read back."""
    table = [i for category in CATEGORIES for i in instructions(category)]
    pairs = [(text, ins) for ins in table for text in reword(request_of(ins.text))]
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
    ):
        n = reading.sentences
        confused = ", ".join(f"{a} as {b} {k}" for (a, b), k in reading.confusions.most_common(4))
        print(
            f"| {reading.name} | {n} | {100 * reading.intent_right / n:.1f}% "
            f"| {100 * reading.instruction_right / n:.1f}% | {confused or 'none'} |"
        )


if __name__ == "__main__":
    main()
