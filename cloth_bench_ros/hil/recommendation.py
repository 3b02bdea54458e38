"""
The recommendation file (config/hil_recommended.yaml) from a settings sweep's rows.

What `cloth-bench hil --config recommended` falls back to without settings-sweep results: the
recommended configuration per engine, task and rate, with its provenance.
"""

from __future__ import annotations

from datetime import datetime, timezone
from typing import Sequence

from cloth_bench_ros.sweep.aggregate import finite
from cloth_bench_ros.sweep.recommend import DEADLINE_BUDGET, recommend_for_rate, Recommendation
import numpy as np
import yaml


def recommendation_yaml(recs: Sequence[Recommendation], provenance: dict) -> str:
    """Return the recommendation file: provenance, then one entry per engine, task and rate."""
    return yaml.safe_dump(
        {'provenance': provenance, 'recommendations': [r.as_dict() for r in recs]},
        sort_keys=False,
        width=110,
    )


def all_recommendations(
    rows: Sequence[dict],
    tol_rel: float = 0.05,
    tol_abs: float = 0.002,
    budget: float = DEADLINE_BUDGET,
) -> list[Recommendation]:
    """`recommend_for_rate` for every engine, task and rate of a settings sweep's rows."""
    keys = sorted(
        {
            (r['engine'], r['cloth'], r['primitive'], float(r['rate_hz']))
            for r in rows
            if r.get('mode') == 'settings'
        }
    )
    recs = [recommend_for_rate(rows, *key, tol_rel, tol_abs, budget) for key in keys]
    return [r for r in recs if r is not None]


def provenance(
    rows: Sequence[dict], tol_rel: float, tol_abs: float, budget: float, note: str = ''
) -> dict:
    """Return where a recommendation file's numbers come from: sweep size, engines, load, rule."""
    settings = [r for r in rows if r.get('mode') == 'settings']
    loads = finite(r.get('load_avg_1min') for r in settings)
    return {
        'generated': datetime.now(timezone.utc).strftime('%Y-%m-%d %H:%M UTC'),
        'from': (
            f'{len(settings)} settings-sweep cells (`cloth-bench sweep --mode settings`), lockstep'
        ),
        'engines': sorted(
            {f'{r["engine"]} {r["engine_version"]}' for r in settings if r.get('engine_version')}
        ),
        'rule': (
            f'cheapest (median step time) with CD <= best + max({tol_rel:g} x best, {tol_abs:g} m)'
            f' and step p99 < {budget:g} x period; if none meets the deadline, the cheapest within'
            ' tolerance (meets_deadline false)'
        ),
        'machine': (
            f'{settings[0].get("cpu_count") if settings else "?"} cores; 1-minute load average'
            f' during the sweep {np.median(loads):.1f} (median,'
            f' {loads.min():.1f}-{loads.max():.1f})'
            if len(loads)
            else 'unknown'
        ),
        'note': note,
    }
