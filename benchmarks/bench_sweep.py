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
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
import tempfile
import time

from cloth_bench_ros.studies import sweep as sw
from cloth_bench_ros.studies.results import load_rows


def overhead(results_dir: Path) -> None:
    """Print a finished sweep's cell time against its engines' stepping."""
    rows = [r for r in load_rows(results_dir) if r.get('status') == 'ok']
    groups: dict[str, list[dict]] = {'all': rows}
    for row in rows:
        groups.setdefault(f'{row["rate_hz"]:g} Hz', []).append(row)
        groups.setdefault(row['engine'], []).append(row)
    for name, members in groups.items():
        wall = sum(r['cell_wall_s'] for r in members)
        stepping = sum(r['step_count'] * r['step_time_mean'] for r in members)
        print(
            f'{name:>8}: {len(members):4d} cells, {wall / 60:7.1f} core-minutes in cells, '
            f'{stepping / 60:7.1f} of engine stepping, ratio {wall / stepping:.3f}'
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--workers', type=int, default=2)
    parser.add_argument('--seeds', type=int, default=2)
    parser.add_argument('--results', type=Path, help='a finished sweep directory: report only')
    args = parser.parse_args()
    if args.results:
        return overhead(args.results)
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
