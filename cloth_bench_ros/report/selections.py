"""
Selections over results rows for the report: Pareto fronts, colours, number formats.

Mean +- std per group is sweep/aggregate.py's (a study's choice of configuration uses it too).
"""

from __future__ import annotations

from collections import Counter
import math
from typing import Iterable, Sequence

from cloth_bench_ros.options import FLAGS, OPTIONS

ENGINE_COLOR = {
    'mujoco': 'tab:blue',
    'bullet': 'tab:orange',
    'flex': 'tab:green',
    'sofa': 'tab:red',
    'newton': 'tab:purple',
}
METRICS = ('CD_d', 'HD_d', 'CD_q', 'HD_q')
PAPER_ENGINES = ('mujoco', 'bullet', 'flex', 'sofa')
FPS = 30.0
DEFAULT_MODE = FLAGS['sweep_mode'].default  # a row without a mode: the sweep's default


def metric_name(primitive: str, kind: str) -> str:
    return f'{kind}_{"d" if primitive == "dynamic" else "q"}'


def fmt_fixed(value, digits: int = 3, scale: float = 1.0) -> str:
    """`value * scale` with `digits` decimals; "-" for a missing or non-finite value."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return '-'
    return f'{value * scale:.{digits}f}'


def fmt_sig(value, digits: int = 3) -> str:
    """`value` with `digits` significant digits; "-" for a missing or non-finite value."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return '-'
    return f'{value:.{digits}g}'


def paper_rows(
    rows: Sequence[dict], config: str = 'preset', pacing: str = OPTIONS['pacing'].default
) -> list[dict]:
    return [
        r
        for r in rows
        if r.get('mode', DEFAULT_MODE) == 'paper'
        and r.get('config', 'preset') == config
        and r.get('pacing', OPTIONS['pacing'].default) == pacing
    ]


def _ordered(values: Iterable, order: Sequence = ()) -> list:
    values = {v for v in values if v is not None}
    first = [v for v in order if v in values]
    return first + sorted(values - set(first), key=str)


def engines_of(rows: Iterable[dict]) -> list[str]:
    return _ordered((r['engine'] for r in rows), PAPER_ENGINES)


def cloths_of(rows: Iterable[dict]) -> list[str]:
    return _ordered((r['cloth'] for r in rows), ('towel', 'chequered', 'linen'))


def rates_of(rows: Iterable[dict]) -> list[float]:
    return sorted({float(r['rate_hz']) for r in rows})


def table_rate(rows: Sequence[dict], wanted: float) -> float | None:
    """`wanted` if rows hold it, else the rate with the most rows."""
    rates = Counter(float(r['rate_hz']) for r in rows)
    if not rates:
        return None
    return float(wanted) if float(wanted) in rates else rates.most_common(1)[0][0]
