"""World devices that only watch: ground truth read from the simulated world, never over a link.

Benchmarks and tests that judge a loop against the resonator's true motion attach one of these.
"""

from __future__ import annotations

import numpy as np

from .world import World
from .world_block import WorldBlock


class EndStateProbe:
    """The resonator's true state at the end of every block (its time and its q vector)."""

    def __init__(self) -> None:
        self.t_s: list[float] = []
        self.q: list[np.ndarray] = []

    def before_block(self, world: World, t_s: float, n: int, dt_s: float) -> None:
        """Holds no input over the block: a probe does not act on the world."""

    def after_block(self, world: World, block: WorldBlock) -> None:
        """Keeps the last sample's time and true state."""
        self.t_s.append(float(block.t_s[-1]))
        self.q.append(block.q_true[-1].copy())
