"""The report's sections beyond the paper: settings, stress, identification, cross-reference."""

from __future__ import annotations

from functools import partial
from pathlib import Path
from typing import Sequence

from cloth_bench_ros.engines import engine_label
from cloth_bench_ros.metric_choice import DEFAULT_METRIC, metric as metric_choice
from cloth_bench_ros.rank.ranking import Ranking, REPLICATES
from cloth_bench_ros.report import figures
from cloth_bench_ros.report.blocks import Block, figure_block, heading, paragraph, table_block
from cloth_bench_ros.report.cross_reference import (
    cross_reference_section,
    ranking_statements,
)
from cloth_bench_ros.report.hil import deadline_tables
from cloth_bench_ros.report.identification import summary_table
from cloth_bench_ros.report.ranking import ranking_table
from cloth_bench_ros.report.selections import engines_of
from cloth_bench_ros.report.settings import settings_tables
from cloth_bench_ros.studies.stress import stress_table, verdict


def _plot_settings(rows: Sequence[dict], title: str, chosen: list, path: Path) -> Path | None:
    """Draw one engine's settings figure into `path` (a figure block's draw function)."""
    return figures.plot_settings(rows, path, title, chosen)


def settings_section(
    rows: Sequence[dict], tol_rel: float, tol_abs: float, recs: list[dict]
) -> list[Block]:
    """Return the settings sweep section: each configuration against error, and the choice."""
    settings = [r for r in rows if r.get('mode') == 'settings']
    if not settings:
        return []
    s_tables, notes, found = settings_tables(rows, tol_rel, tol_abs)
    recs += found
    blocks = [
        heading(2, 'Model only what the scene needs: settings against error'),
        paragraph(
            f'Factorial sweep over the settings that cost time. Tolerance: a configuration is'
            f' within tolerance '
            f"when its mean CD is at most the best stable configuration's plus max({tol_rel:.0%}"
            ' of it, '
            f'{tol_abs * 1e3:g} mm); the recommendation is the cheapest (mean step time) within'
            ' tolerance. '
            f'A configuration with any diverged seed is unstable and never recommended. Table'
            f' contact cannot be '
            f'switched off: neither engine exposes it.'
        ),
    ]
    for e in engines_of(settings):
        chosen = [x['recommended'] for x in found if x['engine'] == e]
        sel = [r for r in settings if r['engine'] == e]
        title = f'{engine_label(e)}: configurations, CD against compute (stable ones)'
        blocks.append(
            figure_block(
                f'settings_{e}.png',
                f'{engine_label(e)}: speed against error per configuration, Pareto front dashed, '
                'recommended starred (ours)',
                partial(_plot_settings, sel, title, chosen),
            )
        )
    blocks += [
        paragraph(
            'Within one configuration, settings that do not change the result (equal CD) can still'
            ' differ in measured step time by run-to-run timing noise of the machine; compare step'
            ' times that differ by less than about 20 % with care.'
        ),
        heading(3, 'Recommendations'),
    ]
    blocks += [paragraph(n) for n in notes]
    for t in s_tables:
        blocks += [heading(3, t.name.replace('settings_', '').replace('_', ' ')), table_block(t)]

    d_tables, d_notes = deadline_tables(rows, tol_rel, tol_abs)
    blocks += [
        heading(3, 'Fast enough for the rate: step p99 under the period (hardware in the loop)')
    ]
    blocks += [paragraph(n) for n in d_notes] + [table_block(t) for t in d_tables]
    return blocks


def cross_reference_blocks(
    rows: Sequence[dict],
    rankings: dict[tuple[str, str], Ranking],
    metric: str = DEFAULT_METRIC,
) -> list[Block]:
    """Each engine against each synthetic reference, and the given ranking of identified ones."""
    xref = cross_reference_section(rows, metric)
    if xref is None:
        return []
    blocks = [heading(2, xref[0]), paragraph(xref[1]), table_block(xref[2])]
    if rankings:
        blocks += [
            heading(3, 'Ranking of the identified engines, with bootstrap intervals'),
            paragraph(
                'Each engine with the parameters identified against the reference it is scored'
                ' on, over held-out seeds (the identification ran on seed 0), ranked by the share'
                f' of its seeds that diverged, then by the mean {metric_choice(metric).label}.'
                f' 95 % interval from {REPLICATES} paired bootstrap replicates of the seeds (a'
                ' reference bag is one trial; every engine takes the same draw); P(rank): the'
                ' share of replicates in which the engine holds its rank; two engines are told'
                ' apart when the 95 % interval of their paired difference excludes 0. '
                + ' '.join(s[0].upper() + s[1:] + '.' for s in ranking_statements(rankings))
            ),
            table_block(ranking_table('ranking', rankings)),
        ]
    return blocks


def stress_section(stress_rows: Sequence[dict]) -> list[Block]:
    """Return the stress suite: which hard cases each engine survives."""
    v = verdict(stress_rows)
    return [
        heading(2, 'Stress suite: hard cases'),
        paragraph(
            '; '.join(
                f'{engine_label(e)}: {len(c)} of {sum(r["engine"] == e for r in stress_rows)} '
                f'cases diverged ({", ".join(c) or "none"})'
                for e, c in v.items()
            )
            + '.'
        ),
        table_block(stress_table(stress_rows)),
    ]


def identifications_summary(identifications: Sequence[dict]) -> list[Block]:
    """Return one table of every identification's budget, wall time and held-out CD."""
    return [
        heading(2, 'Identifications: budgets and held-out scores'),
        paragraph(
            'Each sampler ran 32 trials, then doubled while a doubling improved its best by'
            ' 2 % or more (`--trials auto`; a fixed count otherwise); held-out: seeds other'
            ' than the fitted one, mean ± std.'
        ),
        table_block(summary_table(identifications)),
    ]
