"""
The answer of `cloth-bench rank`: per cloth and task, the engines on held-out trials, ranked.

From the study's numbers (rank.study): each entrant's held-out runs over trials and seeds,
ranked by rank.ranking (the cross-reference study's code: divergence rate first, then
the metric; paired bootstrap over trials and seeds for the intervals, P(rank) and the paired
differences; one sentence on which neighbours in the ranking are told apart); the preset beside
the identified figure; the floor; step times and, per rate, the most accurate entrant that meets
the rate's deadline (sweep.recommend's one rule: step p99 under DEADLINE_BUDGET of the
period); the Pareto front of error against step time; the cross-task check.
"""

from __future__ import annotations

from typing import Any

from cloth_bench_ros.core.deadline import DEADLINE_BUDGET
from cloth_bench_ros.metric_choice import Metric, metric as metric_of
from cloth_bench_ros.rank.ranking import HeldOutRun, rank_runs, Ranked, ranking_record
import numpy as np


def deadline_ms(rate_hz: float) -> float:
    """Return the step time (ms) a configuration must stay under, at p99, to run at a rate."""
    return DEADLINE_BUDGET * 1e3 / rate_hz


def cell_value(cell: dict, m: Metric) -> float | None:
    """Return a cell's value of the ranking metric: its objective's, or from its metrics."""
    if m.name in cell.get('metrics', {}):
        return cell['metrics'][m.name]
    return cell.get('value') if m.name in ('cd', 'hd') else None


def finite(values: list[float | None]) -> np.ndarray:
    """Return the finite values as a float array (a diverged run has none)."""
    a = np.asarray([v for v in values if v is not None], dtype=float)
    return a[np.isfinite(a)]


def _held_out(cells: list[dict], group: str, entrant: str, config: str) -> list[dict]:
    return [
        c for c in cells
        if c.get('kind') == 'held_out' and c['group'] == group and c['entrant'] == entrant
        and c['config'] == config
    ]


def held_out_runs(cells: list[dict], m: Metric) -> list[HeldOutRun]:
    """Return the cells as the ranking reads them: trial, seed, value, diverged."""
    return [
        HeldOutRun(c['trial'], int(c['seed']), cell_value(c, m), c.get('status') == 'diverged')
        for c in cells
    ]


def within_reference_error(ranked: list[Ranked], error: dict | None,
                           m: Metric) -> dict[str, Any] | None:
    """
    Return, on a bundled reference, the neighbours whose difference is under its numerical error.

    The reference's error is a CD (bags/README.md, "How converged the references are"): it is
    compared with the ranking's differences only when the ranking is on CD.
    """
    if not error or m.name != 'cd':
        return None
    pairs = [
        {'pair': [a.name, b.name], 'difference_m': abs(b.mean - a.mean)}
        for a, b in zip(ranked, ranked[1:])
        if a.mean is not None and b.mean is not None and abs(b.mean - a.mean) < error['error_m']
    ]
    return {**error, 'pairs': pairs}


def _timing(cells: list[dict], group: str, entrant: str) -> dict[str, dict]:
    out = {}
    for c in cells:
        if c.get('kind') == 'timing' and c['group'] == group and c['entrant'] == entrant:
            p99 = c.get('step_p99_ms')
            out[f'{c["rate_hz"]:g}'] = {
                'step_p50_ms': c.get('step_p50_ms'),
                'step_p99_ms': p99,
                'deadline_ms': deadline_ms(c['rate_hz']),
                'meets_deadline': p99 is not None and p99 < deadline_ms(c['rate_hz']),
                'status': c.get('status'),
            }
    return out


def _pareto(entries: dict[str, dict], rate: str, m: Metric) -> list[str]:
    """Return the entrants no other beats in both held-out error and step time at `rate`."""
    points: dict[str, tuple[float, float]] = {}
    for n, e in entries.items():
        err, step = m.ranked(e['identified']['mean']), e['timing'].get(rate, {}).get('step_p50_ms')
        if err is not None and step is not None:
            points[n] = (err, step)
    return sorted(
        n for n, (cd, t) in points.items()
        if not any(c2 <= cd and t2 <= t and (c2, t2) != (cd, t) for c2, t2 in points.values())
    )


def rank_answer(raw: dict[str, Any]) -> dict[str, Any]:
    """Return the raw numbers with, per group, the ranking and everything said about it."""
    cells = raw['cells']
    m = metric_of(raw['spec']['metric'])
    answer: dict[str, Any] = {}
    for group, info in raw['groups'].items():
        entries: dict[str, dict] = {}
        for entrant in raw['spec']['entrants']:
            ident, preset = (
                [cell_value(c, m) for c in _held_out(cells, group, entrant, k)]
                for k in ('identified', 'preset')
            )
            fi, fp = finite(ident), finite(preset)
            entries[entrant] = {
                'identified': {'values': ident, 'mean': float(fi.mean()) if len(fi) else None,
                               'ok': len(fi), 'n': len(ident)},
                'preset': {'values': preset, 'mean': float(fp.mean()) if len(fp) else None,
                           'ok': len(fp), 'n': len(preset)},
                'timing': _timing(cells, group, entrant),
            }
        ranking = rank_runs(
            {n: held_out_runs(_held_out(cells, group, n, 'identified'), m) for n in entries},
            higher_is_better=m.higher_is_better, absolute=m.absolute,
        )
        ranked = ranking.ranked
        recommendation = {}
        for rate in raw['spec']['rates']:
            key = f'{rate:g}'
            timing = {n: e['timing'].get(key, {}) for n, e in entries.items()}
            fit = [r for r in ranked
                   if r.mean is not None and timing[r.name].get('meets_deadline')]
            recommendation[key] = (
                {'entrant': fit[0].name, 'mean': fit[0].mean,
                 'step_p99_ms': entries[fit[0].name]['timing'][key]['step_p99_ms']}
                if fit else None
            )
        cross = [
            {'entrant': c['entrant'], 'fitted_on': c['fitted_on'], 'trial': c['trial'],
             'value': cell_value(c, m)}
            for c in cells if c.get('kind') == 'cross_task' and c['group'] == group
        ]
        other_motion = {  # held out along a motion its fold was not fitted on
            n: [cell_value(c, m) for c in _held_out(cells, group, n, 'identified')
                if c.get('other_motion')]
            for n in entries
        }
        answer[group] = {
            **ranking_record(ranking),
            'within_reference_error': within_reference_error(
                ranked, info.get('reference_error'), m
            ),
            'entrants': entries,
            'floor': info['floor'],
            'recommendation': recommendation,
            'deadline_rule': f'step p99 < {DEADLINE_BUDGET:g} x the period',
            'pareto': {f'{r:g}': _pareto(entries, f'{r:g}', m) for r in raw['spec']['rates']},
            'cross_task': cross,
            'cross_motion': {n: {'values': v, 'mean': float(finite(v).mean())
                                 if len(finite(v)) else None}
                             for n, v in other_motion.items() if v},
        }
    return {**raw, 'answer': answer}
