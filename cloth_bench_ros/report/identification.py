"""
Parameter identification in the report: before/after, convergence, importance.

Reads the identification.json that `cloth-bench identify` writes (in the results directory or a
directory below it) as untrusted input: a file that is not such an object is a ResultsError.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Sequence

from cloth_bench_ros.engines import engine_label
from cloth_bench_ros.report.blocks import (
    Block,
    figure_block,
    heading,
    paragraph,
    Table,
    table_block,
)
from cloth_bench_ros.report.figures import plt, save_figure
from cloth_bench_ros.report.selections import fmt_sig
from cloth_bench_ros.safe_io import read_text_bounded, safe_name, UnsafeInputError
from cloth_bench_ros.studies.results import ResultsError

SUMMARY_FILE = 'identification.json'
REQUIRED = {
    'engine': str,
    'cloth': str,
    'primitive': str,
    'objective': str,
    'params': dict,
    'per_sampler': dict,
    'preset_params': dict,
    'validation': list,
    'samplers': list,
}


def load_identification(path: Path) -> dict:
    """Return an identification.json, checked; ResultsError naming the file if it is not usable."""
    try:
        data = json.loads(read_text_bounded(path))
    except (UnsafeInputError, json.JSONDecodeError) as exc:
        raise ResultsError(f'{path}: not an identification summary ({exc})') from None
    if not isinstance(data, dict):
        raise ResultsError(f'{path}: an identification summary must be a JSON object')
    for key, kind in REQUIRED.items():
        if not isinstance(data.get(key), kind):
            raise ResultsError(f'{path}: {key} missing or not a {kind.__name__}')
    try:
        for key in ('engine', 'cloth', 'primitive'):
            safe_name(data[key], key)
    except UnsafeInputError as exc:
        raise ResultsError(f'{path}: {exc}') from None
    for name, result in data['per_sampler'].items():
        if not isinstance(result, dict) or not isinstance(result.get('convergence', []), list):
            raise ResultsError(
                f'{path}: per_sampler.{name} is not an object with a convergence list'
            )
    return data


def find_identifications(results_dir: Path) -> list[dict]:
    """Return the identifications in results_dir and the directories up to two levels below it."""
    found = []
    for pattern in (SUMMARY_FILE, f'*/{SUMMARY_FILE}', f'*/*/{SUMMARY_FILE}'):
        found += sorted(Path(results_dir).glob(pattern))
    return [load_identification(p) for p in found]


def _num(value: object) -> float:
    return (
        float(value)
        if isinstance(value, (int, float)) and not isinstance(value, bool)
        else math.nan
    )


def params_table(ident: dict, suffix: str) -> Table:
    """Per fitted parameter: the preset's value, the identified one, the search range."""
    space: dict = ident['space'] if isinstance(ident.get('space'), dict) else {}
    rows = []
    for name, value in ident['params'].items():
        r = (
            space[name]
            if isinstance(space.get(name), list) and len(space[name]) == 3
            else None
        )
        rng = (
            f'[{fmt_sig(_num(r[0]), 3)}, {fmt_sig(_num(r[1]), 3)}]{" log" if r[2] else ""}'
            if r
            else '-'
        )
        rows.append(
            [
                str(name),
                fmt_sig(_num(ident['preset_params'].get(name)), 4),
                fmt_sig(_num(value), 4),
                rng,
            ]
        )
    return Table(
        f'identified_params_{suffix}',
        ['parameter', 'preset', 'identified', 'search range'],
        rows,
        'lrrl',
    )


def before_after_table(ident: dict, suffix: str) -> Table:
    """Return the objective before and after identification, on the fitted and held-out seeds."""
    metric = str(ident['objective']).upper()
    rows = [
        [
            f'seed {ident.get("seed", 0)} (fitted)',
            'identification bag',
            fmt_sig(_num(ident.get('preset_value')), 4),
            fmt_sig(_num(ident.get('value')), 4),
            '1 / 1',
        ]
    ]
    for v in ident['validation']:
        if not isinstance(v, dict) or not all(
            isinstance(v.get(k), dict) for k in ('preset', 'identified')
        ):
            continue
        p, i = v['preset'], v['identified']
        rows.append(
            [
                'held-out seeds',
                Path(str(v.get('bag', ''))).name,
                _mean_std(p),
                _mean_std(i),
                (
                    f'{i.get("ok", 0)} / {i.get("n", 0)} ok ({p.get("ok", 0)} / {p.get("n", 0)}'
                    ' preset)'
                ),
            ]
        )
    return Table(
        f'identification_{suffix}',
        ['runs', 'bag', f'{metric} preset (m)', f'{metric} identified (m)', 'runs ok'],
        rows,
        'llrrl',
    )


def _mean_std(stat: dict) -> str:
    mean = _num(stat.get('mean'))
    return f'{mean:.4g} ± {_num(stat.get("std")):.2g}' if math.isfinite(mean) else '-'


def importance_table(ident: dict, suffix: str) -> Table:
    """Parameter importance (PED-ANOVA) per sampler."""
    samplers = [
        s
        for s in ident['per_sampler']
        if isinstance(ident['per_sampler'][s].get('importance'), dict)
    ]
    names = list(ident['params'])
    rows = [
        [n] + [fmt_sig(_num(ident['per_sampler'][s]['importance'].get(n)), 3) for s in samplers]
        for n in names
    ]
    return Table(
        f'importance_{suffix}',
        ['parameter'] + [f'importance ({s})' for s in samplers],
        rows,
        'l' + 'r' * len(samplers),
    )


