"""
The report's figures (matplotlib, Agg backend: no display).

Fig. 5 layout, speed against error, settings (per-frame scores and latency: time_figures.py).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Sequence

from cloth_bench_ros.engines import engine_label
from cloth_bench_ros.report.selections import (
    ENGINE_COLOR,
    engines_of,
    metric_name,
    rates_of,
)
from cloth_bench_ros.sweep.aggregate import (
    compute_per_sim_second,
    finite,
    group,
    pareto_front,
    stat,
)
from cloth_bench_ros.validation import parse_grid
import matplotlib

matplotlib.use('Agg')  # no display: figures are files
from matplotlib.lines import Line2D  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.ticker import FixedLocator, FuncFormatter, NullFormatter  # noqa: E402


def plain_log(ax, axis: str = 'xy') -> None:
    """Log-axis tick labels as plain numbers (0.2, 10, 1000) rather than 2 x 10^-1."""
    fmt = FuncFormatter(lambda v, _: f'{v:g}')
    for name in axis:
        a = ax.xaxis if name == 'x' else ax.yaxis
        if a.get_scale() != 'log':
            continue
        low, high = sorted(ax.get_xlim() if name == 'x' else ax.get_ylim())
        a.set_major_formatter(fmt)
        # Less than about a decade shown: label the minor ticks too, or the axis has no numbers.
        few = low > 0 and high / low < 20
        a.set_minor_formatter(
            FuncFormatter(lambda v, _: f'{v:.3g}') if few else FuncFormatter(lambda v, _: '')
        )


def save_figure(fig, path: Path) -> Path:
    """tight_layout, save as PNG, close; the path."""
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_fig5(rows: Sequence[dict], cloth: str, path: Path, title: str) -> Path:
    """
    Plot step time, L_s, CD_d and CD_q against rate per engine (log-log), mean +- std.

    Rates at which some runs diverged are marked with an open marker and their count.
    """
    sel = [r for r in rows if r['cloth'] == cloth]
    fig, axes = plt.subplots(2, 2, figsize=(10, 7.5))
    panels = [
        ('step_time_mean', None, 1e3, 'step time (ms)'),
        ('L_s', None, 1.0, 'L_s (m)'),
        ('CD', 'dynamic', 1.0, 'CD_d (m)'),
        ('CD', 'quasi_static', 1.0, 'CD_q (m)'),
    ]
    for ax, (key, prim, scale, label) in zip(axes.ravel(), panels):
        for e in engines_of(sel):
            xs: list[float] = []
            ys: list[float] = []
            es: list[float] = []
            div: list[tuple[float, float | None, str]] = []
            for rate in rates_of(sel):
                g = [
                    r
                    for r in sel
                    if r['engine'] == e
                    and float(r['rate_hz']) == rate
                    and (prim is None or r['primitive'] == prim)
                ]
                if not g:
                    continue
                s = stat(g, key)
                if s.used:
                    xs.append(rate)
                    ys.append(s.mean * scale)
                    es.append(s.std * scale)
                    if s.diverged:
                        div.append((rate, s.mean * scale, f'{s.diverged}/{s.n} div.'))
                elif s.diverged:
                    div.append((rate, None, f'all {s.n} div.'))
            color = ENGINE_COLOR.get(e)
            if xs:
                ax.errorbar(
                    xs, ys, yerr=es, marker='o', capsize=3, color=color, label=engine_label(e)
                )
            for rate, y, text in div:
                if y is None:
                    ax.annotate(
                        f'{engine_label(e)}: {text}',
                        (rate, 0.02),
                        xycoords=('data', 'axes fraction'),
                        color=color,
                        fontsize=8,
                        rotation=90,
                        va='bottom',
                    )
                else:
                    ax.plot([rate], [y], marker='o', mfc='white', ms=11, color=color)
                    ax.annotate(
                        text,
                        (rate, y),
                        textcoords='offset points',
                        xytext=(6, 6),
                        color=color,
                        fontsize=8,
                    )
        ax.set_xscale('log')
        if ax.has_data():
            ax.set_yscale('log')
        plain_log(ax)
        ax.xaxis.set_major_locator(FixedLocator(rates_of(sel)))
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xlabel('simulator rate (Hz)')
        ax.set_ylabel(label)
        ax.grid(True, which='both', alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
    fig.suptitle(title, fontsize=11)
    return save_figure(fig, path)


def speed_error_points(rows: Sequence[dict], label_key: str = 'rate') -> tuple[list, list]:
    """((compute s/s, mean CD) per engine x rate x config, (engine, label, CD std) of each)."""
    pts, labels = [], []
    for (e, rate, config), g in sorted(
        group(rows, 'engine', 'rate_hz', 'config').items(), key=lambda x: str(x[0])
    ):
        cd = stat(g, 'CD')
        cost = finite(compute_per_sim_second(r) for r in g if r.get('status') == 'ok')
        if not cd.used or not len(cost):
            continue
        pts.append((float(cost.mean()), cd.mean))
        text = f'{rate:g} Hz' if label_key == 'rate' else config
        if label_key == 'rate' and config != 'preset':
            text += f' {config}'
        labels.append((e, text, cd.std))
    return pts, labels


def speed_error_front(rows: Sequence[dict]) -> list[dict]:
    """Return the Pareto front (minimal compute and CD) of each task, as rows for a table."""
    fronts = []
    for prim in ('dynamic', 'quasi_static'):
        pts, labels = speed_error_points([r for r in rows if r['primitive'] == prim])
        fronts += [
            {
                'task': prim,
                'engine': labels[i][0],
                'point': labels[i][1],
                'compute_s_per_s': pts[i][0],
                'CD': pts[i][1],
            }
            for i in pareto_front(pts)
        ]
    return fronts


def plot_speed_error(
    rows: Sequence[dict], path: Path, title: str, label_key: str = 'rate'
) -> tuple[Path, list]:
    """
    Plot CD against compute per simulated second, with the Pareto front per task.

    One point per engine x rate (x config); the front is minimal compute and CD. Returns the path
    and the front points.
    """
    fig, axes = plt.subplots(1, 2, figsize=(12, 5))
    fronts = []
    for ax, prim in zip(axes, ('dynamic', 'quasi_static')):
        sel = [r for r in rows if r['primitive'] == prim]
        pts, labels = speed_error_points(sel, label_key)
        colors = [ENGINE_COLOR.get(e, 'gray') for e, _, _ in labels]
        for (x, y), (e, text, sd), c in zip(pts, labels, colors):
            ax.errorbar([x], [y], yerr=[sd], marker='o', color=c, capsize=2, ms=5)
            ax.annotate(
                text, (x, y), textcoords='offset points', xytext=(4, 4), fontsize=7, color=c
            )
        front = pareto_front(pts)
        if front:
            fx = [pts[i][0] for i in front]
            fy = [pts[i][1] for i in front]
            ax.step(fx, fy, where='post', color='black', lw=1.2, ls='--', label='Pareto front')
            ax.scatter(fx, fy, s=120, facecolors='none', edgecolors='black', zorder=3)
            fronts += [
                {
                    'task': prim,
                    'engine': labels[i][0],
                    'point': labels[i][1],
                    'compute_s_per_s': pts[i][0],
                    'CD': pts[i][1],
                }
                for i in front
            ]
        for e in engines_of(sel):
            ax.plot(
                [], [], marker='o', color=ENGINE_COLOR.get(e, 'gray'), ls='', label=engine_label(e)
            )
        ax.axvline(1.0, color='gray', lw=0.8, ls=':')
        ax.set_xscale('log')
        plain_log(ax)
        ax.set_xlabel(
            'engine compute per simulated second (s/s); left of 1 = faster than real time'
        )
        ax.set_ylabel(f'{metric_name(prim, "CD")} (m)')
        ax.set_title(prim)
        ax.grid(True, which='both', alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
        else:
            ax.text(
                0.5, 0.5, 'no runs of this task', transform=ax.transAxes, ha='center', color='gray'
            )
    fig.suptitle(title, fontsize=11)
    return save_figure(fig, path), fronts


_SHORT = {
    'grid': '',
    'self_collision': 'sc:',
    'timestep': 'dt:',
    'solver_iterations': 'it:',
    'substeps': 'sub:',
}


def short_config(label: str) -> str:
    """Short label: "grid=11x15,self_collision=off,timestep=0.005" -> "11x15 sc:off dt:0.005"."""
    parts = []
    for item in label.split(','):
        name, _, value = item.partition('=')
        parts.append(f'{_SHORT.get(name, name + ":")}{value}' if value else item)
    return ' '.join(parts)


def plot_settings(
    rows: Sequence[dict], path: Path, title: str, recommended: Sequence[str] = ()
) -> Path:
    """
    Plot one engine's settings sweep: CD against compute per configuration and task.

    Colour: mesh; marker: internal time step; open marker: self-collision on; the Pareto front
    dashed and labelled; the recommended configuration starred.
    """
    prims = [p for p in ('dynamic', 'quasi_static') if any(r['primitive'] == p for r in rows)]
    fig, axes = plt.subplots(1, len(prims), figsize=(7.5 * len(prims), 5.5), squeeze=False)
    grids = sorted(
        {r.get('grid') or 'default' for r in rows},
        key=lambda g: 0 if g == 'default' else math.prod(parse_grid(g)),
    )
    steps = sorted({str(r.get('params', {}).get('timestep', 'preset')) for r in rows})
    cmap = plt.get_cmap('viridis', max(2, len(grids)))
    markers = ['o', 's', '^', 'D', 'v', 'P', 'X']
    for ax, prim in zip(axes[0], prims):
        pts, labels = [], []
        for config, g in sorted(
            group([r for r in rows if r['primitive'] == prim], 'config').items(), key=str
        ):
            cd = stat(g, 'CD')
            cost = finite(compute_per_sim_second(r) for r in g if r.get('status') == 'ok')
            if not cd.used or not len(cost) or cd.used < cd.n:
                continue  # unstable configurations are in the table, not on the plot
            r0 = g[0]
            color = cmap(grids.index(r0.get('grid') or 'default'))
            marker = markers[
                steps.index(str(r0.get('params', {}).get('timestep', 'preset'))) % len(markers)
            ]
            hollow = bool(r0.get('params', {}).get('self_collision'))
            x, y = float(cost.mean()), cd.mean
            ax.errorbar(
                [x],
                [y],
                yerr=[cd.std],
                color=color,
                marker=marker,
                ms=7,
                capsize=2,
                ls='',
                mfc='white' if hollow else color,
            )
            if config[0] in recommended:
                ax.scatter(
                    [x], [y], marker='*', s=260, facecolors='none', edgecolors='red', zorder=4
                )
            pts.append((x, y))
            labels.append(config[0])
        front = pareto_front(pts)
        if front:
            ax.step(
                [pts[i][0] for i in front],
                [pts[i][1] for i in front],
                where='post',
                color='black',
                lw=1,
                ls='--',
            )
            for n, i in enumerate(front):
                ax.annotate(
                    short_config(labels[i]),
                    pts[i],
                    textcoords='offset points',
                    xytext=(6, 8 if n % 2 == 0 else -12),
                    fontsize=7,
                )
        ax.set_xscale('log')
        plain_log(ax)
        ax.set_xlabel('engine compute per simulated second (s/s)')
        ax.set_ylabel(f'{metric_name(prim, "CD")} (m)')
        ax.set_title(prim)
        ax.grid(True, which='both', alpha=0.3)
        handles = [
            Line2D([], [], color=cmap(i), marker='o', ls='', label=f'mesh {g}')
            for i, g in enumerate(grids)
        ]
        handles += [
            Line2D([], [], color='gray', marker=markers[i % len(markers)], ls='', label=f'dt {t}')
            for i, t in enumerate(steps)
        ]
        handles += [
            Line2D(
                [], [], color='gray', marker='o', mfc='white', ls='', label='self-collision on'
            ),
            Line2D([], [], color='black', ls='--', label='Pareto front'),
            Line2D([], [], color='red', marker='*', mfc='none', ls='', ms=12, label='recommended'),
        ]
        ax.legend(handles=handles, fontsize=7, loc='best')
    fig.suptitle(title, fontsize=11)
    return save_figure(fig, path)
