"""
The answer of `cloth-bench rank` as text: the table and the sentences under it.

rank.answer computes the answer (ranking, intervals, floor, recommendation, Pareto front); this
module only renders it.
"""

from __future__ import annotations

import math
from typing import Any

from cloth_bench_ros.core.cloth_size import BENCHMARK_SIZE, is_benchmark, size_text
from cloth_bench_ros.core.deadline import DEADLINE_BUDGET
from cloth_bench_ros.core.table import Table
from cloth_bench_ros.metric_choice import metric as metric_of
from cloth_bench_ros.rank.answer import finite
import numpy as np


def _f(value: float | None, digits: int = 4) -> str:
    return '-' if value is None or not math.isfinite(value) else f'{value:.{digits}f}'


def rank_table(result: dict[str, Any]) -> Table:
    """Return one row per group and entrant: rank, held-out figure, interval, P(rank), preset."""
    m = metric_of(result['spec']['metric'])
    metric, unit = m.name.upper(), f' ({m.unit})' if m.unit else ''
    rate = f'{result["spec"]["rate_hz"]:g}'
    body = []
    for group, a in result['answer'].items():
        floor = a['floor']['mean']
        for r in a['ranking']:
            e = a['entrants'][r['name']]
            t = e['timing'].get(rate, {})
            body.append([
                group, str(r['rank']), r['name'], _f(r['mean']), _diverged(r),
                f'[{_f(r["low"])}, {_f(r["high"])}]', f'{r["p_rank"]:.2f}', str(r['n']),
                _f(e['preset']['mean']), _f(floor), _f(t.get('step_p99_ms'), 2),
            ])
    headers = ['cloth_task', 'rank', 'engine', f'{metric} held-out{unit}', 'diverged', '95 % CI',
               'P(rank)', 'runs', f'{metric} preset{unit}', 'floor CD (m)',
               f'step p99 at {rate} Hz (ms)']
    return Table('rank', headers, body, 'lrlrrrrrrrr')


def _diverged(ranked: dict) -> str:
    """Return an engine's diverged runs of its held-out runs, e.g. 0/15 (a rank.json before)."""
    if 'diverged' not in ranked:
        return '-'
    return f'{ranked["diverged"]}/{ranked["runs"]}'


def bootstrap_line(group: str, answer: dict) -> str | None:
    """Return what a group's intervals rest on: trials, seeds, replicates, the paired draw."""
    boot = answer.get('bootstrap')
    if not boot:
        return None
    trials = boot['trials']
    return (
        f'{group}: {boot["confidence"] * 100:g} % intervals from {boot["replicates"]} paired'
        f' bootstrap replicates (seed {boot["seed"]}) over {trials} held-out'
        f' trial{"s" if trials != 1 else ""} x {boot["seeds_per_trial"]} seed'
        f'{"s" if boot["seeds_per_trial"] != 1 else ""} each ({boot["resampled"]});'
        ' ranked by divergence rate, then by the metric'
    )


def rank_lines(result: dict[str, Any]) -> list[str]:
    """Return the sentences under the table: significance, floor, recommendation, cross-task."""
    lines = []
    m = metric_of(result['spec']['metric'])
    unit = f' {m.unit}' if m.unit else ''
    for group, a in result['answer'].items():
        info = result['groups'].get(group, {})
        size, mass = info.get('cloth_size') or BENCHMARK_SIZE, info.get('cloth_mass')
        if not is_benchmark(size) or mass is not None:  # a cloth other than the benchmark's
            lines.append(
                f'{group}: cloth {size_text(size)}, mass '
                + (f'{mass:g} kg (--cloth-mass, not fitted)' if mass is not None
                   else "the preset's per area times the area")
            )
        said = bootstrap_line(group, a)
        if said:
            lines.append(said)
        lines.append(f'{group}: {a["significance"]}')
        ref = a.get('within_reference_error')
        if ref:
            lines.append(
                f'{group}: on the bundled {ref["reference"]} reference, whose own numerical error'
                f' is about {ref["error_m"] * 1e3:.0f} mm ({ref["source"]}): '
                + ('; '.join(
                    f'{p["pair"][0]} and {p["pair"][1]} differ by'
                    f' {p["difference_m"] * 1e3:.1f} mm, less than that: not told apart by this'
                    ' reference' for p in ref['pairs'])
                   or 'every difference between neighbours is larger than that')
            )
        floor = a['floor']
        if floor['mean'] is not None and m.name != 'cd':
            lines.append(
                f'{group}: floor (repeated real trials, CD) {floor["mean"]:.4f} m; the ranking is '
                f'on {m.name.upper()}, so no engine is compared with it'
            )
        elif floor['mean'] is not None:
            above = [
                r['name'] for r in a['ranking']
                if r['low'] is not None and r['low'] > floor['max']
            ]
            motions = info.get('motions', 1)
            lines.append(
                f'{group}: floor (repeated real trials, {floor["vertices"]} points) '
                f'{floor["mean"]:.4f} m (pairs {floor["min"]:.4f}-{floor["max"]:.4f}'
                + (f"; between {motions} motions: an upper bound of the trials' own spread"
                   if motions > 1 else '') + '); '
                + (f'further from a trial than the trials are from each other: {", ".join(above)}'
                   if above else "no engine is clearly further than the trials' own spread")
            )
        for rate, rec in a['recommendation'].items():
            rule = f'p99 < {DEADLINE_BUDGET * 1e3 / float(rate):.2f} ms'
            lines.append(
                f'{group} at {rate} Hz ({rule}): '
                + (f'{rec["entrant"]} (held-out {rec["mean"]:.4f}{unit}, step p99 '
                   f'{rec["step_p99_ms"]:.2f} ms)' if rec else 'no engine meets the deadline')
            )
        by: dict[tuple[str, str], list] = {}
        for c in a['cross_task']:
            by.setdefault((c['entrant'], c['fitted_on']), []).append(c['value'])
        for (entrant, fitted_on), values in sorted(by.items()):
            own = a['entrants'].get(entrant, {}).get('identified', {}).get('mean')
            v = finite(values)
            mean = float(np.mean(v)) if len(v) else None
            lines.append(
                f'{group}: {entrant} fitted on {fitted_on}: {_f(mean)}{unit} '
                f'(fitted on this task: {_f(own)}{unit})'
            )
        for entrant, c in sorted(a.get('cross_motion', {}).items()):
            own = a['entrants'].get(entrant, {}).get('identified', {}).get('mean')
            lines.append(
                f'{group}: {entrant} fitted on other motions, scored on {len(c["values"])} '
                f'held-out runs of a motion it was not fitted on: {_f(c["mean"])}{unit} '
                f'(every held-out run: {_f(own)}{unit})'
            )
    return lines
