"""
The cross-reference study's rows by entrant, and its identified engines ranked per reference.

An entrant is an engine (with its model where it was entered with several) and its kind (preset
or identified). Engines identified against a reference are ranked on it by `ranking.rank_runs`,
the code `rank` ranks with: one reference bag is one trial, so the paired bootstrap draws its
seeds; divergence rate first, then the metric. report/cross_reference.py renders the rankings.
"""

from __future__ import annotations

from typing import Sequence

from cloth_bench_ros.engines import engine_label
from cloth_bench_ros.metric_choice import DEFAULT_METRIC, metric as metric_choice
from cloth_bench_ros.options import FLAGS
from cloth_bench_ros.rank.ranking import HeldOutRun, rank_runs, Ranking
from cloth_bench_ros.studies.cross_reference import DEFAULT_ENTRANTS, MODE, REFERENCES

TASKS = ('dynamic', 'quasi_static')
# Engines entered with several models (Newton: vbd, xpbd): their model is part of the name.
MODEL_ENGINES = {engine for engine, overrides in DEFAULT_ENTRANTS if 'model' in overrides}


def entrant_name(engine: str, overrides: dict) -> str:
    """Return an entrant's name: "newton (vbd)" for a model override, else the engine's label."""
    model = overrides.get('model')
    return f'{engine_label(engine)} ({model})' if model else engine_label(engine)


def row_entrant(row: dict) -> tuple[str, str, str]:
    """Return (engine, model or '', kind) of a row; kind: preset or identified."""
    kind = 'preset' if row.get('presets', FLAGS['presets'].default) == 'default' else 'identified'
    model = (row.get('params') or {}).get('model', '') if row['engine'] in MODEL_ENGINES else ''
    return row['engine'], model, kind


def cross_reference_rows(rows: Sequence[dict]) -> list[dict]:
    """Return the rows of the cross-reference study (its mode, a known reference)."""
    return [r for r in rows if r.get('mode') == MODE and r.get('reference') in REFERENCES]


def identified_rankings(
    rows: Sequence[dict], metric: str = DEFAULT_METRIC
) -> dict[tuple[str, str], Ranking]:
    """Return {(reference, task): identified engines ranked on it by the metric, bootstrapped."""
    chosen = metric_choice(metric)
    sel = [r for r in cross_reference_rows(rows) if row_entrant(r)[2] == 'identified']
    out = {}
    for ref in REFERENCES:
        for task in TASKS:
            runs: dict[str, list[HeldOutRun]] = {}
            for r in sel:
                if r['reference'] == ref and r['primitive'] == task:
                    engine, model, _ = row_entrant(r)
                    name = entrant_name(engine, {'model': model} if model else {})
                    value = chosen.row_value(r) if r.get('status') == 'ok' else None
                    runs.setdefault(name, []).append(HeldOutRun(
                        str(r.get('bag', ref)), int(r['seed']), value,
                        r.get('status') == 'diverged',
                    ))
            if runs:
                out[(ref, task)] = rank_runs(
                    runs, higher_is_better=chosen.higher_is_better, absolute=chosen.absolute
                )
    return out
