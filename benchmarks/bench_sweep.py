"""
Sweep throughput on the Dask executor against the same cells run one after another in this process.

Runs a slice of the default sweep (MuJoCo and Bullet, towel, both tasks, 100 Hz, `--seeds` seeds,
the bundled bags) twice: serially in-process (the baseline), then with `run_sweep` on a local
cluster of `--workers` processes. Prints both wall times, the ratio, and the full default sweep
(720 cells) extrapolated from the measured cells: measured / estimated cost of these cells times
the estimated cost of the 720. Goal of issue 13: the full sweep under 30 minutes on 2 idle cores.

    .venv/bin/python benchmarks/bench_sweep.py [--workers 2] [--seeds 2]

With `--results DIR` it runs nothing and reads a finished sweep's results.jsonl instead: the
cells' wall time (core-minutes: each cell runs on one core) against the engines' own stepping
(step count x mean step time, as each cell reports it), overall, per rate and per engine.

    .venv/bin/python benchmarks/bench_sweep.py --results results/sweep

With `--cost` it runs the cells of `cloth-bench sweep --engine mujoco --rate 1000 --rate 100
--seeds 2 --workers 1` one after another in this process, as that one worker would (its tree
cache; a replay plan cache of its own for each way), each twice in turn: scored on every metric
(`--all-metrics`, what every cell computed before) and on the paper's CD/HD only (a sweep's
default now); it prints the same ratio of both, overall and per rate. Goal: at most 1.10, 1.05
hoped for (issue 48).

    .venv/bin/python benchmarks/bench_sweep.py --cost [--cloth towel] [--seeds 2]
"""

from __future__ import annotations

import argparse
from dataclasses import replace
import os
from pathlib import Path
import sys
import tempfile
import time

from cloth_bench_ros.studies.results import load_rows
from cloth_bench_ros.sweep import study as sw


def overhead(rows: list[dict], label: str = '') -> dict[str, float]:
    """Print the cells' time against their engines' stepping, overall and per rate and engine."""
    rows = [r for r in rows if r.get('status') == 'ok']
    groups: dict[str, list[dict]] = {'all': rows}
    for row in sorted(rows, key=lambda r: -r['rate_hz']):
        groups.setdefault(f'{row["rate_hz"]:g} Hz', []).append(row)
    for row in rows:
        groups.setdefault(row['engine'], []).append(row)
    ratios = {}
    for name, members in groups.items():
        wall = sum(r['cell_wall_s'] for r in members)
        stepping = sum(r['step_count'] * r['step_time_mean'] for r in members)
        ratios[name] = wall / stepping
        print(
            f'{label}{name:>8}: {len(members):4d} cells, {wall / 60:7.2f} core-minutes in cells, '
            f'{stepping / 60:7.2f} of engine stepping, ratio {wall / stepping:.3f}'
        )
    return ratios


def cell_cost(cloths: list[str], seeds: int) -> None:
    """Print the cost ratio of the issue's sweep with every metric and with the paper's only."""
    from cloth_bench_ros.core import metrics
    from cloth_bench_ros.core.surface_metrics import compile_kernels
    from cloth_bench_ros.studies import direct
    from cloth_bench_ros.studies.dask_executor import WORKER_TREE_CACHE_POINTS

    plan = sw.SweepPlan(engines=['mujoco'], rates=[1000.0, 100.0], cloths=cloths, n_seeds=seeds)
    cells = sw.cells_to_run(plan.cells(), [])  # in the order the worker runs them
    compile_kernels()  # a worker's start-up (studies/dask_executor.py), not a cell's
    metrics.keep_trees(WORKER_TREE_CACHE_POINTS)
    rows: dict[bool, list[dict]] = {True: [], False: []}
    plans: dict[bool, dict] = {True: {}, False: {}}  # each its own worker's replay plans
    with tempfile.TemporaryDirectory() as tmp:
        for k, cell in enumerate(cells):
            for every in ((True, False) if k % 2 == 0 else (False, True)):  # turns: fair to both
                direct._PLANS = plans[every]
                row = sw.run_cell(replace(cell, all_metrics=every), tmp)
                assert row['status'] == 'ok', row.get('error')
                rows[every].append(row)
            print(f'{k + 1}/{len(cells)} {cell.ident()}', file=sys.stderr, flush=True)
    print(f'{len(cells)} cells of `cloth-bench sweep --engine mujoco --rate 1000 --rate 100 '
          f'--seeds {seeds}` ({", ".join(cloths) or "every cloth"}), run in turn in one process; '
          f'load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores')
    before = overhead(rows[True], 'every metric (before) ')
    after = overhead(rows[False], "paper's CD/HD (now)   ")
    for name in before:
        print(f'{name:>8}: cell cost / engine stepping {before[name]:.3f} -> {after[name]:.3f}'
              f' (goal <= 1.10, hoped 1.05)')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--workers', type=int, default=2)
    parser.add_argument('--seeds', type=int, default=2)
    parser.add_argument('--results', type=Path, help='a finished sweep directory: report only')
    parser.add_argument('--cost', action='store_true', help="the issue's sweep, cell cost ratio")
    parser.add_argument('--cloth', action='append', default=[], help='--cost: these cloths only')
    args = parser.parse_args()
    if args.results:
        overhead(load_rows(args.results))
        return
    if args.cost:
        return cell_cost(args.cloth, args.seeds)
    cells = sw.paper_cells(
        ['mujoco', 'bullet'],
        [100.0],
        ['towel'],
        ['dynamic', 'quasi_static'],
        range(args.seeds),
        keep_frames_seeds=[],
    )
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        for cell in cells:
            sw.run_cell(cell, tmp)
        serial = time.perf_counter() - start
        outcome = sw.run_sweep(cells, Path(tmp) / 'dask', args.workers, progress=False)
    assert outcome.errors == 0, [r.get('error') for r in outcome.rows]
    full = sw.SweepPlan(engines=['mujoco', 'bullet']).cells()
    scale = sum(sw.estimated_cost(c) for c in full) / sum(sw.estimated_cost(c) for c in cells)
    print(
        f'{len(cells)} cells: serial in-process {serial:.1f} s, Dask on {args.workers} workers'
        f' {outcome.wall_s:.1f} s (ratio {serial / outcome.wall_s:.2f}); load average'
        f' {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores'
    )
    print(
        f'full default sweep ({len(full)} cells), extrapolated: {serial * scale / 60:.0f}'
        f' core-minutes, {outcome.wall_s * scale / 60:.0f} min on {args.workers} workers (goal: <'
        ' 30 min on 2 idle cores)'
    )


if __name__ == '__main__':
    main()
