"""
The configuration to run an engine with: the settings sweep's choice at one rate.

For hardware in the loop.

- `recommend`: the most accurate configuration and the cheapest within a tolerance of it.
- `recommend_for_rate`: the cheapest configuration both accurate enough (`recommend`'s rule) and
  fast enough (the engine's step p99 under the period, times a budget fraction) at one rate.
- `load_recommendations`: the entries of a recommendation file (config/hil_recommended.yaml), what
  `cloth-bench hil --config recommended` falls back to without settings-sweep results.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math
from pathlib import Path
from typing import Sequence

from cloth_bench_ros.core.deadline import (
    cd_tolerance,
    DEADLINE_BUDGET,
    deadline_check,
    within_tolerance,
)
from cloth_bench_ros.errors import InputError
from cloth_bench_ros.safe_io import load_yaml_file
from cloth_bench_ros.sweep.aggregate import compute_per_sim_second, finite, group, Stat, stat
from cloth_bench_ros.validation import parse_grid
import numpy as np

RECOMMENDATION_KEYS = (
    'engine',
    'cloth',
    'primitive',
    'rate_hz',
    'config',
    'grid',
    'params',
    'cd',
    'step_p99_ms',
    'best_config',
    'best_cd',
    'tolerance_m',
    'meets_deadline',
)
MEASURED_KEYS = RECOMMENDATION_KEYS[RECOMMENDATION_KEYS.index('cd'):]  # optional in a file

# DEADLINE_BUDGET (core/deadline.py): the step's share of the period; the rest is the round trip
# (two DDS hops, the messages in Python), 0.4-0.5 ms on a 2-core machine, so at 1 kHz a
# configuration must step in half the period.


@dataclass
class ConfigResult:
    """One settings-sweep configuration at one engine, task and rate: error, cost, stability."""

    engine: str
    cloth: str
    primitive: str
    rate: float
    config: str
    cd: Stat
    hd: Stat
    step_ms: float
    cost: float  # compute per simulated second
    stable: bool


def settings_results(rows: Sequence[dict]) -> list[ConfigResult]:
    """Return a ConfigResult per engine, cloth, task, rate and configuration of the rows."""
    sel = [r for r in rows if r.get('mode') == 'settings']
    out = []
    for (e, cloth, prim, rate, config), g in group(
        sel, 'engine', 'cloth', 'primitive', 'rate_hz', 'config'
    ).items():
        ok = [r for r in g if r.get('status') == 'ok']
        st = finite(r.get('step_time_mean') for r in ok)
        cost = finite(compute_per_sim_second(r) for r in ok)
        out.append(
            ConfigResult(
                e,
                cloth,
                prim,
                float(rate),
                config,
                stat(g, 'CD'),
                stat(g, 'HD'),
                float(st.mean() * 1e3) if len(st) else math.nan,
                float(cost.mean()) if len(cost) else math.nan,
                len(ok) == len(g) and len(g) > 0,
            )
        )
    return out


def recommend(
    results: Sequence[ConfigResult], tol_rel: float, tol_abs: float
) -> tuple[ConfigResult | None, ConfigResult | None, float]:
    """
    (most accurate, cheapest within tolerance, tolerance in m) among stable configurations.

    Within tolerance: mean CD <= best CD + max(tol_rel * best CD, tol_abs).
    """
    stable = [r for r in results if r.stable and math.isfinite(r.cd.mean)]
    if not stable:
        return None, None, math.nan
    best = min(stable, key=lambda r: (r.cd.mean, r.step_ms))
    tol = cd_tolerance(best.cd.mean, tol_rel, tol_abs)
    within = [r for r in stable if within_tolerance(r.cd.mean, best.cd.mean, tol)]
    cheapest = min(within, key=lambda r: (r.step_ms, r.cd.mean))
    return best, cheapest, tol


@dataclass(frozen=True)
class Recommendation:
    """The configuration to run an engine with at a rate, and why."""

    engine: str
    cloth: str
    primitive: str
    rate_hz: float
    config: str  # the settings sweep's label of the configuration
    grid: tuple[int, int] | None
    params: dict = field(default_factory=dict)
    cd: float = math.nan
    step_p99_ms: float = math.nan  # measured in the settings sweep (lockstep) at this rate
    best_config: str = ''
    best_cd: float = math.nan
    tolerance_m: float = math.nan
    meets_deadline: bool = (
        False  # step p99 under budget x period; False: the most accurate-enough cheapest
    )

    def as_dict(self) -> dict:
        d = {k: getattr(self, k) for k in RECOMMENDATION_KEYS}
        d['grid'] = list(self.grid) if self.grid else None
        return d


def step_ms_by_config(rows: Sequence[dict], key: str) -> dict[str, float]:
    """Return the median over seeds of a step-time statistic per configuration, in ms."""
    by: dict[str, list] = {}
    for r in rows:
        if r.get('status') == 'ok':
            by.setdefault(r['config'], []).append(r.get(key))
    return {
        c: float(np.median(v)) * 1e3 if len(v := finite(vals)) else math.nan
        for c, vals in by.items()
    }


def meets_deadline(step_p99_ms: float, rate_hz: float, budget: float = DEADLINE_BUDGET) -> bool:
    """Return whether a step p99 in ms meets the deadline rule (core/deadline.py) at a rate."""
    return deadline_check(step_p99_ms / 1e3, rate_hz, budget).meets


def _grid_params(rows: Sequence[dict], config: str) -> tuple[tuple[int, int] | None, dict]:
    row = next(r for r in rows if r['config'] == config)
    grid = row.get('grid')
    if isinstance(grid, str):
        grid = parse_grid(grid)
    return (tuple(grid) if grid else None), dict(row.get('params') or {})


def recommend_for_rate(
    rows: Sequence[dict],
    engine: str,
    cloth: str,
    primitive: str,
    rate_hz: float,
    tol_rel: float = 0.05,
    tol_abs: float = 0.002,
    budget: float = DEADLINE_BUDGET,
) -> Recommendation | None:
    """
    Return the cheapest configuration within tolerance of the most accurate.

    Only configurations that meet the deadline rule (step p99 < budget / rate) count.

    Cheapest: the lowest median step time (p50), which other work on a shared machine inflates far
    less than the mean. If no accurate-enough configuration meets the deadline, the cheapest
    accurate-enough one, with meets_deadline False. None without stable settings-sweep rows for
    this engine, task and rate.
    """
    sel = [
        r
        for r in rows
        if r.get('mode') == 'settings'
        and r['engine'] == engine
        and r['cloth'] == cloth
        and r['primitive'] == primitive
        and float(r['rate_hz']) == float(rate_hz)
    ]
    results = settings_results(sel)
    best, _, tol = recommend(results, tol_rel, tol_abs)
    if best is None:
        return None
    p50, p99 = step_ms_by_config(sel, 'step_time_p50'), step_ms_by_config(sel, 'step_time_p99')
    accurate = [r for r in results if r.stable and within_tolerance(r.cd.mean, best.cd.mean, tol)]
    fast = [r for r in accurate if meets_deadline(p99.get(r.config, math.nan), rate_hz, budget)]

    def cost(r) -> tuple[float, float]:
        value = p50.get(r.config, math.nan)
        return (value if math.isfinite(value) else math.inf, r.cd.mean)

    choice = min(fast or accurate, key=cost)
    grid, params = _grid_params(sel, choice.config)
    return Recommendation(
        engine,
        cloth,
        primitive,
        float(rate_hz),
        choice.config,
        grid,
        params,
        choice.cd.mean,
        p99.get(choice.config, math.nan),
        best.config,
        best.cd.mean,
        tol,
        bool(fast),
    )


def load_recommendations(path: Path) -> list[Recommendation]:
    """Return the entries of a recommendation file; ValueError naming the file if malformed."""
    data = load_yaml_file(path)
    entries = data.get('recommendations') if isinstance(data, dict) else None
    if not isinstance(entries, list):
        raise InputError(f"recommendation file {path}: no 'recommendations' list")
    out = []
    for i, e in enumerate(entries):
        if not isinstance(e, dict) or not {
            'engine',
            'cloth',
            'primitive',
            'rate_hz',
            'config',
        } <= set(e):
            raise InputError(
                f'recommendation file {path}: entry {i} lacks engine, cloth, primitive, rate_hz or'
                ' config'
            )
        grid = e.get('grid')
        if grid is not None and not (
            isinstance(grid, list) and len(grid) == 2 and all(isinstance(g, int) for g in grid)
        ):
            raise InputError(f'recommendation file {path}: entry {i} grid is not [nx, nz]')
        params = e.get('params') or {}
        if not isinstance(params, dict):
            raise InputError(f'recommendation file {path}: entry {i} params is not a mapping')
        out.append(
            Recommendation(
                str(e['engine']),
                str(e['cloth']),
                str(e['primitive']),
                float(e['rate_hz']),
                str(e['config']),
                tuple(grid) if grid else None,
                params,
                **{k: e[k] for k in MEASURED_KEYS if k in e},
            )
        )
    return out
