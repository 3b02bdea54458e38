"""
Ranking identified engines per reference and task, with bootstrap intervals over seeds.

Each engine's seeds are resampled with replacement (independently: two engines' seed k share
no randomness); a replicate ranks the engines by their resampled mean CD. The interval is the
2.5-97.5 % percentile of the resampled mean; "P(rank)" is the share of replicates in which the
engine holds the rank it has on the full data.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Mapping, Sequence

from cloth_bench_ros.core.table import Table
import numpy as np

REPLICATES = 4000
CONFIDENCE = 0.95


@dataclass(frozen=True)
class Ranked:
    """One engine's place: rank on the data, mean CD, its interval, and how often it holds."""

    name: str
    rank: int
    mean: float
    low: float
    high: float
    p_rank: float
    n: int


def bootstrap_ranking(
    samples: Mapping[str, Sequence[float | None]],
    replicates: int = REPLICATES,
    seed: int = 0,
    higher_is_better: bool = False,
    absolute: bool = False,
) -> list[Ranked]:
    """
    Return the engines ranked by mean (lowest first), each with its bootstrap interval.

    higher_is_better ranks the highest mean first (F-score, recall); absolute ranks on the values'
    magnitudes (a signed error such as the contact onset's), whose mean is then reported.
    """
    if absolute:
        samples = {n: [None if v is None else abs(v) for v in vs] for n, vs in samples.items()}
    sign = -1.0 if higher_is_better else 1.0
    names = [n for n, v in samples.items() if len(finite(v))]
    if not names:
        return []
    rng = np.random.default_rng(seed)
    means = np.empty((replicates, len(names)))
    for j, name in enumerate(names):
        values = finite(samples[name])
        picks = rng.integers(0, len(values), size=(replicates, len(values)))
        means[:, j] = values[picks].mean(axis=1)
    point = np.array([finite(samples[n]).mean() for n in names])
    order = np.argsort(sign * point, kind='stable')
    ranks_of = np.argsort(np.argsort(sign * means, axis=1, kind='stable'), axis=1)  # per replicate
    alpha = (1.0 - CONFIDENCE) / 2.0
    out = []
    for rank, j in enumerate(order, 1):
        low, high = np.quantile(means[:, j], [alpha, 1.0 - alpha])
        out.append(
            Ranked(
                names[j],
                rank,
                float(point[j]),
                float(low),
                float(high),
                float(np.mean(ranks_of[:, j] == rank - 1)),
                len(finite(samples[names[j]])),
            )
        )
    return out


def finite(values: Sequence[float | None]) -> np.ndarray:
    """Return the finite values as a float array (a diverged seed has no CD)."""
    a = np.asarray([v for v in values if v is not None], dtype=float)
    return a[np.isfinite(a)]


def order_agreement(rankings: Mapping[str, list[Ranked]]) -> str:
    """
    Return one sentence: whether the engines ranked under every key come in the same order.

    Only engines ranked under every key are compared.
    """
    keys = [k for k, r in rankings.items() if r]
    if len(keys) < 2:
        return 'only one reference ranked: nothing to compare'
    common = set.intersection(*({r.name for r in rankings[k]} for k in keys))
    orders = {k: [r.name for r in rankings[k] if r.name in common] for k in keys}
    first = orders[keys[0]]
    if all(orders[k] == first for k in keys[1:]):
        return f'the ranking holds across references: {" < ".join(first)}'
    return 'the ranking changes between references: ' + '; '.join(
        f'{k}: {" < ".join(orders[k])}' for k in keys
    )


def ranking_table(
    name: str, rankings: Mapping[tuple[str, str], list[Ranked]], digits: int = 4
) -> Table:
    """Return (reference, task) x rank rows: engine, mean CD, 95 % interval, P(rank), seeds."""
    body = []
    for (reference, task), ranked in rankings.items():
        for r in ranked:
            body.append(
                [
                    reference,
                    task,
                    str(r.rank),
                    r.name,
                    f'{r.mean:.{digits}f}',
                    f'[{r.low:.{digits}f}, {r.high:.{digits}f}]',
                    f'{r.p_rank:.2f}' if math.isfinite(r.p_rank) else '-',
                    str(r.n),
                ]
            )
    headers = ['reference', 'task', 'rank', 'engine', 'CD (m)', '95 % CI', 'P(rank)', 'seeds']
    return Table(name, headers, body, 'llrlrrrr')
