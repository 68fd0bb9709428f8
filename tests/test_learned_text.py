"""The instruction encoder: loads the bundled weights with the network blocked, reads paraphrases."""

from __future__ import annotations

import socket

import numpy as np
import pytest

from learned import text
from models.errors import InstructionError


def _no_network(*args, **kwargs):
    raise OSError("network access attempted by the text encoder")


def test_encoder_loads_offline(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(socket.socket, "connect", _no_network)
    monkeypatch.setattr(socket.socket, "connect_ex", _no_network)
    monkeypatch.setattr(socket, "create_connection", _no_network)
    monkeypatch.setattr(socket, "getaddrinfo", _no_network)
    monkeypatch.setattr(text, "_model", None)  # force a fresh load under the block
    monkeypatch.setattr(text, "_cache", {})
    vecs = text.encode(["Use a mug by handle", "Hold a bottle by body"])
    assert vecs.shape == (2, text.EMBED_DIM)
    assert vecs.dtype == np.float32
    np.testing.assert_allclose(np.linalg.norm(vecs, axis=1), 1.0, atol=1e-5)


def test_paraphrases_are_closer_than_unrelated() -> None:
    a, para, other = text.encode(
        ["Use a mug by handle", "grab the mug by its handle", "Hand over a knife by blade"]
    )
    assert float(a @ para) > float(a @ other) + 0.2


def test_cache_returns_same_vector() -> None:
    first = text.encode(["Lift up a bowl by body"])
    again = text.encode(["Lift  up a bowl by body ", "Lift up a bowl by body"])
    np.testing.assert_array_equal(again[0], first[0])
    np.testing.assert_array_equal(again[1], first[0])


@pytest.mark.parametrize("bad", ["", "   ", "\n\t"])
def test_blank_instruction_refused(bad: str) -> None:
    with pytest.raises(InstructionError):
        text.encode([bad])


def test_non_text_refused() -> None:
    with pytest.raises(InstructionError):
        text.encode([None])  # type: ignore[list-item]


def test_reading_back_counts_right_intents_and_misreadings():
    from eval.understanding import read_back
    from learned.paraphrase import eval_paraphrases

    canonical = read_back("canonical", lambda req: [f"{req.intent} a {req.noun} by {req.part}"])
    assert canonical.sentences == canonical.intent_right == canonical.instruction_right > 50
    hoist = read_back("hoist", lambda req: eval_paraphrases(req)[:1])
    assert hoist.intent_right == hoist.sentences and not hoist.confusions
