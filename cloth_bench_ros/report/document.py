"""
The report of a study (`cloth-bench report RESULTS`): Markdown and HTML, PNG and CSV.

`render_report` composes the document from section builders, each a short function of the rows
that returns blocks (headings, paragraphs, tables, figures to draw); `write_document` does every
file write. Sections: the paper's Table III and Fig. 5 layouts, speed against error with its
Pareto front, per-frame CD and HD, timing and hardware in the loop, stability, the settings
recommendation, the stress suite, and parameter identification when the directory holds one.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from datetime import datetime, timezone
from functools import partial
from pathlib import Path
import re
from typing import Mapping, Sequence

from cloth_bench_ros.engines import engine_label
from cloth_bench_ros.errors import InputError
from cloth_bench_ros.metric_choice import DEFAULT_METRIC
from cloth_bench_ros.options import OPTIONS
from cloth_bench_ros.rank.cross_reference import identified_rankings
from cloth_bench_ros.rank.ranking import Ranking
from cloth_bench_ros.report import figures, time_figures
from cloth_bench_ros.report.blocks import (
    Block,
    Document,
    figure_block,
    heading,
    paragraph,
    Table,
    table_block,
    write_document,
)
from cloth_bench_ros.report.cloth_error import cloth_error_section
from cloth_bench_ros.report.comparison import comparison_section
from cloth_bench_ros.report.identification import find_identifications, identification_section
from cloth_bench_ros.report.metric_sections import metrics_section
from cloth_bench_ros.report.rank_report import RANK_FILE, rank_report
from cloth_bench_ros.report.selections import (
    cloths_of,
    DEFAULT_MODE,
    fmt_fixed,
    fmt_sig,
    paper_rows,
    table_rate,
)
from cloth_bench_ros.report.study_sections import (
    cross_reference_blocks,
    identifications_summary,
    settings_section,
    stress_section,
)
from cloth_bench_ros.report.tables import (
    errors_table,
    fig5_table,
    PAPER_FIG5,
    stability_table,
    table3,
    timing_table,
)
from cloth_bench_ros.studies.results import load_rows, RESULTS_FILE
from cloth_bench_ros.studies.stress import load_stress, STRESS_FILE
from cloth_bench_ros.sweep.aggregate import finite
import numpy as np


@dataclass
class ReportOutcome:
    markdown: Path
    html: Path
    images: list[Path]
    tables: dict[str, Table]
    recommendations: list[dict]
    pareto: list[dict]


def results_table(rows: Sequence[dict]) -> Table:
    """Every row and field of the results, as one table (results.csv)."""
    keys: list[str] = []
    for r in rows:
        keys += [k for k in r if k not in keys]
    return Table('results', keys, [[_csv_cell(r.get(k)) for k in keys] for r in rows])


def _csv_cell(value: object) -> str:
    if isinstance(value, dict):
        return ';'.join(f'{a}={b}' for a, b in value.items())
    return '' if value is None else f'{value}'


def overview_section(rows: Sequence[dict]) -> list[Block]:
    """Return what the report is made of: cells, status, engine versions, compute, machine load."""
    status = Counter(r.get('status') for r in rows)
    versions = sorted(
        {
            f'{engine_label(r["engine"])} {r["engine_version"]}'
            for r in rows
            if r.get('engine_version')
        }
    )
    compute = float(finite(r.get('cell_wall_s') for r in rows).sum())
    loads = finite(r.get('load_avg_1min') for r in rows)
    load_text = (
        ' Step times are wall times: the 1-minute load average at the end of the cells was '
        f'{np.median(loads):.1f} (median; {loads.min():.1f}-{loads.max():.1f}) on '
        f'{rows[0].get("cpu_count") or "?"} cores; a load above the core count inflates them.'
        if len(loads)
        else ''
    )
    return [
        paragraph(
            f'Rendered {datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")} from'
            f' {len(rows)} cells ({status.get("ok", 0)} ok, {status.get("diverged", 0)} diverged,'
            f' {status.get("error", 0)} errors); engines {", ".join(versions) or "-"};'
            f' {compute / 3600:.2f} h of cell compute in total. CD and HD are one-sided L1'
            ' distances in metres (docs/benchmark.md, section 3); mean ± std over seeds and trial'
            ' bags (population std); a diverged run is counted, not averaged. All results here'
            ' are ours unless a column or paragraph is marked **paper**.'
            + load_text + inputs_text(rows)
        )
    ]


def inputs_text(rows: Sequence[dict]) -> str:
    """Return the sentence naming the task files and cloth meshes the cells ran ('' : none)."""
    parts = []
    for field, sha, what in (('task_file', 'task_sha256', 'task file'),
                             ('cloth_mesh', 'mesh_sha256', 'cloth mesh')):
        files = sorted({(r[field], str(r.get(sha, ''))[:12]) for r in rows if r.get(field)})
        if files:
            named = ', '.join(f'`{name}` (sha256 {digest})' for name, digest in files)
            cells = sum(1 for r in rows if r.get(field))
            parts.append(f'{cells} cells ran the {what} {named}')
    return (' ' + '; '.join(parts) + '; the others the shipped task on the grid.') if parts else ''


def paper_configs(rows: Sequence[dict]) -> list[str]:
    """Return the configurations of the lockstep paper sweep, Table III's (the presets) first."""
    counts = Counter(
        r.get('config', 'preset')
        for r in rows
        if r.get('mode', DEFAULT_MODE) == 'paper'
        and r.get('pacing', OPTIONS['pacing'].default) == 'lockstep'
    )
    if not counts:
        return []
    main = 'preset' if 'preset' in counts else counts.most_common(1)[0][0]
    return [main] + sorted(c for c in counts if c != main)


