"""Small model configurations for tests: the real architectures at sizes that run in seconds."""

from __future__ import annotations

from learned.interaction import InteractionConfig

TINY_INTERACTION = InteractionConfig(
    points=512,
    object_levels=((64, 8, (16, 32)), (16, 8, (32, 32))),
    hand_levels=((32, 8, (16, 32)), (8, 8, (32, 32))),
    width=32,
    heads=2,
    layers=1,
    ff=64,
    diffusion_steps=50,
    sample_steps=5,
)
