"""Mean +- std of result rows per group (diverged or failed cells counted), the Pareto front."""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass
import math
from typing import Iterable, Sequence

import numpy as np


def finite(values: Iterable) -> np.ndarray:
    a = np.asarray([np.nan if v is None else v for v in values], dtype=float)
    return a[np.isfinite(a)]


@dataclass
class Stat:
    """mean +- std over the usable cells of a group, with how many there were and diverged."""

    n: int  # cells in the group
    used: int  # cells with a finite value
    diverged: int
    errors: int
    mean: float
    std: float

    def text(self, digits: int = 3, show_n: bool = True) -> str:
        if self.used == 0:
            if self.diverged:
                return f'diverged ({self.diverged}/{self.n})'
            return 'error' if self.errors else '-'
        out = f'{self.mean:.{digits}f} ± {self.std:.{digits}f}'
        notes = []
        if show_n:
            notes.append(f'n={self.used}')
        if self.diverged:
            notes.append(f'{self.diverged} diverged')
        if self.errors:
            notes.append(f'{self.errors} errors')
        return out + (f' ({", ".join(notes)})' if notes else '')


def stat(rows: Sequence[dict], key: str) -> Stat:
    """Mean and (population) std of `key` over the rows that neither diverged nor failed."""
    usable = [r for r in rows if r.get('status') == 'ok']
    values = finite(r.get(key) for r in usable)
    return Stat(
        len(rows),
        len(values),
        sum(r.get('status') == 'diverged' for r in rows),
        sum(r.get('status') == 'error' for r in rows),
        float(values.mean()) if len(values) else math.nan,
        float(values.std()) if len(values) else math.nan,
    )


def group(rows: Iterable[dict], *keys: str) -> dict[tuple, list[dict]]:
    out: dict[tuple, list[dict]] = defaultdict(list)
    for r in rows:
        out[tuple(r.get(k) for k in keys)].append(r)
    return dict(out)


def compute_per_sim_second(row: dict) -> float:
    """Return engine compute time per simulated second (mean step time x rate); < 1 is faster."""
    st = row.get('step_time_mean')
    if st is None or not math.isfinite(st):
        return math.nan
    return float(st) * float(row['rate_hz'])


def pareto_front(points: Sequence[tuple[float, float]]) -> list[int]:
    """Return indices of the points not dominated in (x, y), both minimised, sorted by x."""
    order = sorted(
        (i for i, (x, y) in enumerate(points) if math.isfinite(x) and math.isfinite(y)),
        key=lambda i: (points[i][0], points[i][1]),
    )
    front, best = [], math.inf
    for i in order:
        if points[i][1] < best:
            front.append(i)
            best = points[i][1]
    return front