def table3_section(paper: Sequence[dict], config: str, wanted_rate: float) -> list[Block]:
    """Return the paper's Table III layout at one rate, ours beside the paper's numbers."""
    rate = table_rate(paper, wanted_rate)
    what = 'engine presets' if config == 'preset' else f'configuration `{config}`'
    combos = len({(r['seed'], r.get('trial', 0)) for r in paper if float(r['rate_hz']) == rate})
    return [
        heading(2, f'Table III layout: accuracy per cloth and engine at {rate:g} Hz'),
        paragraph(
            f'Columns marked (ours): this system, {what}, lockstep pacing, {rate:g} Hz, over'
            f' {combos} seed x trial '
            f"combinations per cell; bold = best of ours. Columns marked (paper) are the paper's"
            f' Table III '
            f'(docs/benchmark.md, section 6: real rags, 3 trials x 20 seeds, MuJoCo 3.1.1, Bullet'
            f' 3.26, Flex 1.2, '
            f'SOFA 23.06; bold = best in the paper). The paper scores real clouds; ours are scored'
            f' against the '
            f'bags given to the sweep, so the columns compare layouts and magnitudes, not the same'
            f' data.'
        ),
        table_block(table3(paper, rate if rate is not None else wanted_rate)),
    ]


def fig5_section(
    sel: Sequence[dict], config: str, main_config: str, wanted_cloth: str
) -> list[Block]:
    """Return the paper's Fig. 5 layout (frequency study) for one configuration."""
    cloths = cloths_of(sel)
    cloth = wanted_cloth if wanted_cloth in cloths else cloths[0]
    suffix = (
        '' if config == main_config else '_' + re.sub(r'[^A-Za-z0-9]+', '_', config).strip('_')
    )
    what = (
        'engine presets (internal time step from the preset; the rate is the target rate)'
        if config == 'preset'
        else f'configuration `{config}`'
        + (
            " (one internal step per target, as in the paper's frequency study)"
            if 'step=1/rate' in config
            else ''
        )
    )
    title = f'{cloth}: step time, L_s, CD_d, CD_q against rate ({config})'
    return [
        heading(
            2,
            f'Fig. 5 layout: frequency study, {cloth}'
            + ('' if config == 'preset' else f', {config}'),
        ),
        paragraph(
            f'Ours: {what}; mean ± std over seeds, log scales; open markers: some runs diverged.'
        ),
        figure_block(
            f'fig5{suffix}.png',
            f'Fig. 5 layout, {cloth}, {config} (ours)',
            lambda path: figures.plot_fig5(sel, cloth, path, title),
        ),
        table_block(fig5_table(sel, cloth, f'fig5{suffix}')),
        paragraph('**paper** — ' + PAPER_FIG5),
    ]


