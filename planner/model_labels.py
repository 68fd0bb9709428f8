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

import itertools
from dataclasses import dataclass, replace

import numpy as np
from scipy import sparse
from scipy.sparse.linalg import splu
from scipy.spatial import cKDTree

from models.hands import HandModel
from models.objects import Instruction, ObjectModel
from models.objects.instructions import instructions
from models.objects.intents import Definition
from models.objects.library import CATEGORIES
from planner.intent import intent_definition
from planner.learned_proposer import pointed_region

# samples drawn for each part other than the instructed one (whose own samples are reused),
# and how far from its seed the instructed part's label reaches (`trim_held`); planning takes
# LearnedSettings.label_samples and .held_reach
PART_SAMPLES = 16
HELD_REACH = 0.03  # m
# a part's seed: the points within SEED_RADIUS of the anchors of SEED_VOTES of the samples
# that point at the same region as most do (pointed_region)
SEED_RADIUS = 0.006  # m
SEED_VOTES = 1
# the random walk that spreads the seeds' labels (`spread_labels`): on this many of the points,
# each joined to this many nearest; a convex crease costs this fraction of a concave one
# two parts whose seeds share more than this share of the smaller one's points are not told
# apart by the model (a screwdriver's shaft, a part word no training category has, is sought
# on its handle: 0.49); adjacent parts it does tell apart share up to 0.25 (a bowl's body and
# rim; one object per category of the validation split, Allegro's samples)
MAX_SEED_OVERLAP = 0.4
GRAPH_POINTS = 4096
GRAPH_NEIGHBOURS = 10
CONVEX_WEIGHT = 0.2


@dataclass
class ModelLabels:
    """The cloud labelled by the interaction model, the definition measured on it, and how
    many points each part's seed region had (0: a part no table instruction names, labelled
    by its neighbours)."""

    obj: ObjectModel
    meaning: Definition
    seeds: dict[str, int]
    held_seed: np.ndarray  # (N,) mask: the points the instructed part's samples point at

    def near_seed(self, reach: float) -> ObjectModel:
        """The labelled object with the instructed part kept within `reach` (m) of the points
        its samples point at (`trim_held`): where the model's label of the part is sure."""
        names = self.obj.part_names
        held = names.index(self.meaning.part)
        labels = trim_held(self.obj.points, self.obj.point_labels, self.held_seed, held, reach)
        return replace(self.obj, cloud_labels=labels, _derived={})


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


def part_seeds(
    obj: ObjectModel,
    instruction: Instruction,
    hand: HandModel,
    anchors: np.ndarray | None,
    seed: int = 0,
    weights: str | None = None,
    steps: int | None = None,
    samples: int = PART_SAMPLES,
) -> dict[str, np.ndarray]:
    """Each sought part's seed: a mask of the object's points its `samples` point at, asked
    in the table's words (`part_texts`; parts of 8 points or more). `anchors`: samples
    already drawn for the instruction in those words, which seed its own part; None: drawn
    here, as for a free sentence, whose samples follow its own wording ("hand me the knife
    handle first", read as Handover by the blade, draws them on the handle). {} outside the
    library."""
    if instruction.category not in CATEGORIES:
        return {}
    from learned.interaction import load_model

    model = load_model(weights)
    masks: dict[str, np.ndarray] = {}
    for part, text in part_texts(instruction).items():
        if part == instruction.part and anchors is not None:
            drawn = anchors
        elif text is None:
            continue
        else:
            _, drawn = model.sample(obj.points, text, hand, samples, None, steps, seed=seed)
        mask = pointed_region(obj.points, drawn, SEED_RADIUS, SEED_VOTES)
        if mask.sum() >= 8:
            masks[part] = mask
    return masks


