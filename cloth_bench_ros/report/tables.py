"""The report's tables: the paper's Table III layout, Fig. 5's numbers, timing, stability."""

from __future__ import annotations

from collections import Counter
import math
import re
from typing import Sequence

from cloth_bench_ros.engines import engine_label
from cloth_bench_ros.report.blocks import Table
from cloth_bench_ros.report.selections import (
    cloths_of,
    engines_of,
    fmt_fixed,
    fmt_sig,
    METRICS,
    PAPER_ENGINES,
    rates_of,
)
from cloth_bench_ros.sweep.aggregate import finite, group, stat
import numpy as np

# docs/benchmark.md section 6, Table III: (mean, std, bold in the paper) per cloth, metric and
# engine.
PAPER_TABLE3: dict[tuple[str, str], dict[str, tuple[float, float, bool]]] = {
    ('towel', 'CD_d'): {
        'mujoco': (0.079, 0.031, False),
        'bullet': (0.155, 0.093, False),
        'flex': (0.168, 0.129, False),
        'sofa': (0.078, 0.029, True),
    },
    ('towel', 'HD_d'): {
        'mujoco': (0.167, 0.037, True),
        'bullet': (0.206, 0.083, False),
        'flex': (0.277, 0.158, False),
        'sofa': (0.194, 0.074, False),
    },
    ('towel', 'CD_q'): {
        'mujoco': (0.079, 0.027, True),
        'bullet': (0.097, 0.045, False),
        'flex': (0.080, 0.021, False),
        'sofa': (0.089, 0.022, False),
    },
    ('towel', 'HD_q'): {
        'mujoco': (0.182, 0.040, False),
        'bullet': (0.243, 0.078, False),
        'flex': (0.169, 0.024, True),
        'sofa': (0.174, 0.032, False),
    },
    ('chequered', 'CD_d'): {
        'mujoco': (0.067, 0.026, True),
        'bullet': (0.119, 0.060, False),
        'flex': (0.164, 0.134, False),
        'sofa': (0.068, 0.024, False),
    },
    ('chequered', 'HD_d'): {
        'mujoco': (0.154, 0.035, True),
        'bullet': (0.242, 0.063, False),
        'flex': (0.280, 0.180, False),
        'sofa': (0.178, 0.051, False),
    },
    ('chequered', 'CD_q'): {
        'mujoco': (0.076, 0.025, False),
        'bullet': (0.094, 0.034, False),
        'flex': (0.072, 0.019, True),
        'sofa': (0.102, 0.034, False),
    },
    ('chequered', 'HD_q'): {
        'mujoco': (0.186, 0.055, False),
        'bullet': (0.243, 0.070, False),
        'flex': (0.171, 0.024, True),
        'sofa': (0.198, 0.020, False),
    },
    ('linen', 'CD_d'): {
        'mujoco': (0.071, 0.031, False),
        'bullet': (0.116, 0.054, False),
        'flex': (0.160, 0.131, False),
        'sofa': (0.061, 0.024, True),
    },
    ('linen', 'HD_d'): {
        'mujoco': (0.154, 0.033, False),
        'bullet': (0.235, 0.076, False),
        'flex': (0.281, 0.186, False),
        'sofa': (0.150, 0.064, True),
    },
    ('linen', 'CD_q'): {
        'mujoco': (0.083, 0.037, False),
        'bullet': (0.078, 0.023, False),
        'flex': (0.075, 0.023, False),
        'sofa': (0.073, 0.021, True),
    },
    ('linen', 'HD_q'): {
        'mujoco': (0.177, 0.068, False),
        'bullet': (0.182, 0.024, False),
        'flex': (0.148, 0.045, False),
        'sofa': (0.137, 0.038, True),
    },
}
PAPER_FIG5 = (
    'Paper, Fig. 5 (towel, 10 seeds, 10 / 100 / 1000 Hz; the paper gives no numbers): '
    "Bullet and MuJoCo become unstable at low frequency, Flex and SOFA stay consistent; MuJoCo's "
    'error drops sharply as the frequency rises; an unstable simulator also takes much longer per '
    'step; at 100 Hz every engine needs on the order of milliseconds per step (Intel i7-10875H), '
    'which the paper judges too slow for real-time dynamic manipulation with hardware in the loop.'
)


def table3(rows: Sequence[dict], rate: float) -> Table:
    """Return the paper's Table III layout: cloth x metric rows; ours, then the paper's."""
    sel = [r for r in rows if float(r['rate_hz']) == rate]
    engines = engines_of(sel)
    headers = (
        ['cloth', 'metric']
        + [f'{engine_label(e)} (ours)' for e in engines]
        + [f'{engine_label(e)} (paper)' for e in PAPER_ENGINES]
    )
    by = group(sel, 'cloth', 'primitive', 'engine')
    out = []
    for cloth in cloths_of(sel):
        for metric in METRICS:
            primitive = 'dynamic' if metric.endswith('_d') else 'quasi_static'
            kind = metric[:2]
            stats = {e: stat(by.get((cloth, primitive, e), []), kind) for e in engines}
            if all(s.n == 0 for s in stats.values()):
                continue
            best = min((s.mean for s in stats.values() if s.used), default=math.nan)
            ours = []
            for e in engines:
                s = stats[e]
                text = s.text(3) if s.n else '-'
                ours.append(
                    f'**{text}**' if s.used and s.mean == best and len(engines) > 1 else text
                )
            paper = []
            for e in PAPER_ENGINES:
                v = PAPER_TABLE3.get((cloth, metric), {}).get(e)
                paper.append(
                    '-'
                    if v is None
                    else (f'**{v[0]:.3f} ± {v[1]:.3f}**' if v[2] else f'{v[0]:.3f} ± {v[1]:.3f}')
                )
            out.append([cloth, metric] + ours + paper)
    return Table('table3', headers, out, 'll' + 'r' * (len(headers) - 2))


