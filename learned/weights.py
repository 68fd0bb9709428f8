"""Weights on disk: one safetensors file per model, its config in the file's header, never a
pickle.

Every learned model (interaction, direct diffusion, D(R,O)) and the interaction model's training
checkpoint is one `<name>.safetensors` whose header holds a JSON object under `drograsp` (the
model's config, how it was trained, a `format` tag), so tensors and config cannot part ways, a
fresh `pip install .` has working models, and loading cannot run code. A missing or damaged file
is a WeightsError naming the file and the command that remakes it.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import torch

from models.errors import DrograspError

WEIGHTS_DIR = Path(__file__).resolve().parent / "weights"
HEADER_KEY = "drograsp"  # the safetensors metadata entry holding the config (JSON)


class WeightsError(DrograspError, RuntimeError):
    """Model weights that are missing, damaged or do not fit the model's code."""


def weights_path(name: str, folder: str | Path | None = None) -> Path:
    """The named model's file in `folder` (default: the package's shipped weights)."""
    root = Path(folder) if folder is not None else WEIGHTS_DIR
    return root / f"{name}.safetensors"


def save_weights(path: str | Path, state: dict[str, torch.Tensor], config: dict[str, Any]) -> Path:
    """Write the tensors with `config` in the header, atomically (a reader never sees half a
    file)."""
    from safetensors.torch import save_file

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tensors = {k: v.detach().cpu().contiguous() for k, v in state.items()}
    tmp = path.with_name(path.name + ".tmp")
    save_file(tensors, str(tmp), metadata={HEADER_KEY: json.dumps(config, sort_keys=True)})
    os.replace(tmp, path)
    return path


def load_weights(
    path: str | Path, retrain: str, what: str = "model"
) -> tuple[dict[str, torch.Tensor], dict[str, Any]]:
    """(tensors, config) stored at `path`; `retrain` is the command that remakes them and
    `what` names the model in the error."""
    from safetensors import SafetensorError
    from safetensors.torch import load_file, safe_open

    path = Path(path)
    if not path.is_file():
        raise WeightsError(f"{path}: the {what}'s weights are missing; make them with `{retrain}`")
    try:
        with safe_open(str(path), framework="pt") as f:
            header = f.metadata() or {}
        if HEADER_KEY not in header:
            raise ValueError(f"no {HEADER_KEY!r} config in the header")
        config = json.loads(header[HEADER_KEY])
        if not isinstance(config, dict):
            raise ValueError("the header's config is not a JSON object")
        state = load_file(str(path), device="cpu")
    except (SafetensorError, OSError, ValueError, RuntimeError) as err:
        raise WeightsError(
            f"{path} is damaged ({type(err).__name__}: {str(err)[:200]}); remake it with "
            f"`{retrain}`"
        ) from None
    return state, config