def speed_error_section(
    rows: Sequence[dict], wanted_cloth: str, pareto: list[dict]
) -> list[Block]:
    """Speed against error for one cloth, with its Pareto front (appended to `pareto`)."""
    lockstep = [
        r
        for r in rows
        if r.get('mode', DEFAULT_MODE) == 'paper'
        and r.get('pacing', OPTIONS['pacing'].default) == 'lockstep'
    ]
    cloth = (
        wanted_cloth
        if any(r['cloth'] == wanted_cloth for r in lockstep)
        else (cloths_of(lockstep) or [''])[0]
    )
    sel = [r for r in lockstep if r['cloth'] == cloth]  # one cloth: every configuration has it
    if not sel:
        return []
    title = f'{cloth}: CD against compute per simulated second; Pareto front dashed'
    front = figures.speed_error_front(sel)
    pareto += front
    return [
        heading(2, f'Speed against error ({cloth})'),
        paragraph(
            'One point per engine, rate and configuration (mean over seeds); x: engine compute per'
            ' simulated second (mean step time x rate; below 1 the engine alone is faster than'
            ' real time); y: CD of the task. The Pareto front joins the points that no other point'
            ' beats in both.'
        ),
        figure_block(
            'speed_error.png',
            'speed against error with its Pareto front (ours)',
            lambda path: figures.plot_speed_error(sel, path, title)[0],
        ),
        table_block(
            Table(
                'pareto',
                ['task', 'engine', 'point', 'compute s/s', 'CD (m)'],
                [
                    [
                        f['task'],
                        engine_label(f['engine']),
                        f['point'],
                        fmt_sig(f['compute_s_per_s']),
                        fmt_fixed(f['CD'], 4),
                    ]
                    for f in front
                ],
                'lllrr',
            )
        ),
    ]


def _plot_frames(rows: Sequence[dict], results_dir: Path, cloth: str, path: Path) -> Path | None:
    """Draw the per-frame figure of `cloth` into `path` (a figure block's draw function)."""
    return time_figures.plot_frames(rows, results_dir, cloth, path)


def frames_section(paper: Sequence[dict], results_dir: Path) -> list[Block]:
    """Per-frame CD and HD over time, first seed, per cloth."""
    blocks = [heading(2, 'Per-frame CD and HD over time')]
    kept = [r for r in paper if time_figures.frames_file(results_dir, r) is not None]
    for cloth in cloths_of(kept):
        blocks.append(
            figure_block(
                f'frames_{cloth}.png',
                f'{cloth}: per-frame CD and HD, first seed; red: change of phase (ours)',
                partial(_plot_frames, kept, results_dir, cloth),
            )
        )
    if not kept:
        blocks.append(
            paragraph(
                'No per-frame scores were kept in this sweep '
                '(frames are kept for the first seed by default).'
            )
        )
    return blocks


def timing_section(rows: Sequence[dict]) -> list[Block]:
    """Step time, latency, deadline misses and real-time factor."""
    timed = [r for r in rows if r.get('status') in ('ok', 'diverged')]
    if not timed:
        return []
    return [
        heading(2, 'Timing and hardware in the loop'),
        paragraph(
            'Step time: wall time of one engine step (all internal substeps) per target. Latency:'
            " wall time until the engine's state reaches the evaluator, counted from the"
            " target's due time on the wall-clock schedule (first target + k / rate) with"
            ' realtime pacing, so a run that falls behind its schedule shows it, and from the'
            " target's arrival with lockstep pacing. Deadline misses: steps whose latency exceeds"
            ' 1 / rate (mean per run / steps per run). Real-time factor: simulated time over wall'
            ' time of the run (lockstep runs as fast as they can; realtime runs are paced by the'
            ' wall clock and cannot exceed 1). Medians over runs.'
        ),
        table_block(timing_table(timed)),
        figure_block(
            'latency.png',
            'latency percentiles against the deadline (ours)',
            lambda path: time_figures.plot_latency(timed, path),
        ),
    ]


def stability_section(rows: Sequence[dict]) -> list[Block]:
    """Divergences per engine, rate, configuration and task; the cells that failed."""
    blocks = [heading(2, 'Stability'), table_block(stability_table(rows))]
    errs = errors_table(rows)
    if errs.rows:
        blocks += [heading(3, 'Cells that failed'), table_block(errs)]
    return blocks