def plot_convergence(ident: dict, path: Path) -> Path | None:
    """Best objective so far against trials, one line per sampler (failed trials marked)."""
    fig, ax = plt.subplots(figsize=(7.5, 4.5))
    drawn = False
    for name, result in ident['per_sampler'].items():
        points = [p for p in result.get('convergence', []) if isinstance(p, list) and len(p) == 3]
        xs = [i + 1 for i, p in enumerate(points) if p[2] is not None]
        ys = [_num(p[2]) for p in points if p[2] is not None]
        if not xs:
            continue
        (line,) = ax.plot(xs, ys, lw=1.5, label=f'{name}: best so far')
        tried = [(i + 1, _num(p[1])) for i, p in enumerate(points) if p[1] is not None]
        ax.scatter(
            [t[0] for t in tried], [t[1] for t in tried], s=6, alpha=0.35, color=line.get_color()
        )
        failed = sum(p[1] is None for p in points)
        if failed:
            ax.plot([], [], ls='', label=f'{name}: {failed} failed (diverged) trials')
        for _, after, _ in (result.get('budget') or {}).get('doublings') or []:
            ax.axvline(after, color=line.get_color(), ls=':', lw=0.8)
        drawn = True
    if not drawn:
        plt.close(fig)
        return None
    preset = _num(ident.get('preset_value'))
    if math.isfinite(preset):
        ax.axhline(preset, color='gray', ls='--', lw=1, label='preset')
    ax.set_yscale('log')
    ax.set_xlabel('trials')
    ax.set_ylabel(f'{str(ident["objective"]).upper()} (m)')
    ax.grid(True, which='both', alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(
        f'{engine_label(ident["engine"])} {ident["cloth"]} {ident["primitive"]} against'
        f' {Path(str(ident.get("bag", ""))).name}: convergence (dotted: budget doublings)',
        fontsize=9,
    )
    return save_figure(fig, path)


def file_suffix(ident: dict) -> str:
    """Return <engine>_<cloth>_<task>[_<reference>]: one name per identification of a report."""
    task = f'{ident["cloth"]}_{ident["primitive"]}'
    bag = Path(str(ident.get('bag', ''))).name
    return f'{ident["engine"]}_{task}' + (bag[len(task):] if bag.startswith(task + '_') else '')


def budget_text(result: dict) -> str:
    """Return how a sampler's trial budget was chosen, e.g. 'doubling 32 -> 64: 1.2 %, enough'."""
    budget = result.get('budget') or {}
    doublings = budget.get('doublings') or []
    if not doublings:
        return 'fixed'
    steps = ', '.join(f'{a} -> {b}: {_num(g):.1%}' for a, b, g in doublings)
    return steps + ('; enough' if budget.get('reached') else '; cap reached')


def held_out(ident: dict) -> tuple[dict, dict]:
    """Return the first validation bag's (preset, identified) statistics on held-out seeds."""
    for v in ident.get('validation', []):
        if isinstance(v, dict) and isinstance(v.get('preset'), dict):
            return v['preset'], v.get('identified') or {}
    return {}, {}


def summary_table(idents: Sequence[dict]) -> Table:
    """Return one row per identification: budget per sampler, wall time, held-out CD."""
    body = []
    for ident in idents:
        preset, fitted = held_out(ident)
        body.append(
            [
                engine_label(ident['engine']) + (f' ({ident["fixed"]["model"]})'
                                                 if 'model' in (ident.get('fixed') or {}) else ''),
                Path(str(ident.get('bag', ''))).name,
                '; '.join(
                    f'{s} {r.get("trials", "?")} ({budget_text(r)})'
                    for s, r in ident['per_sampler'].items()
                ),
                f'{_num(ident.get("wall_s")) / 60:.1f}',
                _mean_std(preset) if preset else '-',
                _mean_std(fitted) if fitted else '-',
            ]
        )
    return Table(
        'identifications',
        ['engine', 'bag', 'trials per sampler (doublings)', 'wall (min)',
         'held-out CD preset (m)', 'held-out CD identified (m)'],
        body,
        'lllrrr',
    )


def identification_section(ident: dict, rows: Sequence[dict] = ()) -> list[Block]:
    """One identification: what was fitted, before/after, convergence per sampler, importance."""
    suffix = file_suffix(ident)
    trials = ', '.join(
        f'{s} {r.get("trials", "?")} trials (best {fmt_sig(_num(r.get("value")), 4)} m;'
        f' budget {budget_text(r)})'
        for s, r in ident['per_sampler'].items()
    )
    return [
        heading(
            2,
            f'Parameter identification: {engine_label(ident["engine"])}, {ident["cloth"]}'
            f' {ident["primitive"]}, against `{Path(str(ident.get("bag", ""))).name}`',
        ),
        paragraph(
            f'Minimised {str(ident["objective"]).upper()} of the task window against'
            f' `{ident.get("bag", "?")}` with seed {ident.get("seed", 0)} held constant: {trials};'
            f' kept **{ident.get("best_sampler", "?")}**. Engine version'
            f' {ident.get("engine_version", "?")}, {ident.get("date", "?")} on'
            f' {ident.get("machine", "?")}, {_num(ident.get("wall_s")) / 60:.1f} min of wall time.'
            f' The preset file is `{ident.get("preset_file", "?")}` (`cloth-bench run --presets'
            ' <that directory>`). Held-out seeds run through the full node graph.'
        ),
        table_block(params_table(ident, suffix)),
        table_block(before_after_table(ident, suffix)),
        figure_block(
            f'convergence_{suffix}.png',
            f'best {str(ident["objective"]).upper()} against trials per sampler',
            lambda path: plot_convergence(ident, path),
        ),
        paragraph(
            "Parameter importance: PED-ANOVA over each sampler's trials (Optuna; no extra"
            " dependency), the share of the objective's variation among the better trials that"
            ' each parameter explains.'
        ),
        table_block(importance_table(ident, suffix)),
    ]
