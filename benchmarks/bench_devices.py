"""
Newton on every device Warp finds: speed, how far the scores are apart, determinism per device.

For each Newton cloth model (xpbd, vbd), each device (`cpu`, then every `cuda:N`; or those
given with --devices) and each of Newton's `deterministic` modes (--deterministic, default off
and run_to_run: Warp's ordered atomics), runs the towel preset through the bundled fling and the
bundled lower-and-drag at 100 Hz on the direct study path (what `cloth-bench run --device D`
computes, without the node graph) and prints per model, device and mode: steps per second of one
world (the engine's own step time, median), CD_d / CD_q, their difference from the CPU's (mode
off), the mean distance of the final vertices from the CPU's, and whether two runs gave
bit-identical vertices. The CPU runs in the first mode only: Warp runs a CPU kernel's threads
one after another, so its atomic sums have one order whatever the mode. So one run on a GPU
machine says whether the deterministic mode closes the CPU/CUDA gap, and at what cost in steps
per second.
Meshes with --grids (default the bundled 11 x 15 and 31 x 43, where CUDA pulls ahead).

Run it on a machine with an NVIDIA GPU (Warp finds it through the driver; nothing else to
install):

    .venv/bin/python benchmarks/bench_devices.py [--devices cpu cuda:0] [--models xpbd vbd]
        [--grids 11x15 31x43] [--primitives dynamic quasi_static]
        [--deterministic off run_to_run gpu_to_gpu]

Several worlds of one Newton model stepped together (vectorised worlds) are not part of the
engine, so only one world is measured here; benchmarks/bench_vectorised_worlds.py --device D
compares them with one world at a time.
"""

from __future__ import annotations

import argparse
from itertools import product
import math

from cloth_bench_ros import paths
from cloth_bench_ros.engines.newton_cloth import available_devices, DETERMINISTIC
from cloth_bench_ros.studies import direct
from cloth_bench_ros.studies.run_config import RunConfig
from cloth_bench_ros.validation import parse_grid
import numpy as np


def run(model: str, device: str, grid: tuple[int, int], primitive: str, mode: str) -> dict:
    """Return one run's score, median step time and final vertices."""
    finals: list[np.ndarray] = []
    build = direct._engine

    def keeping(config: RunConfig, name: str):
        engine = build(config, name)
        step = engine.step

        def step_and_keep(left, right):
            vertices = step(left, right)
            finals[:] = [vertices.copy()]
            return vertices

        engine.step = step_and_keep  # type: ignore[method-assign]
        return engine

    config = RunConfig(
        bag=paths.bundled_bag('towel', primitive),
        engines=['newton'],
        primitive=primitive,
        engine_params={'newton': {'model': model, 'device': device, 'deterministic': mode}},
        grid=grid,
    )
    direct._engine = keeping  # type: ignore[assignment]
    try:
        summary = direct.run_direct(config)
    finally:
        direct._engine = build  # type: ignore[assignment]
    scores = summary['engines']['newton']
    suffix = 'd' if primitive == 'dynamic' else 'q'
    return {
        'cd': scores[f'CD_{suffix}'],
        'step_s': scores['step_time']['p50'],
        'vertices': finals[0],
        'device': summary['run']['devices']['newton'],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--devices', nargs='+', default=list(available_devices()))
    parser.add_argument('--models', nargs='+', default=['xpbd', 'vbd'], choices=['xpbd', 'vbd'])
    parser.add_argument('--grids', nargs='+', default=['11x15', '31x43'])
    parser.add_argument(
        '--primitives', nargs='+', default=['dynamic', 'quasi_static'],
        choices=['dynamic', 'quasi_static'],
    )
    parser.add_argument('--deterministic', nargs='+', default=['off', 'run_to_run'],
                        choices=list(DETERMINISTIC))
    args = parser.parse_args()
    print(f'devices found: {", ".join(available_devices())}')
    print(
        f'{"model":<5} {"mesh":>6} {"task":<12} {"device":<7} {"mode":<10} {"steps/s":>8}'
        f' {"CD mm":>7}'
        f' {"vs cpu mm":>9} {"mean |dx| mm":>12} deterministic'
    )
    for model in args.models:
        for grid in [parse_grid(g) for g in args.grids]:
            for primitive in args.primitives:
                cpu: dict | None = None
                for device, mode in product(args.devices, args.deterministic):
                    if device == 'cpu' and mode != args.deterministic[0]:
                        continue  # Warp runs a CPU kernel's threads in turn: every mode is one
                    first = run(model, device, grid, primitive, mode)
                    again = run(model, device, grid, primitive, mode)
                    same = bool(np.array_equal(first['vertices'], again['vertices']))
                    if cpu is None:
                        cpu = first
                    apart = first['cd'] - cpu['cd']
                    moved = float(
                        np.linalg.norm(first['vertices'] - cpu['vertices'], axis=1).mean()
                    )
                    print(
                        f'{model:<5} {grid[0]}x{grid[1]:<3} {primitive:<12}'
                        f' {first["device"]:<7} {mode:<10} {1 / first["step_s"]:>8.0f}'
                        f' {1000 * first["cd"]:>7.1f}'
                        f' {1000 * apart if math.isfinite(apart) else math.nan:>9.2f}'
                        f' {1000 * moved:>12.2f} {"yes" if same else "NO"}',
                        flush=True,
                    )


if __name__ == '__main__':
    main()
