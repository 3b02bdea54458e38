"""
A study cell's wall time against its engine's own stepping, on the direct path and the node graph.

Runs sweep cells as a worker runs them (`run_cell`: engine construction, bag loading and planning,
stepping, scoring and the row included) for MuJoCo on the bundled towel fling, at 100 Hz and
1 kHz, alternately on the direct study path (the default for lockstep cells) and on the node
graph (`run_pipeline`, the baseline, in the same process). For each cell it prints cell wall
over engine stepping (steps x mean step time, as the cell reports it). Goal: direct <= 1.05 at
both rates. The first cell of a process pays what a worker pays once (loading the compiled
scoring kernels, planning the bag): the worker's start-up does the first, and the table shows
the first cell apart.

    python benchmarks/bench_study_path.py [--engine mujoco] [--rates 100 1000] [--repeats 3]
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time

from cloth_bench_ros.core import metrics
from cloth_bench_ros.paths import bundled_bag
from cloth_bench_ros.studies.cells import Cell
from cloth_bench_ros.studies.run_pipeline import run_pipeline
from cloth_bench_ros.sweep import study as sweep
import numpy as np

GOAL = 1.05


def direct_ratio(cell: Cell, out: str) -> float:
    """Return the cell's wall time over its engine's stepping, run as a sweep worker runs it."""
    row = sweep.run_cell(cell, out)
    if row['status'] != 'ok':
        raise SystemExit(f'cell failed: {row["error"]}')
    return row['cell_wall_s'] / (row['step_count'] * row['step_time_mean'])


def graph_ratio(cell: Cell) -> float:
    """Return the same ratio for the cell's run on the node graph (the baseline)."""
    start = time.perf_counter()
    summary = run_pipeline(sweep.cell_config(cell, None))
    wall = time.perf_counter() - start
    steps = summary['engines'][cell.engine]['step_time']
    return wall / (steps['count'] * steps['mean'])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--engine', default='mujoco')
    parser.add_argument('--rates', type=float, nargs='+', default=[100.0, 1000.0])
    parser.add_argument('--repeats', type=int, default=3)
    args = parser.parse_args()
    metrics.keep_trees(20_000_000)  # as a study worker's set-up does
    metrics.RealCloud(np.eye(3)).chamfer_hausdorff(np.eye(3))
    bag = str(bundled_bag('towel', 'dynamic'))
    print(f'load average {os.getloadavg()[0]:.2f}, {os.cpu_count()} cores')
    print('| engine | rate Hz | path | first cell | cells after it (median) | goal |')
    print('| --- | --- | --- | --- | --- | --- |')
    failed = False
    with tempfile.TemporaryDirectory() as out:
        for rate in args.rates:
            cell = Cell(
                engine=args.engine,
                rate_hz=rate,
                cloth='towel',
                primitive='dynamic',
                bag=bag,
                seed=0,
            )
            ratios: dict[bool, list[float]] = {False: [], True: []}
            for _ in range(args.repeats + 1):
                ratios[False].append(direct_ratio(cell, out))
                ratios[True].append(graph_ratio(cell))
            for graph, values in ratios.items():
                median = statistics.median(values[1:])
                met = graph or median <= GOAL
                failed |= not met
                print(
                    f'| {args.engine} | {rate:g} | {"node graph" if graph else "direct"} '
                    f'| {values[0]:.3f} | {median:.3f} | '
                    f'{"(baseline)" if graph else ("met" if met else "NOT met")} |'
                )
    raise SystemExit(1 if failed else 0)


if __name__ == '__main__':
    main()
