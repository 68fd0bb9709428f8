"""Part labels for an unlabelled cloud, asked of the interaction model.

Use and Handover are measured against the object's other parts (the blade a knife's user
keeps clear, the handle a receiver takes), so on a bare cloud the learned proposer could not
check them, and its grasps met them about half as often as the model-based planner's with
labels. The interaction model knows where each part word of a category lands (97% of its
samples on the instructed part of the test objects): asked for every instructible part of the
category the sentence was understood as, the region each part's samples point at
(planner.learned_proposer.pointed_region) seeds that part, and every other point takes the
label of the nearest seed. The result stands in for the labels in the intent's definition,
its check and its keep-outs (planner.intent_pieces); what the grasp must touch is still decided
as on any unlabelled cloud.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from models.hands import HandModel
from models.objects import Instruction, ObjectModel
from models.objects.instructions import instructions
from models.objects.intents import Definition
from models.objects.library import CATEGORIES
from planner.intent import intent_definition
from planner.learned_proposer import pointed_region

# samples drawn for each part other than the instructed one (whose own samples are reused)
PART_SAMPLES = 8
# a part's seed: the points within SEED_RADIUS of the anchors of SEED_VOTES of the samples
# that point at the same region as most do (pointed_region)
SEED_RADIUS = 0.01  # m
SEED_VOTES = 1


@dataclass
class ModelLabels:
    """The cloud labelled by the interaction model, the definition measured on it, and how
    many points each part's seed region had (0: a part no table instruction names, labelled
    by its neighbours)."""

    obj: ObjectModel
    meaning: Definition
    seeds: dict[str, int]


def part_texts(instruction: Instruction) -> dict[str, str | None]:
    """For each part of the instruction's category, the table instruction that asks for it
    (the instruction's own intent where the table has it): what the model is asked to find
    the part with; None where no instruction names the part (a pen's tip, a glass's foot)."""
    table = instructions(instruction.category)
    texts: dict[str, str | None] = {}
    for part in CATEGORIES[instruction.category].parts:
        asks = [i for i in table if i.part == part]
        own = [i for i in asks if i.intent == instruction.intent]
        texts[part] = (own or asks)[0].text if asks else None
    return texts


def model_labels(
    obj: ObjectModel,
    instruction: Instruction,
    hand: HandModel,
    anchors: np.ndarray,
    seed: int = 0,
    weights: str | None = None,
    steps: int | None = None,
) -> ModelLabels | None:
    """The object's points labelled with the parts of the instruction's category, each part
    found by the interaction model (`anchors`: the samples already drawn for the instruction,
    which seed its own part). None where the instruction names no library category, where a
    part the definition measures (the held part, a working part, an element) got no seed
    region, or where the part's seeds cover fewer than 8 points."""
    if instruction.category not in CATEGORIES:
        return None
    from learned.interaction import load_model

    points = obj.points
    model = load_model(weights)
    names = CATEGORIES[instruction.category].parts
    masks: dict[str, np.ndarray] = {}
    for part, text in part_texts(instruction).items():
        if part == instruction.part:
            drawn = anchors
        elif text is None:
            continue
        else:
            _, drawn = model.sample(points, text, hand, PART_SAMPLES, None, steps, seed=seed)
        mask = pointed_region(points, drawn, SEED_RADIUS, SEED_VOTES)
        if mask.sum() >= 8:
            masks[part] = mask
    if instruction.part not in masks or len(masks) < 2:
        return None
    seeded = list(masks)
    seed_points = np.concatenate([np.flatnonzero(masks[p]) for p in seeded])
    seed_label = np.concatenate([np.full(int(masks[p].sum()), names.index(p)) for p in seeded])
    _, nearest = cKDTree(points[seed_points]).query(points)
    labels = seed_label[nearest]
    labelled = ObjectModel(
        name=obj.name,
        cloud=points,
        cloud_normals=obj.normals,
        cloud_labels=labels,
        part_names=names,
        category=instruction.category,
        seed=obj.seed,
    )
    meaning = intent_definition(labelled, instruction)
    measured = {meaning.part} | {r.part for r in meaning.working}
    measured |= {e.part for e in meaning.elements}
    if not measured <= set(masks):
        return None
    return ModelLabels(labelled, meaning, {p: int(masks.get(p, np.zeros(1)).sum()) for p in names})
