"""Objects: load real meshes and clouds, or make part-labelled ones from the procedural library.

obj = load_object("scan.ply")            # or an (N, 3) array, in metres
mug = make_object("mug", seed=3)         # watertight, per-face part labels, exact pieces
cloud = mug.sample_cloud(2048, seed=0)   # points, normals, labels
pieces = mug.collision_pieces()          # convex hulls for Drake / MuJoCo
parse_instruction("Use a mug by handle") # Instruction(intent="Use", object="mug", ...)
"""

from .cache import cache_dir
from .collision import cloud_pieces, coacd_pieces, contains
from .generate import export_object, make_object
from .instructions import (
    INTENTS,
    PARAPHRASES,
    TABLE,
    Instruction,
    instruction_text,
    instructions,
    paraphrase,
    parse_instruction,
)
from .library import CATEGORIES, Category, categories, category
from .loading import load_object
from .model import ObjectModel, Samples
from .splits import HELDOUT, SPLITS, seeds, split_of

__all__ = [
    "CATEGORIES",
    "HELDOUT",
    "INTENTS",
    "PARAPHRASES",
    "SPLITS",
    "TABLE",
    "Category",
    "Instruction",
    "ObjectModel",
    "Samples",
    "cache_dir",
    "categories",
    "category",
    "cloud_pieces",
    "coacd_pieces",
    "contains",
    "export_object",
    "instruction_text",
    "instructions",
    "load_object",
    "make_object",
    "paraphrase",
    "parse_instruction",
    "seeds",
    "split_of",
]
