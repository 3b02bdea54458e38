"""
`cloth-bench hil`: the deadline said out loud, and `--find-rate`.

Before each real-time run a warm-up of the engine on this machine, its step p99 against the
deadline rule (core/deadline.py); after a run whose misses exceed the threshold, one line naming
what would meet the rate; `--find-rate`, the highest rate each engine and mesh holds.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
import json
from pathlib import Path

from cloth_bench_ros.cli.common import UserError
from cloth_bench_ros.core.deadline import deadline_check, deadline_rule, DeadlineCheck, holds_rate
from cloth_bench_ros.core.table import Table
from cloth_bench_ros.errors import ClothBenchError
from cloth_bench_ros.hil import study as hil
from cloth_bench_ros.hil.config import HilConfig
from cloth_bench_ros.hil.find_rate import find_rate, miss_fraction, missed
from cloth_bench_ros.hil.warmup import coarser_grids, warmup
from cloth_bench_ros.report.hil import text_table
from cloth_bench_ros.safe_io import atomic_write_text

FIND_RATE_FILE = 'find_rate.json'


def warmup_check(config: HilConfig, budget: float) -> tuple[DeadlineCheck, object]:
    """Time the engine's warm-up on this machine and print its step p99 against the rule."""
    timing = warmup(config)
    check = deadline_check(timing.p99_s, config.rate_hz, budget)
    print(f'  warm-up on this machine ({timing.describe()}): {check.verdict()}', flush=True)
    return check, timing


def remedy_line(
    config: HilConfig,
    result,
    check: DeadlineCheck,
    timing,
    args: argparse.Namespace,
    recommended_running: bool,
) -> str | None:
    """Return one line naming what would meet the rate, or None if the misses are under it."""
    share = miss_fraction(result)
    if holds_rate([share], args.miss_threshold):
        return None
    rate = config.rate_hz
    ways = []
    if not recommended_running:
        try:
            rec, _ = hil.recommended(
                config.engine,
                config.cloth,
                config.primitive,
                rate,
                Path(args.settings) if args.settings else hil.DEFAULT_SETTINGS,
                args.tolerance_rel,
                args.tolerance_abs,
                args.budget,
            )
        except ClothBenchError:  # no usable recommendation: the other remedies remain
            rec = None
        if rec is not None:
            params = {**dict(config.params), **rec.params}
            tried = warmup(hil.with_config(config, rec.config, rec.grid, params))
            if deadline_check(tried.p99_s, rate, args.budget).meets:
                ways.append(
                    f'`--config recommended` ({rec.config}, CD {rec.cd:.4f} m; warm-up step p99'
                    f' {1e3 * tried.p99_s:.3g} ms)'
                )
    if not check.meets and not timing.mesh:
        for grid in coarser_grids(timing.grid):
            coarse = warmup(replace(config, grid=grid))
            if deadline_check(coarse.p99_s, rate, args.budget).meets:
                ways.append(
                    f'a coarser mesh, `--grid {grid[0]}x{grid[1]}` (warm-up step p99'
                    f' {1e3 * coarse.p99_s:.3g} ms; its CD differs, compare in lockstep)'
                )
                break
    else:
        ways.append(
            'a quieter machine: the step p99 meets the rule, so the misses are the round trip'
            f' and the load (CPU busy {100 * result.load.get("cpu_busy", float("nan")):.0f} %)'
        )
    mesh = (f' --cloth-mesh {timing.mesh}' if timing.mesh
            else f' --grid {timing.grid[0]}x{timing.grid[1]}')
    ways.append(
        f'a lower rate: this configuration meets the rule up to {check.rate_met_hz:.3g} Hz'
        f' (`cloth-bench hil --find-rate --engine {config.engine}{mesh}` finds the highest rate'
        ' it holds)'
    )
    return (
        f'to meet {rate:g} Hz with {config.engine} ({missed(result)} of'
        f' {result.figures.targets} targets late or skipped, {100 * share:.2f} %, over'
        f' {100 * args.miss_threshold:g} %): ' + '; or '.join(ways)
    )


def find_rates(args: argparse.Namespace, bases: list[HilConfig], out: Path) -> int:
    """Search the highest rate each base configuration holds; print the table, write JSON."""
    if args.rate:
        raise UserError('--find-rate searches the rate: give --rate-min/--rate-max, not --rate')
    if args.rate_min >= args.rate_max:
        raise UserError(
            f'--rate-min {args.rate_min:g} Hz must be under --rate-max {args.rate_max:g} Hz'
        )
    length = f'the first {args.duration:g} s' if args.duration else 'the whole trajectory'
    print(
        f'find-rate: {args.rate_min:g}-{args.rate_max:g} Hz, bisection on a log scale to within'
        f' {100 * args.rate_tolerance:g} %, each rate judged on the median of {args.repeats}'
        f' runs of {length}; held: under {100 * args.miss_threshold:g} % of the deadlines missed'
        ' (a skipped target counts as missed)'
    )
    print(
        'rule rate: the highest rate at which the warm-up step p99 at the rate held meets the'
        f' deadline rule (budget {args.budget:g}); CD: lockstep at the rate held'
    )
    found = []
    for base in bases:
        print(f'{base.engine}, configuration {base.config} ...', flush=True)
        found.append(
            find_rate(
                base,
                out,
                args.rate_min,
                args.rate_max,
                args.rate_tolerance,
                args.repeats,
                args.miss_threshold,
                not args.no_lockstep,
                args.budget,
            )
        )
    rows = [f.as_dict() for f in found]
    table = Table('find_rate', FIND_RATE_HEADERS, [_table_row(r) for r in rows], 'llrrrrrr')
    print(text_table(table))
    path = out / FIND_RATE_FILE
    atomic_write_text(
        path,
        json.dumps(
            {
                'options': {
                    'rate_min_hz': args.rate_min,
                    'rate_max_hz': args.rate_max,
                    'rate_tolerance': args.rate_tolerance,
                    'repeats': args.repeats,
                    'miss_threshold': args.miss_threshold,
                    'duration_s': args.duration,
                    'deadline_budget': args.budget,
                },
                'rule': deadline_rule(args.budget),
                'results': rows,
            },
            indent=1,
        ),
    )
    print(f'written: {path}')
    return 0


FIND_RATE_HEADERS = [
    'engine',
    'mesh',
    'rate held Hz',
    'misses there',
    'lat p99.9 ms',
    'warm-up step p99 ms',
    'rule rate Hz',
    'CD lockstep m',
]


def _table_row(r: dict) -> list[str]:
    rate = r['rate_hz']
    _, high = r['bracket_hz']
    if rate is None:  # not even the lowest rate
        shown = f'< {high:g}'
    elif high is None:  # the highest rate held
        shown = f'>= {rate:.4g}'
    else:
        shown = f'{rate:.4g}'
    missed = (
        f'{r["missed"]} of {r["targets"]} ({100 * r["miss_fraction"]:.2f} %)'
        if r['miss_fraction'] is not None
        else '-'
    )
    latency = '-' if r['latency_p999'] is None else f'{1e3 * r["latency_p999"]:.3g}'
    warm, rule, cd = r['warmup_step_p99'], r['rule_rate_hz'], r['cd_lockstep']
    return [
        r['engine'],
        r['grid'],
        shown,
        missed,
        latency,
        '-' if warm is None else f'{1e3 * warm:.3g}',
        '-' if rule is None else f'{rule:.4g}',
        '-' if cd is None else f'{cd:.4f}',
    ]
