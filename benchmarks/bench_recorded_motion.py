"""
Cost per step of a recorded motion against the task's quintic (goal: within 2 %).

The paper's dynamic task sampled at 60 Hz becomes a recorded motion (the grippers' samples, as
`--gripper-frames` gives them), so that both runs move the cloth alike; each run times the
targets' sampling (full_targets) and every engine.step along them, the two kinds alternated
`--repeats` times in this process (the machine's load affects both alike). Prints the median
cost per step of each and their ratio.

    .venv/bin/python benchmarks/bench_recorded_motion.py [--engine mujoco] [--rate 100]
        [--grid 6x8] [--repeats 5] [--samples-hz 60]
"""

from __future__ import annotations

import argparse
from dataclasses import replace
import time

from cloth_bench_ros import validation
from cloth_bench_ros.core.cloth_size import cloth_grid
from cloth_bench_ros.core.task_data import load_task, RecordedMotion, Task
from cloth_bench_ros.core.trajectory import full_targets, sample_quintic
from cloth_bench_ros.engines import make_engine
from cloth_bench_ros.engines.presets import load_preset
import numpy as np


def recorded_copy(task: Task, samples_hz: float) -> Task:
    """Return the task's motion as a recorded one: its samples at `samples_hz`."""
    quintic = sample_quintic(task, samples_hz)
    motion = RecordedMotion('the quintic sampled', '', 0, tuple(np.eye(4).ravel()), None, 'none',
                            quintic.t, quintic.left, quintic.right)
    return replace(task, recorded=motion)


def cost_per_step(engine_name: str, task: Task, rate_hz: float, grid: tuple[int, int]) -> float:
    """Return the wall time (s) of one run along the task, per step, targets included."""
    engine = make_engine(engine_name, rate_hz, load_preset(engine_name, 'towel', 'dynamic'),
                         cloth_grid(grid, None))
    start = time.perf_counter()
    targets = full_targets(task, rate_hz)
    engine.start(0, targets.left[0], targets.right[0])
    for k in range(1, len(targets)):
        engine.step(targets.left[k], targets.right[k])
    elapsed = time.perf_counter() - start
    engine.close()
    return elapsed / (len(targets) - 1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--engine', default='mujoco')
    parser.add_argument('--rate', type=float, default=100.0)
    parser.add_argument('--grid', default='6x8')
    parser.add_argument('--repeats', type=int, default=5)
    parser.add_argument('--samples-hz', type=float, default=60.0)
    args = parser.parse_args()
    grid = validation.parse_grid(args.grid)
    quintic = load_task('dynamic')
    recorded = recorded_copy(quintic, args.samples_hz)
    costs: dict[str, list[float]] = {'quintic': [], 'recorded': []}
    for _ in range(args.repeats):
        for name, task in (('quintic', quintic), ('recorded', recorded)):
            costs[name].append(cost_per_step(args.engine, task, args.rate, grid))
    q, r = (float(np.median(costs[k])) for k in ('quintic', 'recorded'))
    print(f'{args.engine} at {args.rate:g} Hz, grid {args.grid}, {args.repeats} runs each:')
    print(f'  quintic  {q * 1e3:.4f} ms/step')
    print(f'  recorded {r * 1e3:.4f} ms/step ({args.samples_hz:g} Hz samples)')
    print(f'  recorded / quintic = {r / q:.4f} (goal: within 2 %)')


if __name__ == '__main__':
    main()
