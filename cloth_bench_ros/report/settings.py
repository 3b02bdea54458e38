"""Settings sweep: speed and error per configuration, and the cheapest near the best."""

from __future__ import annotations

from collections import defaultdict
import math
from typing import Sequence

from cloth_bench_ros.core.deadline import within_tolerance
from cloth_bench_ros.engines import engine_label
from cloth_bench_ros.report.blocks import Table
from cloth_bench_ros.report.selections import (
    engines_of,
    fmt_fixed,
    fmt_sig,
    metric_name,
)
from cloth_bench_ros.sweep.aggregate import pareto_front
from cloth_bench_ros.sweep.recommend import recommend, settings_results


def settings_tables(
    rows: Sequence[dict], tol_rel: float, tol_abs: float
) -> tuple[list[Table], list[str], list[dict]]:
    """Per engine, cloth, task and rate: every configuration, and the recommendation sentences."""
    results = settings_results(rows)
    tables, notes, recs = [], [], []
    by = defaultdict(list)
    for r in results:
        by[(r.engine, r.cloth, r.primitive, r.rate)].append(r)
    for key in sorted(by, key=lambda k: (engines_of(rows).index(k[0]), k[1], k[2], k[3])):
        group_results = by[key]
        best, cheap, tol = recommend(group_results, tol_rel, tol_abs)  # both None or neither
        front = pareto_front(
            [(r.step_ms, r.cd.mean) if r.stable else (math.nan, math.nan) for r in group_results]
        )
        rows_out = []
        for i, r in sorted(
            enumerate(group_results),
            key=lambda x: x[1].step_ms if math.isfinite(x[1].step_ms) else math.inf,
        ):
            flags = []
            if best is not None and r is best:
                flags.append('most accurate')
            if cheap is not None and r is cheap:
                flags.append('**recommended**')
            if i in front:
                flags.append('Pareto')
            if not r.stable:
                flags.append('unstable')
            within = (
                best is not None and r.stable and within_tolerance(r.cd.mean, best.cd.mean, tol)
            )
            rows_out.append(
                [
                    r.config,
                    fmt_fixed(r.step_ms, 3),
                    fmt_sig(r.cost),
                    r.cd.text(4, False),
                    r.hd.text(4, False),
                    'yes' if within else 'no',
                    ', '.join(flags),
                ]
            )
        e, cloth, prim, rate = key
        name = f'settings_{e}_{cloth}_{prim}_{rate:g}hz'
        tables.append(
            Table(
                name,
                [
                    'configuration',
                    'step mean ms',
                    'compute s/s',
                    metric_name(prim, 'CD') + ' (m)',
                    metric_name(prim, 'HD') + ' (m)',
                    'within tolerance',
                    'notes',
                ],
                rows_out,
                'lrrrrll',
            )
        )
        if best is None or cheap is None:
            notes.append(
                f'{engine_label(e)}, {cloth} {prim} at {rate:g} Hz: no stable configuration.'
            )
            continue
        notes.append(
            f'{engine_label(e)}, {cloth} {prim} at {rate:g} Hz: the most accurate configuration is'
            f' `{best.config}` ({metric_name(prim, "CD")} = {best.cd.mean:.4f} m,'
            f' {best.step_ms:.3f} ms per step); the cheapest within tolerance (CD <= best +'
            f' max({tol_rel:.0%} of best, {tol_abs * 1e3:g} mm) = {best.cd.mean + tol:.4f} m) is'
            f' **`{cheap.config}`** (CD = {cheap.cd.mean:.4f} m, {cheap.step_ms:.3f} ms per step,'
            f' {best.step_ms / cheap.step_ms:.1f}x faster than the most accurate).'
        )
        recs.append(
            {
                'engine': e,
                'cloth': cloth,
                'primitive': prim,
                'rate_hz': rate,
                'best': best.config,
                'best_cd': best.cd.mean,
                'best_step_ms': best.step_ms,
                'recommended': cheap.config,
                'recommended_cd': cheap.cd.mean,
                'recommended_step_ms': cheap.step_ms,
                'tolerance_m': tol,
            }
        )
    # One configuration for every task and cloth of an engine: within tolerance everywhere,
    # cheapest in total.
    for e in engines_of([r for r in rows if r.get('mode') == 'settings']):
        keys = [k for k in by if k[0] == e]
        if len(keys) < 2:
            continue
        ok_everywhere: set[str] | None = None
        cost: defaultdict[str, float] = defaultdict(float)
        for k in keys:
            best, _, tol = recommend(by[k], tol_rel, tol_abs)
            near_best = {
                r.config
                for r in by[k]
                if best is not None and r.stable and within_tolerance(r.cd.mean, best.cd.mean, tol)
            }
            ok_everywhere = near_best if ok_everywhere is None else ok_everywhere & near_best
            for r in by[k]:
                cost[r.config] += r.step_ms if math.isfinite(r.step_ms) else math.inf
        if ok_everywhere:
            choice = min(ok_everywhere, key=lambda c: cost[c])
            notes.append(
                f'{engine_label(e)}, one configuration for all {len(keys)} task/cloth/rate groups:'
                f' **`{choice}`** is within tolerance in each, at {cost[choice]:.3f} ms summed'
                ' step time.'
            )
        else:
            notes.append(
                f'{engine_label(e)}: no single configuration is within tolerance in every group.'
            )
    return tables, notes, recs
