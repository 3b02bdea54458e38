"""
The engine's own step time on this machine, measured before a real-time run.

`warmup` builds the engine of a HIL configuration as the simulator node does (preset, then the
configuration's parameters and mesh), starts it the same way and steps it through the first
seconds of the task's targets at the run's rate, timing each step. Its step p99 against the
deadline rule (core/deadline.py) says before the run whether the configuration can keep up.
`coarser_grids` lists the meshes the remedy line tries.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
import time

from cloth_bench_ros.core.cloth_mesh import mesh_area, run_cloth
from cloth_bench_ros.core.scene import ClothGrid
from cloth_bench_ros.core.trajectory import full_targets
from cloth_bench_ros.engines import make_engine
from cloth_bench_ros.engines.presets import load_preset, sized_params
from cloth_bench_ros.hil.config import HilConfig
import numpy as np

WARMUP_SECONDS = 2.0  # of the trajectory stepped (its start: the grasp, the lift, the swing)
WARMUP_WALL_S = 3.0  # at most this long on the wall clock, whatever the rate and the engine
WARMUP_MIN_STEPS = 20  # fewer steps than this (a very slow engine) and the p99 is the max


@dataclass(frozen=True)
class Warmup:
    """Step times of a warm-up: how many steps, their p50 / p99 / max (s), and the mesh."""

    steps: int
    p50_s: float
    p99_s: float
    max_s: float
    grid: tuple[int, int]  # the grid that ran (the engine's default when none was given)
    mesh: str = ''  # the --cloth-mesh file that ran instead of a grid (grid then (0, 0))

    def describe(self) -> str:
        """Return how the warm-up went, in a few words."""
        cloth = f'mesh {self.mesh}' if self.mesh else f'{self.grid[0]}x{self.grid[1]} mesh'
        return (
            f'{self.steps} steps of the {cloth}: step p50'
            f' {1e3 * self.p50_s:.3g} ms, p99 {1e3 * self.p99_s:.3g} ms'
        )


def warmup(
    config: HilConfig, seconds: float = WARMUP_SECONDS, wall_s: float = WARMUP_WALL_S
) -> Warmup:
    """Step the configuration's engine through the first `seconds` of its targets; time steps."""
    task = config.task()
    grid = run_cloth(config.grid, None, config.cloth_mesh or None, task, config.rate_hz)
    params = sized_params(config.engine, {
        **load_preset(config.engine, config.cloth, config.primitive),
        **dict(config.params),
    }, None, None, mesh_area(grid))
    engine = make_engine(config.engine, config.rate_hz, params, grid)
    targets = full_targets(task, config.rate_hz)
    span = seconds if not config.duration else min(seconds, config.duration)
    count = min(len(targets), max(WARMUP_MIN_STEPS, int(round(span * config.rate_hz)) + 1))
    times = np.empty(count - 1)
    clock = time.perf_counter
    try:
        engine.start(config.seed, targets.left[0], targets.right[0])
        deadline = clock() + wall_s
        n = 0
        for k in range(1, count):
            start = clock()
            engine.step(targets.left[k], targets.right[k])
            end = clock()
            times[n] = end - start
            n += 1
            if end > deadline and n >= WARMUP_MIN_STEPS:
                break
        made = grid if isinstance(grid, ClothGrid) else ClothGrid()  # the engine's grid
        done = (0, 0) if config.cloth_mesh else (made.nx, made.nz)
    finally:
        engine.close()
    taken = times[:n]
    if not n:
        return Warmup(0, math.nan, math.nan, math.nan, done, config.cloth_mesh)
    return Warmup(
        n,
        float(np.percentile(taken, 50)),
        float(np.percentile(taken, 99)),
        float(taken.max()),
        done,
        config.cloth_mesh,
    )


def coarser_grids(grid: tuple[int, int], least: int = 4) -> list[tuple[int, int]]:
    """Return meshes of the same aspect with fewer vertices, finest first (each side >= least)."""
    out: list[tuple[int, int]] = []
    for factor in (0.8, 0.65, 0.5, 0.4):
        nx, nz = (max(least, int(round(n * factor))) for n in grid)
        if (nx, nz) != tuple(grid) and (nx, nz) not in out and nx * nz < grid[0] * grid[1]:
            out.append((nx, nz))
    return out