def render_report(
    rows: Sequence[dict],
    results_dir: Path,
    out_dir: Path,
    stress_rows: Sequence[dict] | None = None,
    wanted_rate: float = OPTIONS['rate_hz'].default,
    fig5_cloth: str = 'towel',
    tol_rel: float = 0.05,
    tol_abs: float = 0.002,
    title: str = 'cloth_bench_ros: speed against error',
    identifications: Sequence[dict] = (),
    metric: str = DEFAULT_METRIC,
    xref_rankings: Mapping[tuple[str, str], Ranking] | None = None,
) -> ReportOutcome:
    """
    Render every table and figure of the rows into out_dir (report.md, .html, .png, .csv).

    xref_rankings: the cross-reference study's identified engines ranked per reference and task
    (rank/cross_reference.py's `identified_rankings` of the rows), rendered as given.
    """
    results_dir, out_dir = Path(results_dir), Path(out_dir)
    doc = Document(title)
    pareto: list[dict] = []
    recs: list[dict] = []
    if rows:
        doc.extend(overview_section(rows))
    configs = paper_configs(rows)
    paper = paper_rows(rows, configs[0]) if configs else []
    if paper:
        doc.extend(table3_section(paper, configs[0], wanted_rate))
    for config in configs:
        doc.extend(fig5_section(paper_rows(rows, config), config, configs[0], fig5_cloth))
    doc.extend(speed_error_section(rows, fig5_cloth, pareto))
    if paper:
        doc.extend(frames_section(paper, results_dir))
    doc.extend(timing_section(rows))
    if rows:
        doc.extend(stability_section(rows))
    doc.extend(settings_section(rows, tol_rel, tol_abs, recs))
    if stress_rows:
        doc.extend(stress_section(stress_rows))
    if len(identifications) > 1:
        doc.extend(identifications_summary(identifications))
    for ident in identifications:
        doc.extend(identification_section(ident, rows))
    doc.extend(metrics_section(rows, metric))
    doc.extend(cross_reference_blocks(rows, dict(xref_rankings or {}), metric))
    doc.extend(comparison_section(results_dir))
    doc.extend(cloth_error_section(results_dir))
    tables = {t.name: t for t in doc.tables()}
    md, html, images = write_document(doc, out_dir, csv_only=[results_table(rows)])
    return ReportOutcome(md, html, images, tables, recs, pareto)


def report_directory(
    results: Path,
    out: Path,
    stress: Path | None = None,
    wanted_rate: float = OPTIONS['rate_hz'].default,
    fig5_cloth: str = 'towel',
    tol_rel: float = 0.05,
    tol_abs: float = 0.002,
    metric: str = DEFAULT_METRIC,
) -> ReportOutcome:
    """
    `cloth-bench report`: the report of a results.jsonl (or its directory), or of a rank directory.

    With the stress suite and the identifications found beside it; ValueError (one line) when there
    is nothing usable to report.
    """
    if results.is_dir() and (results / RANK_FILE).is_file():  # a `cloth-bench rank` directory
        md, html, images, tables = rank_report(results, out)
        return ReportOutcome(md, html, images, tables, [], [])

    results_file = results / RESULTS_FILE if results.is_dir() else results
    identifications = (
        find_identifications(results_file.parent) if results_file.parent.is_dir() else []
    )
    if not results_file.is_file() and not identifications:
        raise InputError(
            f'results {results}: no {RESULTS_FILE} there (run `cloth-bench sweep` first)'
        )
    rows = load_rows(results_file)
    if not rows and not identifications:
        raise InputError(f'results {results_file}: holds no result rows')
    if stress is None and (results_file.parent / STRESS_FILE).is_file():
        stress = results_file.parent / STRESS_FILE
    if stress is not None and not Path(stress).exists():
        raise InputError(f'stress results {stress}: no such file or directory')
    stress_rows = load_stress(Path(stress)) if stress is not None else None
    return render_report(
        rows,
        results_file.parent,
        out,
        stress_rows,
        wanted_rate,
        fig5_cloth,
        tol_rel,
        tol_abs,
        identifications=identifications,
        metric=metric,
        xref_rankings=identified_rankings(rows, metric),
    )
