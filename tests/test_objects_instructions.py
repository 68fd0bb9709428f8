"""Instruction table, text, paraphrases, parsing, and dataset splits."""

from __future__ import annotations

from collections import Counter

import pytest

from models.errors import InstructionError
from models.objects import (
    CATEGORIES,
    HELDOUT,
    INTENTS,
    TABLE,
    categories,
    instruction_text,
    instructions,
    parse_instruction,
    seeds,
    split_of,
)


def test_every_category_has_two_or_more_instructions_on_existing_parts():
    assert set(TABLE) == set(categories())
    for name in categories():
        rows = instructions(name)
        assert len(rows) >= 2
        for instr in rows:
            assert instr.part in CATEGORIES[name].parts, (name, instr)
            assert instr.intent in INTENTS
        assert len({(i.intent, i.part) for i in rows}) == len(rows)


def test_all_intents_covered():
    used = {i.intent for name in categories() for i in instructions(name)}
    assert used == set(INTENTS) == {"Use", "Hold", "Handover", "Liftup"}


def test_canonical_text_and_round_trip():
    assert instruction_text("Use", "mug", "handle") == "Use a mug by handle"
    assert instruction_text("Handover", "knife", "blade") == "Handover a knife by blade"
    for name in categories():
        for instr in instructions(name):
            back = parse_instruction(instr.text, strict=True)
            assert back == instr


def test_parse_tolerates_case_articles_and_spaced_intents():
    i = parse_instruction("  hand over the Spray Bottle by its trigger. ")
    assert (i.intent, i.object, i.part, i.category) == (
        "Handover",
        "spray bottle",
        "trigger",
        "spray_bottle",
    )
    assert parse_instruction("Lift up an bowl by rim").intent == "Liftup"
    unknown = parse_instruction("Use a drill by handle")
    assert unknown.category is None and unknown.object == "drill"


def test_paraphrases_differ_and_keep_the_words():
    instr = instructions("mug")[0]
    texts = instr.paraphrases()
    assert len(set(texts)) == len(texts) >= 3
    for t in texts:
        assert "mug" in t and "handle" in t and t != instr.text


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", "empty"),
        ("   ", "empty"),
        ("Use a mug", 'no " by'),
        ("Throw a mug by handle", "unknown intent 'Throw'"),
    ],
)
def test_parse_errors_say_what_to_write(text, message):
    with pytest.raises(InstructionError, match=message) as err:
        parse_instruction(text)
    assert "Use a mug by handle" in str(err.value)


def test_strict_parse_checks_object_and_part():
    with pytest.raises(InstructionError, match="unknown object 'drill'"):
        parse_instruction("Use a drill by handle", strict=True)
    with pytest.raises(InstructionError, match="its parts are: body, handle"):
        parse_instruction("Use a mug by spout", strict=True)
    with pytest.raises(InstructionError, match="not an instruction for mug"):
        instruction_text("Use", "mug", "body")


def test_instance_split_is_exactly_8_1_1_per_block_of_ten():
    for name in categories():
        if name in HELDOUT:
            continue
        for block in range(3):
            counts = Counter(split_of(name, s) for s in range(10 * block, 10 * block + 10))
            assert counts == {"train": 8, "val": 1, "test": 1}
        assert split_of(name, 17) == split_of(name, 17)
    # not the same positions in every category and block
    patterns = {tuple(split_of(n, s) for s in range(10)) for n in ("mug", "knife", "bowl", "pen")}
    assert len(patterns) > 1


def test_heldout_categories():
    assert len(HELDOUT) >= 2 and set(HELDOUT) <= set(categories())
    for name in HELDOUT:
        assert {split_of(name, s) for s in range(30)} == {"heldout"}
        assert seeds(name, "train", 5) == []
    train = seeds("mug", "train", 16)
    assert len(train) == 16 and all(split_of("mug", s) == "train" for s in train)
    assert seeds("mug", "heldout", 3) == []