def fig5_table(rows: Sequence[dict], cloth: str, name: str = 'fig5') -> Table:
    """Return Fig. 5's numbers per engine and rate: step time, L_s, CD_d, CD_q, divergences."""
    sel = [r for r in rows if r['cloth'] == cloth]
    headers = [
        'engine',
        'rate Hz',
        'substeps',
        'step mean ms',
        'step p99 ms',
        'L_s (m)',
        'CD_d (m)',
        'CD_q (m)',
        'diverged',
    ]
    by = group(sel, 'engine', 'rate_hz')
    out = []
    for e in engines_of(sel):
        for rate in rates_of(sel):
            g = by.get((e, rate), [])
            if not g:
                continue
            ok = [r for r in g if r.get('status') == 'ok']
            st = finite(r.get('step_time_mean') for r in ok) * 1e3
            p99 = finite(r.get('step_time_p99') for r in ok) * 1e3
            subs = {int(r['substeps']) for r in g if r.get('substeps')}
            dyn = stat([r for r in g if r['primitive'] == 'dynamic'], 'CD')
            qs = stat([r for r in g if r['primitive'] == 'quasi_static'], 'CD')
            ls = stat(g, 'L_s')
            out.append(
                [
                    engine_label(e),
                    f'{rate:g}',
                    ','.join(str(s) for s in sorted(subs)) or '-',
                    fmt_fixed(st.mean() if len(st) else math.nan, 3),
                    fmt_fixed(p99.mean() if len(p99) else math.nan, 3),
                    fmt_sig(ls.mean),
                    dyn.text(4, False) if dyn.n else '-',
                    qs.text(4, False) if qs.n else '-',
                    f'{sum(r.get("status") == "diverged" for r in g)}/{len(g)}',
                ]
            )
    return Table(name, headers, out, 'lrrrrrrrr')


def timing_table(rows: Sequence[dict]) -> Table:
    """Per engine, rate and pacing: step time, latency, deadline misses, real-time factor."""
    headers = [
        'engine',
        'rate Hz',
        'pacing',
        'config',
        'runs',
        'step p50 ms',
        'step p99 ms',
        'step max ms',
        'latency p50 ms',
        'latency p99 ms',
        'latency max ms',
        'deadline misses',
        'real-time factor',
    ]
    by = group(rows, 'engine', 'rate_hz', 'pacing', 'config')
    out = []
    for key in sorted(by, key=lambda k: (engines_of(rows).index(k[0]), k[1], k[2], str(k[3]))):
        g = [r for r in by[key] if r.get('status') in ('ok', 'diverged')]
        if not g:
            continue
        ok = [r for r in g if r.get('status') == 'ok'] or g

        def med(k, scale=1e3):
            v = finite(r.get(k) for r in ok)
            return fmt_fixed(float(np.median(v)) if len(v) else math.nan, 3, scale)

        misses = [
            (r.get('deadline_misses'), r.get('latency_count'))
            for r in ok
            if r.get('latency_count')
        ]
        miss_txt = '-'
        if misses:
            m = sum(x or 0 for x, _ in misses)
            n = sum(c or 0 for _, c in misses)
            miss_txt = f'{m / len(misses):.0f} / {n / len(misses):.0f} ({100 * m / n:.1f} %)'
        rtf = finite(r.get('real_time_factor') for r in ok)
        out.append(
            [
                engine_label(key[0]),
                f'{key[1]:g}',
                key[2],
                key[3],
                str(len(g)),
                med('step_time_p50'),
                med('step_time_p99'),
                med('step_time_max'),
                med('latency_p50'),
                med('latency_p99'),
                med('latency_max'),
                miss_txt,
                fmt_fixed(float(np.median(rtf)) if len(rtf) else math.nan, 2, 1.0),
            ]
        )
    return Table('timing', headers, out, 'lrllrrrrrrrrr')


def stability_table(rows: Sequence[dict]) -> Table:
    headers = [
        'engine',
        'rate Hz',
        'config',
        'task',
        'cells',
        'diverged',
        'errors',
        'median diverged at step',
        'most common reason',
        'L_s (m)',
    ]
    by = group(rows, 'engine', 'rate_hz', 'config', 'primitive')
    out = []
    for key in sorted(by, key=lambda k: (engines_of(rows).index(k[0]), k[1], str(k[2]), k[3])):
        g = by[key]
        div = [r for r in g if r.get('status') == 'diverged']
        steps = [r['diverged_at_step'] for r in div if r.get('diverged_at_step') is not None]
        reasons = Counter(re.sub(r'[\d.]+', '#', r.get('diverged_reason') or '') for r in div)
        out.append(
            [
                engine_label(key[0]),
                f'{key[1]:g}',
                key[2],
                key[3],
                str(len(g)),
                str(len(div)),
                str(sum(r.get('status') == 'error' for r in g)),
                f'{int(np.median(steps))}' if steps else '-',
                reasons.most_common(1)[0][0] if reasons else '-',
                fmt_sig(stat(g, 'L_s').mean),
            ]
        )
    return Table('stability', headers, out, 'lrllrrrrlr')


def errors_table(rows: Sequence[dict]) -> Table:
    errs = [r for r in rows if r.get('status') == 'error']
    out = [
        [
            r['engine'],
            f'{r["rate_hz"]:g}',
            r['cloth'],
            r['primitive'],
            str(r['seed']),
            r.get('config', ''),
            (r.get('error') or '')[:200],
        ]
        for r in errs
    ]
    return Table('errors', ['engine', 'rate Hz', 'cloth', 'task', 'seed', 'config', 'error'], out)
