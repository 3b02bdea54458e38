"""
The report's figures over time: per-frame CD and HD of each run, and the latency distribution.

Drawn with figures.py's matplotlib set-up (Agg backend: no display).
"""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Sequence

from cloth_bench_ros.engines import engine_label
from cloth_bench_ros.report.figures import plain_log, plt, save_figure
from cloth_bench_ros.report.selections import ENGINE_COLOR, engines_of, FPS
from cloth_bench_ros.safe_io import confined_path, UnsafeInputError
from cloth_bench_ros.sweep.aggregate import finite, group
import numpy as np


def frames_file(results_dir: Path, row: dict) -> Path | None:
    """Return the row's frames.csv if it is a file inside results_dir (rows are untrusted)."""
    name = row.get('frames_csv')
    if not isinstance(name, str) or not name:
        return None
    try:
        path = confined_path(results_dir, name)
    except UnsafeInputError:
        return None
    return path if path.is_file() else None


def _read_frames(path: Path) -> dict[str, np.ndarray]:
    with path.open() as f:
        rows = list(csv.DictReader(f))
    return {
        k: np.array([float(r[k]) if r[k] not in ('', 'nan') else np.nan for r in rows])
        for k in ('t', 'cd', 'hd')
    }


def plot_frames(rows: Sequence[dict], results_dir: Path, cloth: str, path: Path) -> Path | None:
    """
    Plot per-frame CD and HD over time for each task, engine and rate.

    The first seed and trial, with the change of phase of the dynamic trial marked.
    """
    sel = [r for r in rows if r['cloth'] == cloth and r.get('frames_csv')]
    prims = [p for p in ('dynamic', 'quasi_static') if any(r['primitive'] == p for r in sel)]
    if not prims:
        return None
    fig, axes = plt.subplots(len(prims), 2, figsize=(12, 3.8 * len(prims)), squeeze=False)
    styles = ['-', '--', ':', '-.']
    for row_axes, prim in zip(axes, prims):
        g = [r for r in sel if r['primitive'] == prim]
        first: dict = {}
        for r in sorted(g, key=lambda r: (r.get('trial', 0), r['seed'])):
            first.setdefault((r['engine'], float(r['rate_hz'])), r)
        rates = sorted({k[1] for k in first})
        cut = next(
            (
                r.get('change_of_phase_frame')
                for r in g
                if r.get('change_of_phase_frame') is not None
            ),
            None,
        )
        for ax, kind in zip(row_axes, ('cd', 'hd')):
            for (e, rate), r in sorted(
                first.items(), key=lambda x: (engines_of(g).index(x[0][0]), x[0][1])
            ):
                f = frames_file(results_dir, r)
                if f is None:
                    continue
                data = _read_frames(f)
                ax.plot(
                    data['t'],
                    data[kind],
                    color=ENGINE_COLOR.get(e),
                    ls=styles[rates.index(rate) % 4],
                    lw=1.2,
                    label=f'{engine_label(e)} {rate:g} Hz'
                    + (' (diverged)' if r.get('diverged') else ''),
                )
            if prim == 'dynamic' and cut is not None:
                ax.axvline(cut / FPS, color='red', lw=1, ls='--')
                ax.annotate(
                    f'change of phase (frame {cut}) ',
                    (cut / FPS, 0.03),
                    xycoords=('data', 'axes fraction'),
                    color='red',
                    fontsize=8,
                    ha='right',
                    va='bottom',
                    rotation=90,
                )
            ax.set_xlabel('time since the start of the quintic part (s)')
            ax.set_ylabel(f'{kind.upper()} (m)')
            ax.set_title(
                f'{cloth} {prim}: per-frame {kind.upper()} (seed'
                f' {min(r["seed"] for r in first.values())})'
            )
            ax.grid(True, alpha=0.3)
            if ax.get_legend_handles_labels()[0]:
                ax.legend(fontsize=7)
    return save_figure(fig, path)


def plot_latency(rows: Sequence[dict], path: Path) -> Path | None:
    """Latency p50 / p99 / max per engine and rate (realtime-paced runs if any, else all)."""
    rt = [
        r for r in rows if r.get('pacing') == 'realtime' and r.get('status') in ('ok', 'diverged')
    ]
    sel = rt or [r for r in rows if r.get('status') == 'ok']
    groups = group(
        [r for r in sel if r.get('latency_p50') is not None], 'engine', 'rate_hz', 'pacing'
    )
    if not groups:
        return None
    fig, ax = plt.subplots(figsize=(max(6, 1.3 * len(groups) + 2), 4.5))
    keys = sorted(groups, key=lambda k: (k[2], engines_of(sel).index(k[0]), k[1]))
    x = np.arange(len(keys))
    for i, (q, marker) in enumerate(
        (('latency_p50', 'o'), ('latency_p99', 's'), ('latency_max', '^'))
    ):
        vals = [
            (
                np.median(finite(r.get(q) for r in groups[k])) * 1e3
                if len(finite(r.get(q) for r in groups[k]))
                else np.nan
            )
            for k in keys
        ]
        ax.scatter(x + (i - 1) * 0.15, vals, marker=marker, label=q.split('_')[1], zorder=3)
    for j, k in enumerate(keys):
        ax.plot([j - 0.35, j + 0.35], [1e3 / k[1]] * 2, color='red', lw=1.5)
    ax.plot([], [], color='red', label='deadline = 1 / rate')
    ax.set_xticks(x, [f'{engine_label(k[0])}\n{k[1]:g} Hz\n{k[2]}' for k in keys], fontsize=8)
    ax.set_yscale('log')
    plain_log(ax)
    ax.set_ylabel('latency, target due -> state received (ms)')
    ax.grid(True, which='both', axis='y', alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title('per-step latency against the deadline')
    return save_figure(fig, path)
