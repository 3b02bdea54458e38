"""
Hardware in the loop: the configuration chosen per rate and the report of real-time runs.

- `deadline_tables`: the deadline rule (core/deadline.py) for every configuration of a settings
  sweep.
- `write_hil_report`: per engine, rate and configuration the latency p50 / p99 / p99.9 / max,
  deadline misses, skipped targets, real-time factor, CPU load and the CD in lockstep; a plot of
  latency over the run and a histogram per run.
"""

from __future__ import annotations

from functools import partial
import math
from pathlib import Path
from typing import Sequence

from cloth_bench_ros.core.deadline import deadline_rule, within_tolerance
from cloth_bench_ros.core.hil_timing import latencies, TargetTimeline, UNSET
from cloth_bench_ros.engines import engine_label
from cloth_bench_ros.report.blocks import (
    Document,
    figure_block,
    paragraph,
    Table,
    table_block,
    write_document,
)
from cloth_bench_ros.report.figures import plt
from cloth_bench_ros.report.selections import fmt_fixed as _fmt
from cloth_bench_ros.report.selections import metric_name
from cloth_bench_ros.sweep.recommend import (
    DEADLINE_BUDGET,
    meets_deadline,
    recommend_for_rate,
    settings_results,
    step_ms_by_config,
)
import numpy as np


def deadline_tables(
    rows: Sequence[dict],
    tol_rel: float = 0.05,
    tol_abs: float = 0.002,
    budget: float = DEADLINE_BUDGET,
) -> tuple[list[Table], list[str]]:
    """Per engine, task and rate of a settings sweep: every configuration against the deadline."""
    settings = [r for r in rows if r.get('mode') == 'settings']
    keys = sorted(
        {(r['engine'], r['cloth'], r['primitive'], float(r['rate_hz'])) for r in settings}
    )
    tables: list[Table] = []
    notes = [f'{deadline_rule(budget)}; within tolerance: CD <= best + max({tol_rel:g} x best,'
             f' {tol_abs * 1e3:g} mm).'] if keys else []
    for engine, cloth, primitive, rate in keys:
        sel = [
            r
            for r in settings
            if (r['engine'], r['cloth'], r['primitive'], float(r['rate_hz']))
            == (engine, cloth, primitive, rate)
        ]
        rec = recommend_for_rate(sel, engine, cloth, primitive, rate, tol_rel, tol_abs, budget)
        p50, p99 = step_ms_by_config(sel, 'step_time_p50'), step_ms_by_config(sel, 'step_time_p99')
        period_ms = 1e3 / rate
        out = []
        for r in sorted(settings_results(sel), key=lambda r: p99.get(r.config, math.inf)):
            within = (
                rec is not None
                and r.stable
                and within_tolerance(r.cd.mean, rec.best_cd, rec.tolerance_m)
            )
            fast = meets_deadline(p99.get(r.config, math.nan), rate, budget)
            flag = '**recommended**' if rec is not None and r.config == rec.config else ''
            out.append(
                [
                    r.config,
                    _fmt(p50.get(r.config), 3),
                    _fmt(p99.get(r.config), 3),
                    'yes' if fast else 'no',
                    r.cd.text(4, False),
                    'yes' if within else 'no',
                    flag,
                ]
            )
        tables.append(
            Table(
                f'deadline_{engine}_{cloth}_{primitive}_{rate:g}hz',
                [
                    'configuration',
                    'step p50 ms',
                    'step p99 ms',
                    f'p99 < {budget * period_ms:g} ms',
                    metric_name(primitive, 'CD') + ' (m)',
                    'within tolerance',
                    'notes',
                ],
                out,
                'lrrlrll',
            )
        )
        if rec is None:
            notes.append(
                f'{engine_label(engine)}, {cloth} {primitive} at {rate:g} Hz: no stable'
                ' configuration.'
            )
        elif rec.meets_deadline:
            notes.append(
                f'{engine_label(engine)}, {cloth} {primitive} at {rate:g} Hz: **`{rec.config}`**'
                f' is the cheapest configuration both within tolerance (CD {rec.cd:.4f} m, best'
                f' {rec.best_cd:.4f} m) and with step p99 {rec.step_p99_ms:.3f} ms under'
                f' {budget * period_ms:g} ms.'
            )
        else:
            notes.append(
                f'{engine_label(engine)}, {cloth} {primitive} at {rate:g} Hz: no configuration'
                f' within tolerance has a step p99 under {budget * period_ms:g} ms; the cheapest'
                f' within tolerance is `{rec.config}` (step p99 {rec.step_p99_ms:.3f} ms).'
            )
    return tables, notes


# ---------------------------------------------------------------------------- the report


def _ms(value) -> str:
    return _fmt(value, 3, 1e3)


