"""
The report's sections of the metrics beside the paper's (docs/metrics.md) and Fig. 4's numbers.

- every metric per cloth, task, engine and rate (mean +- std over seeds), the groups of each cloth
  and task ranked on the metric chosen with `--metric` (the paper's CD by default);
- the paper's Fig. 4 CD / HD under each panel beside ours, from a run's frames.csv at the same
  time steps (`cloth-bench run --figures` writes the figure; the numbers are docs/benchmark.md's).
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import Sequence

from cloth_bench_ros.engines import engine_label
from cloth_bench_ros.metric_choice import DEFAULT_METRIC, metric as metric_choice, METRICS
from cloth_bench_ros.options import OPTIONS
from cloth_bench_ros.report.blocks import Block, heading, paragraph, Table, table_block
from cloth_bench_ros.sweep.aggregate import group, stat

# The paper's Fig. 4 (towel, one simulation with the identified parameters): the time steps (s
# from the start of the motion) and the CD / HD (m) under each panel.
FIG4_TIMES = {'dynamic': (0.5, 1.5, 2.5, 3.5), 'quasi_static': (1.0, 4.0, 8.0, 14.0)}
PAPER_FIG4: dict[str, dict[str, tuple[tuple[float, float], ...]]] = {
    'mujoco': {
        'dynamic': ((0.036, 0.108), (0.088, 0.143), (0.110, 0.146), (0.136, 0.220)),
        'quasi_static': ((0.051, 0.142), (0.049, 0.151), (0.082, 0.131), (0.044, 0.180)),
    },
    'bullet': {
        'dynamic': ((0.152, 0.282), (0.069, 0.262), (0.185, 0.315), (0.407, 0.511)),
        'quasi_static': ((0.058, 0.187), (0.050, 0.189), (0.056, 0.144), (0.170, 0.413)),
    },
    'flex': {
        'dynamic': ((0.045, 0.094), (0.226, 0.448), (0.424, 0.646), (0.281, 0.394)),
        'quasi_static': ((0.062, 0.142), (0.061, 0.143), (0.052, 0.122), (0.041, 0.134)),
    },
    'sofa': {
        'dynamic': ((0.032, 0.074), (0.088, 0.268), (0.107, 0.193), (0.167, 0.389)),
        'quasi_static': ((0.066, 0.130), (0.067, 0.132), (0.062, 0.127), (0.067, 0.156)),
    },
}


def _fmt(s, digits: int = 4) -> str:
    return s.text(digits, show_n=False) if s.n else '-'


def metrics_table(rows: Sequence[dict], metric: str = DEFAULT_METRIC) -> Table | None:
    """Return every metric per (cloth, task, engine, rate), ranked within each cloth and task."""
    chosen = metric_choice(metric)
    measured = [r for r in rows if r.get('CD_reverse') is not None or r.get('EMD') is not None]
    if not measured:
        return None
    shown = list(METRICS.values())
    body = []
    by_task = group(measured, 'cloth', 'primitive')
    for (cloth, primitive), task_rows in sorted(by_task.items(), key=lambda kv: str(kv[0])):
        cells = group(task_rows, 'engine', 'config', 'rate_hz')
        ranked = sorted(
            cells.items(), key=lambda kv: chosen.sort_key(stat(kv[1], chosen.key).mean)
        )
        for rank, ((engine, config, rate), cell_rows) in enumerate(ranked, 1):
            name = f'{engine_label(engine)} {config} {float(rate):g} Hz'
            line = [str(cloth), str(primitive), str(rank), name]
            line += [_fmt(stat(cell_rows, m.key), 3 if not m.unit else 4) for m in shown]
            body.append(line)
    headers = ['cloth', 'task', f'rank ({chosen.name})', 'engine'] + [m.name for m in shown]
    return Table('metrics', headers, body, 'lllr' + 'r' * len(shown))


def metrics_section(rows: Sequence[dict], metric: str = DEFAULT_METRIC) -> list[Block]:
    """Return the section of every metric beside the paper's, ranked on the chosen one."""
    table = metrics_table(rows, metric)
    if table is None:
        return []
    chosen = metric_choice(metric)
    return [
        heading(2, "Every metric beside the paper's, ranked on " + chosen.label),
        paragraph(
            "Mean ± std over seeds of the task window. cd, hd: the paper's (simulated vertices"
            ' to real points); *_reverse: real points to the simulated surface (real cloth the'
            ' simulation misses); *_surface: area samples of the simulated surface to the real'
            ' points; *_two_sided: their mean (CD) and larger (HD); precision, recall, fscore at'
            ' the threshold; emd: optimal transport between subsamples; contact_onset: simulated'
            ' minus real first table contact (s, dynamic). In metres, L1; docs/metrics.md says'
            f' what each sees. Ranked within each cloth and task on {chosen.name}'
            f' ({"more" if chosen.higher_is_better else "less"} is better'
            f'{", by magnitude" if chosen.absolute else ""}; `--metric` chooses).'
        ),
        table_block(table),
    ]


def _frames(path: Path) -> list[dict]:
    with path.open(newline='') as f:
        return list(csv.DictReader(f))


def fig4_table(run_dir: Path) -> Table | None:
    """Return ours beside the paper's Fig. 4 values at its time steps, for one run directory."""
    frames, summary = run_dir / 'frames.csv', run_dir / 'summary.json'
    if not frames.is_file() or not summary.is_file():
        return None
    run = json.loads(summary.read_text()).get('run', {})
    primitive = run.get('primitive', OPTIONS['primitive'].default)
    times = FIG4_TIMES.get(primitive)
    rows = _frames(frames)
    if times is None or not rows:
        return None
    body = []
    for engine in dict.fromkeys(r['engine'] for r in rows):
        mine = [r for r in rows if r['engine'] == engine]
        line = [engine_label(engine)]
        for k, t in enumerate(times):
            r = min(mine, key=lambda r: abs(float(r['t']) - t))
            cd, hd = float(r['cd']), float(r['hd'])
            ours = f'{cd:.3f} / {hd:.3f}' if math.isfinite(cd) else 'diverged'
            paper = PAPER_FIG4.get(engine, {}).get(primitive)
            if paper:
                ours += f' (paper {paper[k][0]:.3f} / {paper[k][1]:.3f})'
            line.append(ours)
        body.append(line)
    headers = ['engine'] + [f't = {t:g} s CD / HD' for t in times]
    return Table(f'fig4_{run_dir.name}', headers, body, 'l' + 'r' * len(times))


def fig4_blocks(results_dir: Path) -> list[Block]:
    """Return the Fig. 4 number tables of the run directories that drew the figure."""
    found = sorted({*results_dir.glob('qualitative.png'), *results_dir.glob('*/qualitative.png')})
    blocks: list[Block] = []
    for figure in found:
        table = fig4_table(figure.parent)
        if table is not None:
            blocks += [
                paragraph(
                    f"{figure.parent.name}: CD / HD (m) at the paper's Fig. 4 time steps, ours"
                    " beside the paper's (towel, its identified parameters; docs/benchmark.md)."
                ),
                table_block(table),
            ]
    return blocks
