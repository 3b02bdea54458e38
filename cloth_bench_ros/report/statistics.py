"""Statistics and selections over results rows: mean +- std per group, Pareto fronts, labels."""

from __future__ import annotations

import math
from collections import Counter, defaultdict
from dataclasses import dataclass
from typing import Iterable, Sequence

import numpy as np

ENGINE_LABEL = {"mujoco": "MuJoCo", "bullet": "Bullet", "flex": "Flex", "sofa": "SOFA", "newton": "Newton"}
ENGINE_COLOR = {"mujoco": "tab:blue", "bullet": "tab:orange", "flex": "tab:green", "sofa": "tab:red",
                "newton": "tab:purple"}
METRICS = ("CD_d", "HD_d", "CD_q", "HD_q")
PAPER_ENGINES = ("mujoco", "bullet", "flex", "sofa")
FPS = 30.0


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
                return f"diverged ({self.diverged}/{self.n})"
            return "error" if self.errors else "-"
        out = f"{self.mean:.{digits}f} ± {self.std:.{digits}f}"
        notes = []
        if show_n:
            notes.append(f"n={self.used}")
        if self.diverged:
            notes.append(f"{self.diverged} diverged")
        if self.errors:
            notes.append(f"{self.errors} errors")
        return out + (f" ({', '.join(notes)})" if notes else "")


def stat(rows: Sequence[dict], key: str) -> Stat:
    """Mean and (population) std of `key` over the rows that neither diverged nor failed."""
    usable = [r for r in rows if r.get("status") == "ok"]
    values = finite(r.get(key) for r in usable)
    return Stat(len(rows), len(values), sum(r.get("status") == "diverged" for r in rows),
                sum(r.get("status") == "error" for r in rows),
                float(values.mean()) if len(values) else math.nan,
                float(values.std()) if len(values) else math.nan)


def group(rows: Iterable[dict], *keys: str) -> dict[tuple, list[dict]]:
    out: dict[tuple, list[dict]] = defaultdict(list)
    for r in rows:
        out[tuple(r.get(k) for k in keys)].append(r)
    return dict(out)


def metric_name(primitive: str, kind: str) -> str:
    return f"{kind}_{'d' if primitive == 'dynamic' else 'q'}"


def pareto_front(points: Sequence[tuple[float, float]]) -> list[int]:
    """Indices of the points not dominated in (x, y), both minimised, sorted by x."""
    order = sorted((i for i, (x, y) in enumerate(points) if math.isfinite(x) and math.isfinite(y)),
                   key=lambda i: (points[i][0], points[i][1]))
    front, best = [], math.inf
    for i in order:
        if points[i][1] < best:
            front.append(i)
            best = points[i][1]
    return front


def compute_per_sim_second(row: dict) -> float:
    """Engine compute time per simulated second (s/s): mean step time x rate; < 1 is faster than real time."""
    st = row.get("step_time_mean")
    if st is None or not math.isfinite(st):
        return math.nan
    return float(st) * float(row["rate_hz"])


def engine_label(name: str) -> str:
    return ENGINE_LABEL.get(name, name)


def fmt_fixed(value, digits: int = 3, scale: float = 1.0) -> str:
    """`value * scale` with `digits` decimals; "-" for a missing or non-finite value."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    return f"{value * scale:.{digits}f}"


def fmt_sig(value, digits: int = 3) -> str:
    """`value` with `digits` significant digits; "-" for a missing or non-finite value."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    return f"{value:.{digits}g}"


def paper_rows(rows: Sequence[dict], config: str = "preset", pacing: str = "lockstep") -> list[dict]:
    return [r for r in rows if r.get("mode", "paper") == "paper" and r.get("config", "preset") == config
            and r.get("pacing", "lockstep") == pacing]


def _ordered(values: Iterable, order: Sequence = ()) -> list:
    values = set(v for v in values if v is not None)
    first = [v for v in order if v in values]
    return first + sorted(values - set(first), key=str)


def engines_of(rows: Iterable[dict]) -> list[str]:
    return _ordered((r["engine"] for r in rows), PAPER_ENGINES)


def cloths_of(rows: Iterable[dict]) -> list[str]:
    return _ordered((r["cloth"] for r in rows), ("towel", "chequered", "linen"))


def rates_of(rows: Iterable[dict]) -> list[float]:
    return sorted({float(r["rate_hz"]) for r in rows})


def table_rate(rows: Sequence[dict], wanted: float) -> float | None:
    """`wanted` if rows hold it, else the rate with the most rows."""
    rates = Counter(float(r["rate_hz"]) for r in rows)
    if not rates:
        return None
    return float(wanted) if float(wanted) in rates else rates.most_common(1)[0][0]