def hil_table(rows: Sequence[dict]) -> Table:
    """Item 4 per run: latency percentiles, misses, skipped targets, RTF, load, CD in lockstep."""
    out = []
    for r in rows:
        n = max(int(r.get('states') or 0), 1)
        out.append(
            [
                engine_label(r['engine']),
                f'{r["rate_hz"]:g}',
                r['config'],
                '3 processes' if r.get('processes') else '1 process',
                _ms(r['latency_p50']),
                _ms(r['latency_p99']),
                _ms(r['latency_p999']),
                _ms(r['latency_max']),
                f'{r["deadline_misses"]} ({100 * r["deadline_misses"] / n:.2f} %)',
                f'{r["skipped"]} of {r["sent"]}',
                _ms(r.get('send_lag_p99')),
                _fmt(r['real_time_factor'], 3),
                _ms(r.get('step_time_p99')),
                _percent(r.get('cpu_busy')),
                _percent(r.get('cpu_steal')),
                f'{r.get("loadavg_after", math.nan):.2f} / {r.get("cpu_count") or "?"}',
                _fmt(r.get('cd_lockstep'), 4),
                _fmt(r.get('cd_realtime'), 4),
                'ok' if not r.get('problems') else '; '.join(r['problems']),
            ]
        )
    return Table(
        'hil',
        [
            'engine',
            'rate Hz',
            'configuration',
            'layout',
            'lat p50 ms',
            'lat p99 ms',
            'lat p99.9 ms',
            'lat max ms',
            'deadline misses',
            'skipped targets',
            'send lag p99 ms',
            'RTF',
            'step p99 ms',
            'CPU busy',
            'CPU steal',
            'load / cores',
            'CD lockstep (m)',
            'CD realtime (m)',
            'bookkeeping',
        ],
        out,
        'lrllrrrrrrrrrrrrrrl',
    )


def _percent(share: float | None) -> str:
    return f'{100 * share:.1f} %' if isinstance(share, float) and math.isfinite(share) else '-'


def text_table(table: Table) -> str:
    """Return a table as fixed-width text for the terminal (numbers right-aligned)."""
    cells = [table.headers] + [[str(c).replace('**', '') for c in row] for row in table.rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(table.headers))]
    align = table.align or 'l' * len(widths)
    lines = [
        '  '.join(
            c.rjust(w) if a == 'r' else c.ljust(w) for c, w, a in zip(row, widths, align)
        ).rstrip()
        for row in cells
    ]
    return '\n'.join([lines[0], '-' * len(lines[0])] + lines[1:])


def plot_run(timeline, period_s: float, path: Path, title: str) -> Path:
    """Plot latency over the run and its histogram, the deadline in red, skipped targets marked."""
    got = timeline.received != UNSET
    t = (timeline.stamps - timeline.stamps[0]) / 1e9
    lat_ms = latencies(timeline) * 1e3
    fig, (ax, hist) = plt.subplots(1, 2, figsize=(12, 4), gridspec_kw={'width_ratios': [2.2, 1]})
    ax.plot(t[got], lat_ms, lw=0.6, color='tab:blue', label='latency (due -> state received)')
    missing = ~got & (timeline.sent != UNSET)
    if missing.any():
        ax.scatter(
            t[missing],
            np.full(int(missing.sum()), period_s * 1e3),
            marker='|',
            color='tab:orange',
            label='skipped target',
            zorder=3,
        )
    ax.axhline(period_s * 1e3, color='red', lw=1, label='deadline = 1 / rate')
    ax.set_xlabel('time in the run (s)')
    ax.set_ylabel('latency (ms)')
    if lat_ms.size and np.nanmax(lat_ms) > 20 * period_s * 1e3:
        ax.set_yscale('log')
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc='upper left')
    if lat_ms.size:
        hist.hist(lat_ms, bins=80, color='tab:blue', log=True)
    hist.axvline(period_s * 1e3, color='red', lw=1)
    hist.set_xlabel('latency (ms)')
    hist.set_ylabel('targets')
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _draw_run(timeline, period_s: float, title: str, path: Path) -> Path:
    """Draw one run's latency figure into `path` (a figure block's draw function)."""
    return plot_run(timeline, period_s, path, title) or path


def write_hil_report(rows: Sequence[dict], results_dir: Path, out_dir: Path) -> Path:
    """hil.md and hil.html (table + per-run plots) and hil.csv in out_dir; the Markdown's path."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    doc = Document('cloth_bench_ros: hardware in the loop')
    doc.extend(
        [
            paragraph(
                "Latency: from the target's due time on the controller's wall-clock schedule"
                " (first target + k / rate) to the state's arrival back at the controller (the"
                ' trajectory publisher), so a late send and a simulator that falls behind both'
                ' count. A miss is a state later than one period; a skipped target is one the'
                ' simulator never stepped because a newer one was waiting (keep-last), counted'
                ' beside the misses. RTF: simulated over wall time. CPU busy: share of all cores'
                ' busy during the run (/proc/stat), any process; CPU steal: share the hypervisor'
                ' of a virtual machine ran something else on our cores (the vCPU was runnable but'
                ' stopped; no setting inside the machine prevents it); load: 1-minute load average'
                ' at the end. CD lockstep: the same configuration run in lockstep.'
            )
        ]
    )
    table = hil_table(rows)
    doc.extend([table_block(table)])
    for r in rows:
        run_dir = Path(results_dir) / (r.get('run_dir') or '')
        csv = run_dir / f'timeline_{r["engine"]}.csv'
        if r.get('run_dir') and csv.is_file():
            title = f'{engine_label(r["engine"])} at {r["rate_hz"]:g} Hz, {r["config"]}'
            timeline = TargetTimeline.from_csv(csv.read_text())
            draw = partial(_draw_run, timeline, 1.0 / r['rate_hz'], title)
            doc.extend(
                [
                    figure_block(
                        f'latency_{r["run_dir"]}.png',
                        f'{engine_label(r["engine"])} {r["rate_hz"]:g} Hz '
                        f'{r["config"]}: latency over the run and its histogram',
                        draw,
                    )
                ]
            )
    md, _, _ = write_document(doc, out_dir, names=('hil.md', 'hil.html'))
    return md
