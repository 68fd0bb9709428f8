"""Objects: load real meshes and clouds, or make part-labelled ones from the procedural library.

obj = load_object("scan.ply")            # or an (N, 3) array, in metres
mug = make_object("mug", seed=3)         # watertight, per-face part labels, exact pieces
cloud = mug.sample_cloud(2048, seed=0)   # points, normals, labels
pieces = mug.collision_pieces()          # convex hulls for Drake / MuJoCo
parse_instruction("Use a mug by handle") # Instruction(intent="Use", object="mug", ...)

Names are resolved on first use (PEP 562), so that `from models.objects.names import ...` and
the CLI's start-up do not import trimesh and manifold3d.
"""

from __future__ import annotations

import importlib
import sys
import types
from typing import Any

_WHERE: dict[str, str] = {
    "cache_dir": "cache",
    "cloud_pieces": "collision",
    "coacd_pieces": "collision",
    "contains": "collision",
    "export_object": "generate",
    "make_object": "generate",
    "INTENTS": "names",
    "PARAPHRASES": "instructions",
    "TABLE": "instructions",
    "Instruction": "instructions",
    "instruction_text": "instructions",
    "instructions": "instructions",
    "paraphrase": "instructions",
    "parse_instruction": "instructions",
    "CATEGORIES": "library",
    "Category": "library",
    "categories": "names",
    "category": "library",
    "load_object": "loading",
    "ObjectModel": "model",
    "Samples": "model",
    "HELDOUT": "names",
    "SPLITS": "names",
    "seeds": "splits",
    "split_of": "splits",
}

__all__ = sorted(_WHERE)


def __getattr__(name: str) -> Any:
    module = _WHERE.get(name)
    if module is None:
        raise AttributeError(f"module 'models.objects' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_WHERE))


class _Package(types.ModuleType):
    """The submodule `instructions` shares its name with its function `instructions`: when the
    import system binds the submodule to the package, the function is bound instead (as the
    eager imports of this package did), whichever way the submodule was first imported."""

    def __setattr__(self, name: str, value: Any) -> None:
        if name == "instructions" and isinstance(value, types.ModuleType):
            value = value.instructions
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package
