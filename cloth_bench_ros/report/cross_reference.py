"""
Cross-reference: every engine's CD_d / CD_q against every synthetic reference, and the ranking.

An engine of the reference's own family should win on its own reference, and by how much is the
point (the cells are studies/cross_reference.py's). The ranking of the identified engines per
reference is rank/cross_reference.py's: this module renders the rankings it is given.
"""

from __future__ import annotations

import math
from typing import Sequence

from cloth_bench_ros.metric_choice import DEFAULT_METRIC, metric as metric_choice
from cloth_bench_ros.rank.cross_reference import (
    cross_reference_rows, entrant_name, row_entrant, TASKS,
)
from cloth_bench_ros.rank.ranking import order_agreement, Ranking
from cloth_bench_ros.report.blocks import Table
from cloth_bench_ros.report.ranking import ranking_table
from cloth_bench_ros.studies.cross_reference import DEFAULT_ENTRANTS, KINDS, MODE, REFERENCES
from cloth_bench_ros.sweep.aggregate import stat

REFERENCE_LABEL = {'mujoco': 'MuJoCo shell ref.', 'newton-vbd': 'Newton VBD ref.'}
NOTE = (
    'Every engine with its preset, and identified against that reference where it was'
    ' (lockstep, the rate given), scored against both synthetic'
    " references of the bundled bags: MuJoCo's flex shell (`bags/<cloth>_<task>`) and Newton's"
    ' VBD (`bags/<cloth>_<task>_newton_vbd`), both 31 x 43 vertices seen by the same virtual'
    " Kinect. Mean ± std over seeds, in metres; bold: the best in its column. A column's winner"
    ' is the engine closest to that reference model, not to real cloth; the gap between an'
    " engine's two columns is the bias a reference puts on it."
)


def cross_reference_table(
    rows: Sequence[dict], digits: int = 4, metric: str = DEFAULT_METRIC
) -> Table | None:
    """Return entrants x (reference, task) of the metric (CD_d / CD_q by default), or None."""
    chosen = metric_choice(metric)
    sel = cross_reference_rows(rows)
    if not sel:
        return None
    primitives = [p for p in TASKS if any(r['primitive'] == p for r in sel)]
    references = [ref for ref in REFERENCES if any(r['reference'] == ref for r in sel)]
    columns = [(ref, p) for ref in references for p in primitives]
    # The default entrants' order (preset, then identified), then any other.
    order = [(e, o.get('model', ''), k) for k in KINDS for e, o in DEFAULT_ENTRANTS]
    found = {row_entrant(r) for r in sel}
    entrants = sorted(found, key=lambda e: (order.index(e) if e in order else len(order), e))
    by: dict[tuple, list[dict]] = {}
    for r in sel:
        by.setdefault(row_entrant(r) + (r['reference'], r['primitive']), []).append(r)
    stats = {e + col: stat(by.get(e + col, []), chosen.key) for e in entrants for col in columns}
    best = {
        col: min(
            (s.mean for key, s in stats.items() if key[3:] == col and s.used),
            key=chosen.sort_key,
            default=math.nan,
        )
        for col in columns
    }
    body = []
    for entrant in entrants:
        engine, model, kind = entrant
        name = entrant_name(engine, {'model': model} if model else {})
        line = [name + (', identified' if kind == 'identified' else '')]
        for col in columns:
            s = stats[entrant + col]
            text = s.text(digits, show_n=False) if s.n else '-'
            line.append(
                f'**{text}**' if s.used and s.mean == best[col] and len(entrants) > 1 else text
            )
        body.append(line)
    headers = ['engine'] + [
        f'{REFERENCE_LABEL[ref]} {chosen.summary_key(p)}' for ref, p in columns
    ]
    return Table('cross_reference', headers, body, 'l' + 'r' * len(columns))


def ranking_statements(rankings: dict[tuple[str, str], Ranking]) -> list[str]:
    """
    Return the lines said under the ranking table.

    Per reference and task, which neighbours are told apart; per task, whether the identified
    engines' order holds across references.
    """
    lines = [
        f'{REFERENCE_LABEL[ref]} {task}: {ranking.significance()}'
        for (ref, task), ranking in rankings.items() if len(ranking.ranked) > 1
    ]
    for task in TASKS:
        per_ref = {REFERENCE_LABEL[ref]: r for (ref, t), r in rankings.items() if t == task}
        if per_ref:
            lines.append(f'{task}: {order_agreement(per_ref)}')
    return lines


def cross_reference_markdown(
    rows: Sequence[dict],
    rankings: dict[tuple[str, str], Ranking],
    metric: str = DEFAULT_METRIC,
) -> str:
    """Return the matrix, the given ranking of the identified engines, its lines, as Markdown."""
    table = cross_reference_table(rows, metric=metric)
    if table is None:
        return '(no rows)'
    parts = [table.markdown()]
    if rankings:
        parts.append(ranking_table('ranking', rankings).markdown())
        parts.append('\n'.join(f'- {line}' for line in ranking_statements(rankings)))
    return '\n\n'.join(parts)


def cross_reference_section(
    rows: Sequence[dict], metric: str = DEFAULT_METRIC
) -> tuple[str, str, Table] | None:
    """Return (heading, note, table) of the cross-reference section, or None without such rows."""
    table = cross_reference_table(rows, metric=metric)
    if table is None:
        return None
    cloths = sorted({r['cloth'] for r in rows if r.get('mode') == MODE})
    seeds = sorted({int(r['seed']) for r in rows if r.get('mode') == MODE})
    rates = sorted({float(r['rate_hz']) for r in rows if r.get('mode') == MODE})
    heading = (
        f'Cross-reference: each engine against each synthetic reference ({", ".join(cloths)})'
    )
    note = (
        NOTE.replace('the rate given', '/'.join(f'{r:g}' for r in rates) + ' Hz')
        + f' Seeds {seeds}.'
    )
    return heading, note, table
