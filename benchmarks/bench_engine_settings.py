"""
An engine's numerical settings against its own converged run: the cheapest that stay within 2 mm.

For an engine's towel preset on the bundled 11 x 15 mesh (Newton VBD by default), runs the whole
towel fling at 100 Hz (settle phase and quintic part, the task's targets, seed 0) with every
combination of solver iterations and longest internal step given, and a converged run (the
most iterations and the shortest step given, unless --converged says otherwise), and prints
per setting: the engine's mean step time, and the trajectory change against the converged run
(the surface distance between the two cloths, every 10th step: mean and largest). The cheapest
setting whose mean change is within --tolerance (2 mm) is marked, with its cost against the
preset's. `--compare mujoco` runs the same study for a second engine and prints the two
engines' step times at equal accuracy (each one's cheapest setting within the tolerance).

    .venv/bin/python benchmarks/bench_engine_settings.py [--engine newton] [--model vbd]
        [--iterations 2 5 10 20] [--timesteps 0.004 0.002 0.001] [--compare mujoco]
"""

from __future__ import annotations

import argparse
import itertools
import time

from cloth_bench_ros.core.scene import ClothGrid
from cloth_bench_ros.core.trajectory import full_targets
from cloth_bench_ros.engines import make_engine
from cloth_bench_ros.engines.presets import load_preset
from cloth_bench_ros.studies.reference_convergence import trajectory_change
import numpy as np

RATE_HZ = 100.0
SAMPLE_EVERY = 10


def trajectory(engine: str, params: dict) -> tuple[np.ndarray, float]:
    """Return the sampled vertices of one run of the fling and its mean step time."""
    targets = full_targets('dynamic', RATE_HZ)
    cloth = make_engine(engine, RATE_HZ, params)
    states, seconds = [], 0.0
    try:
        cloth.start(0, targets.left[0], targets.right[0])
        for k in range(1, len(targets)):
            start = time.perf_counter()
            vertices = cloth.step(targets.left[k], targets.right[k])
            seconds += time.perf_counter() - start
            if k % SAMPLE_EVERY == 0:
                states.append(vertices.copy())
        if cloth.diverged:
            return np.full((len(states), 1, 3), np.nan), seconds / (len(targets) - 1)
    finally:
        cloth.close()
    return np.stack(states), seconds / (len(targets) - 1)


def study(
    engine: str, base: dict, iterations: list[int], timesteps: list[float],
    converged: dict, tolerance: float,
) -> list[dict]:
    """Return one row per setting: iterations, timestep, step ms, change mean/max mm, within."""
    grid = (ClothGrid().nx, ClothGrid().nz)
    reference, _ = trajectory(engine, {**base, **converged})
    rows = []
    for n, h in itertools.product(iterations, timesteps):
        states, step_s = trajectory(engine, {**base, 'solver_iterations': n, 'timestep': h})
        if np.isnan(states).any():
            change = np.array([np.inf])
        else:
            change = trajectory_change(reference, grid, states, grid)
        row = {
            'iterations': n, 'timestep': h, 'step_ms': 1000 * step_s,
            'change_mean_mm': 1000 * float(change.mean()),
            'change_max_mm': 1000 * float(change.max()),
        }
        row['within'] = row['change_mean_mm'] <= 1000 * tolerance
        rows.append(row)
        print(
            f'{engine:<7} {n:>5} {1000 * h:>6.2f} {row["step_ms"]:>8.2f}'
            f' {row["change_mean_mm"]:>8.2f} {row["change_max_mm"]:>8.2f}'
            f' {"yes" if row["within"] else ""}', flush=True,
        )
    return rows


def cheapest(rows: list[dict]) -> dict | None:
    within = [r for r in rows if r['within']]
    return min(within, key=lambda r: r['step_ms']) if within else None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--engine', default='newton')
    parser.add_argument('--model', default='vbd', help="the engine's model (default vbd)")
    parser.add_argument('--iterations', nargs='+', type=int, default=[2, 5, 10, 20])
    parser.add_argument('--timesteps', nargs='+', type=float, default=[0.004, 0.002, 0.001])
    parser.add_argument('--converged', nargs=2, type=float, metavar=('ITERATIONS', 'TIMESTEP'))
    parser.add_argument('--tolerance', type=float, default=0.002, help='m (default 0.002)')
    parser.add_argument('--compare', help='a second engine, its preset model (e.g. mujoco)')
    args = parser.parse_args()
    iterations, timesteps = sorted(args.iterations), sorted(args.timesteps)
    converged = (
        {'solver_iterations': int(args.converged[0]), 'timestep': args.converged[1]}
        if args.converged
        else {'solver_iterations': iterations[-1], 'timestep': timesteps[0]}
    )
    print(f'{"engine":<7} {"iter":>5} {"h ms":>6} {"step ms":>8} {"mean mm":>8} {"max mm":>8}'
          f' within {1000 * args.tolerance:g} mm of {converged}')
    base = {**load_preset(args.engine, 'towel', 'dynamic'), 'model': args.model}
    best = {args.engine: cheapest(
        study(args.engine, base, iterations, timesteps, converged, args.tolerance)
    )}
    if args.compare:
        other = load_preset(args.compare, 'towel', 'dynamic')
        best[args.compare] = cheapest(
            study(args.compare, other, iterations, timesteps, converged, args.tolerance)
        )
    for engine, row in best.items():
        if row is None:
            print(f'{engine}: no setting within {1000 * args.tolerance:g} mm')
        else:
            print(
                f'{engine}: cheapest within {1000 * args.tolerance:g} mm: {row["iterations"]}'
                f' iterations, {1000 * row["timestep"]:g} ms internal step,'
                f' {row["step_ms"]:.2f} ms per step'
            )


if __name__ == '__main__':
    main()
