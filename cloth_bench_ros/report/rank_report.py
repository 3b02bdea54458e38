"""
`cloth-bench report` on a `cloth-bench rank` output directory: the ranking with its figures.

Reads `<dir>/rank.json` (everything `rank` printed, and the numbers under it) and writes
report.md / report.html with the table and sentences `rank` printed, and per cloth and task two
figures: the ranking (held-out mean with its 95 % paired bootstrap interval and its diverged runs
per engine, the preset's held-out mean beside it, the floor as a band) and speed against error
(step time p50 at the ranking's rate against the held-out mean, the Pareto front marked, the
deadline of that rate).
"""

from __future__ import annotations

from functools import partial
import json
from pathlib import Path
from typing import Any

from cloth_bench_ros.errors import InputError
from cloth_bench_ros.metric_choice import metric as metric_of
from cloth_bench_ros.rank.answer import deadline_ms
from cloth_bench_ros.report.blocks import (
    Document, figure_block, heading, paragraph, table_block, write_document,
)
from cloth_bench_ros.report.figures import plt, save_figure
from cloth_bench_ros.report.rank import rank_lines, rank_table

RANK_FILE = 'rank.json'


def load_rank(directory: Path) -> dict[str, Any]:
    """Return a rank directory's rank.json; InputError (one line) when it is not one."""
    path = Path(directory) / RANK_FILE
    try:
        result = json.loads(path.read_text())
        result['answer'].items()
        result['spec']['metric'], result['spec']['rate_hz']
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
        raise InputError(
            f'rank results {path}: not a rank.json of cloth-bench rank ({exc})'
        ) from None
    return result


def _axis_label(result: dict) -> str:
    m = metric_of(result['spec']['metric'])
    return f'{m.name.upper()} held-out' + (f' ({m.unit})' if m.unit else '')


def plot_ranking(result: dict, group: str, path: Path) -> Path | None:
    """Draw one group's ranking: mean and 95 % interval per engine, preset, floor."""
    a = result['answer'][group]
    ranked = a['ranking']
    if not ranked:
        return None
    fig, ax = plt.subplots(figsize=(7, 1.2 + 0.6 * len(ranked)))
    ys = list(range(len(ranked)))[::-1]
    for y, r in zip(ys, ranked):
        if r['mean'] is not None and r['low'] is not None:  # None: every run diverged
            ax.errorbar(r['mean'], y, xerr=[[r['mean'] - r['low']], [r['high'] - r['mean']]],
                        fmt='o', color='C0', capsize=4,
                        label='identified' if y == ys[0] else None)
        preset = a['entrants'][r['name']]['preset']['mean']
        if preset is not None:
            ax.plot(preset, y, 'x', color='C1', label='preset' if y == ys[0] else None)
    floor = a['floor']
    if floor.get('mean') is not None and result['spec']['metric'] == 'cd':
        ax.axvspan(floor['min'], floor['max'], color='0.85', label='floor (trials to trials)')
        ax.axvline(floor['mean'], color='0.5', lw=1)
    ax.set_yticks(ys)
    ax.set_yticklabels([f'{r["rank"]}. {r["name"]} (P {r["p_rank"]:.2f}'
                        + (f', diverged {r["diverged"]}/{r["runs"]})' if 'diverged' in r else ')')
                        for r in ranked])
    ax.set_xlabel(_axis_label(result))
    ax.set_title(f'{group}: held-out trials, 95 % paired bootstrap intervals')
    ax.legend(loc='best', fontsize=8)
    return save_figure(fig, path)


def plot_speed_error(result: dict, group: str, path: Path) -> Path | None:
    """Draw one group's step time p50 at the rate against the held-out mean; Pareto marked."""
    a = result['answer'][group]
    rate = f'{result["spec"]["rate_hz"]:g}'
    front = set(a['pareto'].get(rate, []))
    points = []
    for name, e in a['entrants'].items():
        step = e['timing'].get(rate, {}).get('step_p50_ms')
        if e['identified']['mean'] is not None and step is not None:
            points.append((name, e['identified']['mean'], step))
    if not points:
        return None
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    for name, err, step in points:
        ax.plot(step, err, 'o' if name in front else 's', color='C2' if name in front else 'C7')
        ax.annotate(name + (' (Pareto)' if name in front else ''), (step, err), fontsize=8,
                    xytext=(4, 4), textcoords='offset points')
    ax.axvline(deadline_ms(float(rate)), color='C3', ls='--', lw=1,
               label=f'deadline at {rate} Hz (p99 rule)')
    ax.set_xscale('log')
    ax.set_xlabel(f'step time p50 at {rate} Hz (ms)')
    ax.set_ylabel(_axis_label(result))
    ax.set_title(f'{group}: speed against error at the identified parameters')
    ax.legend(loc='best', fontsize=8)
    return save_figure(fig, path)


def rank_report(directory: Path, out: Path) -> tuple[Path, Path, list[Path], dict]:
    """Write the rank directory's report into `out`; (markdown, html, images, tables)."""
    result = load_rank(directory)
    spec = result['spec']
    doc = Document('cloth_bench_ros: which simulator for this cloth')
    doc.extend([
        heading(2, 'The ranking on held-out trials'),
        paragraph(
            f'{len(result.get("trials", []))} trials from {", ".join(spec.get("recordings", []))};'
            f' engines {", ".join(spec.get("entrants", []))}; ranked by'
            f' {spec["metric"].upper()} (identified on'
            f' {str(spec.get("objective", spec["metric"])).upper()}); {spec.get("seeds")}'
            f' held-out seeds; identification budget {spec.get("trials") or "auto"} per'
            f' sampler ({spec.get("sampler")}).'
        ),
        table_block(rank_table(result)),
        *[paragraph(line) for line in rank_lines(result)],
    ])
    for group in result['answer']:
        doc.extend([
            heading(3, group),
            figure_block(f'rank_{group}.png', f'{group}: the ranking with its intervals',
                         partial(plot_ranking, result, group)),
            figure_block(f'rank_speed_{group}.png', f'{group}: speed against error',
                         partial(plot_speed_error, result, group)),
        ])
    tables = {t.name: t for t in doc.tables()}
    md, html, images = write_document(doc, Path(out))
    return md, html, images, tables
