"""
Mesh refinement of every engine: a finer mesh should change only the resolution of the cloth.

For each engine (cloth model) and each mesh from the default 11 x 15 up to the finest given, runs
the engine's towel preset through the bundled towel fling as `cloth-bench run --grid` does (the
direct study path, lockstep at 100 Hz, the parameters that depend on the spacing scaled by
`params_for_grid`), and prints per mesh:

- hanging length: the cloth's vertical extent at the end of the settle phase (hanging from the
  grippers, before the fling);
- trajectory change: per sampled step (every 10th), the one-sided L1 Chamfer distance between the
  cloth surfaces of this mesh and the previous one (both ways, the larger), the mean and largest
  over the run;
- CD_d: the paper's score on the bundled towel fling (simulated vertices to the real points).

A mesh changes only the resolution when the changes shrink from level to level (within 2 mm at
the last) and CD_d moves by no more than that convergence allows. `--unscaled` runs the same
meshes with the parameters as set for 11 x 15 (what `--grid` did before the scaling rule), for
comparison.

    .venv/bin/python benchmarks/bench_mesh_refinement.py [--engines mujoco bullet newton-xpbd
        newton-vbd] [--grids 11x15 21x29 31x43 41x57] [--unscaled] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
import time
from typing import Any

from cloth_bench_ros import paths
from cloth_bench_ros.core.scene import ClothGrid
from cloth_bench_ros.engines import engine_class
from cloth_bench_ros.engines.base import ClothEngine, spacing_ratio
from cloth_bench_ros.studies import direct
from cloth_bench_ros.studies.reference_convergence import trajectory_change
from cloth_bench_ros.studies.run_config import RunConfig
from cloth_bench_ros.validation import parse_grid
import numpy as np

# Engine (cloth model) -> the engine and its overrides of the towel preset.
MODELS = {
    'mujoco': ('mujoco', {}),
    'bullet': ('bullet', {}),
    'newton-xpbd': ('newton', {'model': 'xpbd'}),
    'newton-vbd': ('newton', {'model': 'vbd'}),
}
SAMPLE_EVERY = 10  # steps between the sampled states of the trajectory change
SETTLE_STEPS = 300  # at 100 Hz: the settle phase's 3 s


def run(model: str, grid: tuple[int, int], scaled: bool) -> dict[str, Any]:
    """Run one engine and mesh on the bundled towel fling; its states, CD_d and wall time."""
    name, overrides = MODELS[model]
    states: list[np.ndarray] = []
    build = direct._engine

    def recording(config: RunConfig, engine_name: str) -> ClothEngine:
        engine = build(config, engine_name)
        if not scaled:  # the parameters as set for 11 x 15, on the finer mesh
            engine = type(engine)(engine.rate_hz, unscaled, engine.grid)
        step = engine.step

        def step_and_keep(left: np.ndarray, right: np.ndarray) -> np.ndarray:
            vertices = step(left, right)
            if engine.steps % SAMPLE_EVERY == 0:
                states.append(vertices.copy())
            return vertices

        engine.step = step_and_keep  # type: ignore[method-assign]
        return engine

    from cloth_bench_ros.engines.presets import load_preset

    unscaled = {**load_preset(name, 'towel', 'dynamic'), **overrides}
    config = RunConfig(
        bag=paths.bundled_bag('towel', 'dynamic'),
        engines=[name],
        engine_params={name: overrides},
        grid=grid,
    )
    direct._engine = recording  # type: ignore[assignment]
    try:
        start = time.perf_counter()
        summary = direct.run_direct(config)
        seconds = time.perf_counter() - start
    finally:
        direct._engine = build  # type: ignore[assignment]
    scores = summary['engines'][name]
    return {
        'states': np.stack(states),
        'cd_m': scores.get('CD_d'),
        'diverged': scores.get('diverged'),
        'seconds': seconds,
    }


def hanging_length(states: np.ndarray) -> float:
    """Return the cloth's vertical extent at the end of the settle phase."""
    return float(np.ptp(states[SETTLE_STEPS // SAMPLE_EVERY - 1][:, 2]))


def refine(model: str, grids: list[tuple[int, int]], scaled: bool) -> list[dict[str, Any]]:
    """One row per mesh: hanging length, change from the previous mesh, CD_d, seconds."""
    rows: list[dict[str, Any]] = []
    previous: tuple[tuple[int, int], np.ndarray] | None = None
    for grid in grids:
        result = run(model, grid, scaled)
        row: dict[str, Any] = {
            'engine': model,
            'grid': f'{grid[0]}x{grid[1]}',
            'spacing_ratio': spacing_ratio(ClothGrid(*grid), ClothGrid()),
            'hanging_length_m': hanging_length(result['states']),
            'cd_m': result['cd_m'],
            'diverged': result['diverged'],
            'seconds': result['seconds'],
        }
        if previous is not None:
            n = min(len(previous[1]), len(result['states']))
            change = trajectory_change(previous[1][:n], previous[0], result['states'][:n], grid)
            row['change_mean_m'] = float(change.mean())
            row['change_max_m'] = float(change.max())
            row['hang_change_m'] = abs(row['hanging_length_m'] - rows[-1]['hanging_length_m'])
        rows.append(row)
        previous = (grid, result['states'])
        print(format_row(row), flush=True)
    return rows


def format_row(row: dict[str, Any]) -> str:
    def mm(key: str) -> str:
        value = row.get(key)
        return f'{1000 * value:.1f}' if isinstance(value, (int, float)) else '-'

    return (
        f'{row["engine"]:<12} {row["grid"]:>6} {mm("hanging_length_m"):>8}'
        f' {mm("hang_change_m"):>7}'
        f' {mm("change_mean_m"):>8} {mm("change_max_m"):>7} {mm("cd_m"):>7}'
        f' {row["seconds"]:>6.0f} {"diverged" if row["diverged"] else ""}'
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--engines', nargs='+', default=list(MODELS), choices=list(MODELS))
    parser.add_argument('--grids', nargs='+', default=['11x15', '21x29', '31x43'])
    parser.add_argument('--unscaled', action='store_true', help='parameters as set for 11 x 15')
    parser.add_argument('--json', type=Path, help='write the rows here')
    args = parser.parse_args()
    grids = [parse_grid(text) for text in args.grids]
    for model in args.engines:
        engine_class(MODELS[model][0])  # unavailable engines fail before any run
    print(
        f'{"engine":<12} {"mesh":>6} {"hang mm":>8} {"d hang":>7} {"mean mm":>8} {"max mm":>7}'
        f' {"CD_d mm":>7} {"s":>6}'
    )
    rows = [row for model in args.engines for row in refine(model, grids, not args.unscaled)]
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1) + '\n', encoding='utf-8')


if __name__ == '__main__':
    main()
