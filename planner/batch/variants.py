"""Varied wrist poses for one (object, instruction, hand): rotate the planner's proposals.

FunctionalPlanner ranks a fixed set of proposals (wrist pose + anchors) and plans with the first
`max_candidates` of them. Variant k gives it the next window instead: ranked proposals from
k x max_candidates on (wrapping around), so variants 0, 1, ... search disjoint windows while
there are proposals left, and give different wrist poses wherever a window holds a grasp.
"""

from __future__ import annotations

import sys
from dataclasses import replace

from models.hands import HandModel
from models.objects import ObjectModel
from models.objects.intents import Definition
from planner.functional import FunctionalPlanner, PlannerSettings, Proposal

ALL_PROPOSALS = sys.maxsize


class VariantPlanner(FunctionalPlanner):
    """A FunctionalPlanner whose proposals start at ranked proposal `variant x max_candidates`.

    `max_candidates` proposals are still tried; `proposal_index(rank)` maps a candidate's rank
    in this planner back to its position in the full ranking (what a dataset records)."""

    def __init__(
        self, hand: HandModel | str, settings: PlannerSettings | None = None, variant: int = 0
    ):
        super().__init__(hand, settings)
        self.variant = int(variant)
        self._ranker = FunctionalPlanner(
            self.hand,
            replace(
                self.settings,
                proposals=replace(self.settings.proposals, max_proposals=ALL_PROPOSALS),
            ),
        )
        self._count = 0

    def propose(
        self, obj: ObjectModel, part: str, intent: Definition | None = None
    ) -> list[Proposal]:
        ranked = self._ranker.propose(obj, part, intent)
        self._count = len(ranked)
        k = self.offset % max(len(ranked), 1)
        return (ranked[k:] + ranked[:k])[: self.settings.schedule.max_candidates]

    def proposal_index(self, rank: int) -> int:
        """Position in the full ranking of the candidate tried `rank`-th (after `propose`)."""
        return (rank + self.offset) % max(self._count, 1)

    @property
    def offset(self) -> int:
        return self.variant * self.settings.schedule.max_candidates
