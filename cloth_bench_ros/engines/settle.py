"""
The settle phase before the quintic part, the full way or the fast way (`--settle`).

`full` (the paper's protocol) steps the engine through every target of the settle. `fast` keeps
the targets and their timing and simulates the settle as `full` does up to the pre-grasp pose (the
first hold and the move decide how the slackened cloth buckles), and the final hold for its first
HOLD_LIMIT_S only: the hold's other targets are answered with the state reached then, and the
quintic part starts from that state, the cloth moving as it was. benchmarks/bench_settle.py
measures both (docs/benchmark.md, "The fast settle").
"""

from __future__ import annotations

from cloth_bench_ros.core.trajectory import GripperTargets
from cloth_bench_ros.engines.base import ClothEngine
from cloth_bench_ros.options import SETTLES
import numpy as np

FULL, FAST = SETTLES
HOLD_LIMIT_S = 0.3  # s of the final hold simulated by the fast settle


def final_hold(targets: GripperTargets) -> int:
    """Return the index of the first target of the hold that ends where the quintic part starts."""
    q = targets.quintic_index
    first = q - 1
    while first > 1 and np.array_equal(targets.left[first - 1], targets.left[q - 1]) and \
            np.array_equal(targets.right[first - 1], targets.right[q - 1]):
        first -= 1
    return first


class Settler:
    """Steps one engine through a run's targets, its settle phase the `full` or the `fast` way."""

    def __init__(self, engine: ClothEngine, targets: GripperTargets, settle: str = FULL) -> None:
        if settle not in SETTLES:
            raise ValueError(f'settle {settle!r} is not one of {SETTLES}')
        self.engine = engine
        self.quintic = targets.quintic_index
        # The targets of the final hold answered without a step (none in the full settle).
        held = final_hold(targets) + max(1, round(HOLD_LIMIT_S * engine.rate_hz))
        self.skipped = range(held, self.quintic) if settle == FAST else range(0)
        self.stepped = True  # whether the last `step` called the engine
        self._state: np.ndarray | None = None  # the state the skipped targets are answered with

    def step(self, k: int, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        """Return the state at target k >= 1 (grippers at `left`, `right`)."""
        self.stepped = k not in self.skipped
        if not self.stepped and self._state is not None:
            return self._state
        vertices = self.engine.step(left, right)
        if k + 1 in self.skipped:
            self._state = vertices
        return vertices