def labels_from_seeds(
    obj: ObjectModel,
    instruction: Instruction,
    masks: dict[str, np.ndarray],
    spread: str = "walk",
    held_reach: float = HELD_REACH,
) -> ModelLabels | None:
    """The object's points labelled with the parts of the instruction's category from their
    seeds (`part_seeds`). None where the instructed part or every other part has no seed, where
    a part the definition measures (the held part, a working part, an element) has none, or
    where two parts' seeds overlap (`MAX_SEED_OVERLAP`). `spread`: how the seeds' labels reach
    the other points, "walk" (`spread_labels`) or "nearest" (each point takes its nearest
    seed's label: the baseline eval.model_labels measures beside it). `held_reach` (m, 0:
    off): the instructed part only within this of its seed (`trim_held`)."""
    if instruction.part not in masks or len(masks) < 2:
        return None
    for a, b in itertools.combinations(masks.values(), 2):
        if (a & b).sum() > MAX_SEED_OVERLAP * min(a.sum(), b.sum()):
            return None
    names = CATEGORIES[instruction.category].parts
    seeds = {names.index(p): m for p, m in masks.items()}
    if spread == "walk":
        labels = spread_labels(obj.points, obj.normals, seeds)
    else:
        labels = nearest_seed(obj.points, seeds)
    if held_reach > 0:
        held = names.index(instruction.part)
        labels = trim_held(obj.points, labels, masks[instruction.part], held, held_reach)
    labelled = ObjectModel(
        name=obj.name,
        cloud=obj.points,
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
    counts = {p: int(masks[p].sum()) if p in masks else 0 for p in names}
    return ModelLabels(labelled, meaning, counts, masks[instruction.part])


def model_labels(
    obj: ObjectModel,
    instruction: Instruction,
    hand: HandModel,
    anchors: np.ndarray | None,
    seed: int = 0,
    weights: str | None = None,
    steps: int | None = None,
    samples: int = PART_SAMPLES,
    held_reach: float = HELD_REACH,
) -> ModelLabels | None:
    """The object's parts found by the interaction model (`part_seeds`) and spread over its
    points by the random walk (`labels_from_seeds`); None where they cannot be trusted."""
    masks = part_seeds(obj, instruction, hand, anchors, seed, weights, steps, samples)
    return labels_from_seeds(obj, instruction, masks, held_reach=held_reach)


def trim_held(
    points: np.ndarray, labels: np.ndarray, seed: np.ndarray, held: int, reach: float
) -> np.ndarray:
    """The labels with the held part kept only within `reach` of its seed (mask): its points
    beyond take the label of their nearest point of another part. Where a part's seeds are
    sparse the walk can carry the held label far over it (a pan's handle over half its body);
    the held part is where the grasp goes and the others what it keeps clear of, so a point
    the model did not point at counts as another part's."""
    out = labels.copy()
    far = (labels == held) & (cKDTree(points[seed]).query(points)[0] > reach)
    others = np.flatnonzero(labels != held)
    if far.any() and len(others):
        out[far] = labels[others[cKDTree(points[others]).query(points[far])[1]]]
    return out


def nearest_seed(points: np.ndarray, seeds: dict[int, np.ndarray]) -> np.ndarray:
    """A label for every point: its nearest seed point's (label -> (N,) mask)."""
    index = np.concatenate([np.flatnonzero(m) for m in seeds.values()])
    label = np.concatenate([np.full(int(m.sum()), k) for k, m in seeds.items()])
    return label[cKDTree(points[index]).query(points)[1]]


def spread_labels(
    points: np.ndarray, normals: np.ndarray, seeds: dict[int, np.ndarray], seed: int = 0
) -> np.ndarray:
    """A label for every point from seed masks (label -> (N,) mask), by a random walk on the
    surface (Grady's random walker): each point takes the label whose seeds a walk from it
    reaches first. Steps across a crease are unlikely, concave ones (where a handle meets a
    body, a stem a bowl) five times more than convex ones (Lai et al.'s weights), so the
    borders settle in the creases between parts, not halfway between the seeds, which lie
    where the samples' fingers go. Solved on GRAPH_POINTS of the points; the rest take their
    nearest one's label."""
    rng = np.random.default_rng(seed)
    pick = np.sort(rng.choice(len(points), min(GRAPH_POINTS, len(points)), replace=False))
    p, n = points[pick], normals[pick]
    given = np.full(len(pick), -1)
    for label, mask in seeds.items():
        mine = mask[pick]
        given[mine & (given == -1)] = label
        given[mine & (given != label)] = -2  # in two parts' seeds: left to the walk
    given[given == -2] = -1
    _, nb = cKDTree(p).query(p, GRAPH_NEIGHBOURS + 1)
    i = np.repeat(np.arange(len(p)), GRAPH_NEIGHBOURS)
    j = nb[:, 1:].ravel()
    bend = 1.0 - np.einsum("ij,ij->i", n[i], n[j])
    concave = np.einsum("ij,ij->i", n[i] - n[j], p[i] - p[j]) < 0
    bend = np.where(concave, 1.0, CONVEX_WEIGHT) * np.clip(bend, 0.0, 2.0)
    w = np.exp(-bend / max(float(bend.mean()), 1e-9))
    graph = sparse.coo_matrix((w, (i, j)), shape=(len(p), len(p))).tocsr()
    graph = graph.maximum(graph.T)  # undirected
    lap = sparse.diags(np.asarray(graph.sum(axis=1)).ravel()) - graph
    free, fixed = np.flatnonzero(given < 0), np.flatnonzero(given >= 0)
    order = sorted(seeds)
    onehot = (given[fixed][:, None] == np.array(order)[None]).astype(float)
    # a small pull toward no label keeps parts the seeds cannot reach solvable
    system = (lap[free][:, free] + 1e-9 * sparse.eye(len(free))).tocsc()
    reach = splu(system).solve(-(lap[free][:, fixed] @ onehot))
    sub = given.copy()
    sub[free] = np.array(order)[np.argmax(reach, axis=1)]
    return sub[cKDTree(p).query(points)[1]]
