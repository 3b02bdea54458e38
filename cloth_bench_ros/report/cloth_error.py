"""
The report's error-on-the-cloth view: where on the cloth each engine departs from the real one.

Each run keeps its engines' worst frames (the largest CD in the scoring window) in
worst_frames.npz beside summary.json (core/worst_frames.py); this section draws them, nothing
is run: the real cloud in grey and the scored vertices coloured by their own term of CD (each
vertex's L1 distance to the nearest real point), seen from the side (y-z) and from above (x-y).
"""

from __future__ import annotations

from functools import partial
from pathlib import Path

from cloth_bench_ros.core.worst_frames import read_worst_frames, WORST_FRAMES_FILE, WorstFrame
from cloth_bench_ros.report.blocks import figure_block, heading, paragraph
from cloth_bench_ros.report.figures import plt
import numpy as np

MAX_FIGURES = 6  # run directories drawn; the rest are counted in the section's text
VIEWS = (('side (y-z)', 1, 2), ('top (x-y)', 0, 1))


def find_worst_frames(results_dir: Path) -> list[Path]:
    """Return the worst_frames.npz of results_dir, its run directories and a sweep's frames/*/."""
    patterns = (WORST_FRAMES_FILE, f'*/{WORST_FRAMES_FILE}', f'frames/*/{WORST_FRAMES_FILE}')
    found = {p for pattern in patterns for p in Path(results_dir).glob(pattern)}
    return sorted(p for p in found if p.is_file() and not p.is_symlink())


def plot_worst_frames(frames: list[WorstFrame], path: Path) -> Path:
    """Draw each engine's worst frame: a row per engine, a column per view; the path."""
    top = max(float(np.max(f.errors)) for f in frames) or 1.0
    fig, axes = plt.subplots(
        len(frames), len(VIEWS), figsize=(3.4 * len(VIEWS) + 0.8, 3.0 * len(frames)),
        squeeze=False,
    )
    points = None
    for row, f in enumerate(frames):
        for col, (view, a, b) in enumerate(VIEWS):
            ax = axes[row][col]
            ax.scatter(f.real[:, a], f.real[:, b], s=0.4, c='0.6', linewidths=0)
            points = ax.scatter(
                f.vertices[:, a], f.vertices[:, b], s=14, c=f.errors, cmap='turbo', vmin=0.0,
                vmax=top, linewidths=0,
            )
            ax.set_aspect('equal')
            ax.set_xticks([])
            ax.set_yticks([])
            ax.set_title(
                f'{f.engine}, frame {f.frame} (t={f.t:.2f} s), {view}\n'
                f'CD {f.cd:.4f} m, HD {f.hd:.4f} m',
                fontsize=7,
            )
    assert points is not None  # at least one frame was drawn
    fig.colorbar(points, ax=axes, shrink=0.8, label='vertex error: L1 distance to real (m)')
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def cloth_error_section(results_dir: Path) -> list:
    """Report blocks: the worst frame of each engine of each run found (see module doc)."""
    files = find_worst_frames(results_dir)
    if not files:
        return []
    drawn = files[:MAX_FIGURES]
    blocks = [
        heading(2, 'Error on the cloth: the worst frame of each engine'),
        paragraph(
            "The real cloud in grey; the simulated vertices at the real frame's time coloured"
            " by their own term of CD (each vertex's L1 distance to the nearest real point: CD"
            ' is their mean, HD their maximum), at the frame of the largest CD of each engine in'
            ' its scoring window.'
            + (
                f' {len(drawn)} of {len(files)} runs drawn.'
                if len(files) > len(drawn)
                else ''
            )
        ),
    ]
    for path in drawn:
        run = path.parent.name
        frames = read_worst_frames(path)
        if frames:
            blocks.append(
                figure_block(
                    f'cloth_error_{run}.png',
                    f'{run}: the worst frame of each engine, error on the cloth',
                    partial(_draw, frames),
                )
            )
    return blocks


def _draw(frames: list[WorstFrame], path: Path) -> Path:
    return plot_worst_frames(frames, path)
