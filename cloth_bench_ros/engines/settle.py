"""
The settle phase before the quintic part, the full way or the fast way (`--settle`).

`full` (the paper's protocol) steps the engine through every target of the settle. `fast` keeps
the targets and their timing, and simulates the settle as `full` does up to the pre-grasp pose:
the first hold and the move decide how the slackened cloth buckles, which a seed's noise alone
decides otherwise. Only in the final hold, which lets the cloth come to rest, kinetic damping
applies: whenever the cloth's kinetic energy (the sum of its vertices' squared travel per step)
falls, the engine stops the cloth (`ClothEngine.stop_cloth`). Once every vertex is slower than
REST_SPEED, or HOLD_LIMIT_S of the hold are simulated (the cloth then stopped, where the engine
can), the rest of the hold is not simulated: its targets are answered with that state, and the
quintic part starts from it. benchmarks/bench_settle.py measures both (docs/benchmark.md, 1).
"""

from __future__ import annotations

from cloth_bench_ros.core.trajectory import GripperTargets
from cloth_bench_ros.engines.base import ClothEngine
from cloth_bench_ros.options import SETTLES
import numpy as np

FULL, FAST = SETTLES
REST_SPEED = 0.005  # m/s: a held cloth whose every vertex is slower than this is at rest
HOLD_LIMIT_S = 0.3  # s of the final hold simulated at most


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
        self.fast = settle == FAST
        self.quintic = targets.quintic_index
        self.hold = final_hold(targets)
        self.stepped = True  # whether the last `step` called the engine
        self._limit = max(1, round(HOLD_LIMIT_S * engine.rate_hz))
        self._previous: np.ndarray | None = None
        self._energy = 0.0
        self._resting: np.ndarray | None = None  # the held cloth's state once it is at rest

    def step(self, k: int, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        """Return the state at target k >= 1 (grippers at `left`, `right`), the engine stepped."""
        self.stepped = True
        if not self.fast or not self.hold <= k < self.quintic:
            vertices = self.engine.step(left, right)
            self._previous = vertices.copy() if self.fast and k == self.hold - 1 else None
            return vertices
        if self._resting is not None:
            self.stepped = False
            return self._resting
        vertices = self.engine.step(left, right)
        previous, self._previous = self._previous, vertices.copy()
        if previous is None:  # a run that started in the hold
            return vertices
        travel = np.linalg.norm(vertices - previous, axis=1)
        energy = float(np.dot(travel, travel))
        if energy < self._energy and self.engine.stop_cloth():
            energy = 0.0  # past the peak: stopped, the next peak is measured from rest
        self._energy = energy
        if travel.max() < REST_SPEED * self.engine.dt:
            self._resting = self._previous
        elif k - self.hold + 1 >= self._limit:
            self.engine.stop_cloth()
            self._resting = self._previous
        return vertices
