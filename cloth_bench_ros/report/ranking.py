"""
The table of rankings per reference and task (rank.ranking computes them).

Each engine's row: its rank, mean, the 95 % interval of the paired bootstrap, P(rank), its
finished runs and how many of its runs diverged.
"""

from __future__ import annotations

import math
from typing import Mapping

from cloth_bench_ros.core.table import Table
from cloth_bench_ros.rank.ranking import Ranking


def _f(value: float | None, digits: int) -> str:
    return '-' if value is None or not math.isfinite(value) else f'{value:.{digits}f}'


def ranking_table(
    name: str, rankings: Mapping[tuple[str, str], Ranking], digits: int = 4
) -> Table:
    """Return (reference, task) x rank rows: engine, mean, 95 % interval, P(rank), runs."""
    body = []
    for (reference, task), ranking in rankings.items():
        for r in ranking.ranked:
            body.append(
                [
                    reference,
                    task,
                    str(r.rank),
                    r.name,
                    _f(r.mean, digits),
                    f'{r.diverged}/{r.runs}',
                    f'[{_f(r.low, digits)}, {_f(r.high, digits)}]',
                    f'{r.p_rank:.2f}',
                    str(r.n),
                ]
            )
    headers = ['reference', 'task', 'rank', 'engine', 'CD (m)', 'diverged', '95 % CI', 'P(rank)',
               'seeds']
    return Table(name, headers, body, 'llrlrrrrr')
