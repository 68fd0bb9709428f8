"""Weights on disk: safetensors tensors plus a JSON config beside them, never a pickle.

A learned model ships as `learned/weights/<name>.safetensors` with `<name>.json` (its config and
provenance), so a fresh `pip install .` has a working model and loading cannot run code. A
missing or damaged file is a WeightsError naming the file and the command that remakes it.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import torch

from models.errors import DrograspError

WEIGHTS_DIR = Path(__file__).resolve().parent / "weights"


class WeightsError(DrograspError, RuntimeError):
    """Model weights that are missing, damaged or do not fit the model's code."""


def weight_paths(name: str, folder: str | Path | None = None) -> tuple[Path, Path]:
    """(tensors, config) paths of the named model in `folder` (default: the package's)."""
    root = Path(folder) if folder is not None else WEIGHTS_DIR
    return root / f"{name}.safetensors", root / f"{name}.json"


def save_weights(
    name: str, state: dict[str, torch.Tensor], config: dict[str, Any], folder: str | Path
) -> tuple[Path, Path]:
    """Write tensors and config atomically (a reader never sees half a file)."""
    from safetensors.torch import save_file

    tensors_path, config_path = weight_paths(name, folder)
    tensors_path.parent.mkdir(parents=True, exist_ok=True)
    tensors = {k: v.detach().cpu().contiguous() for k, v in state.items()}
    tmp = tensors_path.with_suffix(".safetensors.tmp")
    save_file(tensors, str(tmp))
    os.replace(tmp, tensors_path)
    tmp = config_path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(config, indent=2, sort_keys=True) + "\n", encoding="utf-8")
    os.replace(tmp, config_path)
    return tensors_path, config_path


def load_weights(
    name: str, retrain: str, folder: str | Path | None = None
) -> tuple[dict[str, torch.Tensor], dict[str, Any]]:
    """(tensors, config) of the named model; `retrain` is the command that remakes them."""
    from safetensors import SafetensorError
    from safetensors.torch import load_file

    tensors_path, config_path = weight_paths(name, folder)
    for path in (tensors_path, config_path):
        if not path.is_file():
            raise WeightsError(
                f"{path}: the {name} model's weights are missing; make them with `{retrain}`"
            )
    try:
        config = json.loads(config_path.read_text(encoding="utf-8"))
        if not isinstance(config, dict):
            raise ValueError("not a JSON object")
    except (ValueError, OSError) as err:
        raise WeightsError(
            f"{config_path} is damaged ({type(err).__name__}: {err}); remake it with `{retrain}`"
        ) from None
    try:
        state = load_file(str(tensors_path), device="cpu")
    except (SafetensorError, OSError, ValueError, RuntimeError) as err:
        raise WeightsError(
            f"{tensors_path} is damaged ({type(err).__name__}: {err}); remake it with `{retrain}`"
        ) from None
    return state, config
