"""
The evaluator's comparison outputs: comparison bag, qualitative figure, animation.

Input is what the evaluator kept of each scored real frame: its `FrameScore`, the real points and
the engine's vertices at that time. The figure puts the mesh (red) over the real cloud (black) at
the time steps of the paper's Fig. 4, CD/HD under each panel, one row per engine; the animation
shows the same over the whole trial (GIF; MP4 when ffmpeg exists). The bag is
live/comparison_bag.py's.
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path
import shutil
from typing import Any

from cloth_bench_ros.core.run_summary import inputs_line
from cloth_bench_ros.core.trajectory import TaskLike
from cloth_bench_ros.live.comparison_bag import cloth_triangles, write_comparison_bag
import numpy as np

# The paper's Fig. 4: time steps (s from the start of the motion) of each primitive.
FIG4_TIMES = {'dynamic': (0.5, 1.5, 2.5, 3.5), 'quasi_static': (1.0, 4.0, 8.0, 14.0)}
ANIMATION_FRAMES = 60  # at most; frames are spread evenly over the trial


def _by_engine(pairs: list) -> dict[str, list]:
    out: dict[str, list] = defaultdict(list)
    for p in pairs:
        out[p[0].engine].append(p)
    return dict(out)


def _draw(ax: Any, real: np.ndarray, vertices: np.ndarray, faces: np.ndarray | None) -> None:
    """Side view (y right, z up), where the fling shows: cloud black, mesh red."""
    ax.scatter(real[:, 1], real[:, 2], s=0.5, c='black', linewidths=0)
    faces = cloth_triangles(vertices, faces)
    ax.triplot(vertices[:, 1], vertices[:, 2], faces, color='red', linewidth=0.4)
    ax.set_aspect('equal')
    ax.set_xticks([])
    ax.set_yticks([])


def _pyplot() -> Any:
    """Return matplotlib's pyplot on the Agg backend (no display: figures are files)."""
    import matplotlib  # lazy: +0.5 s at the evaluator's start, not in .venv-ros

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt  # lazy: as matplotlib, --figures only

    return plt


def qualitative_figure(
    pairs: list, primitive: str, path: Path, faces: np.ndarray | None = None, title: str = ''
) -> tuple[int, int]:
    """Return the paper's Fig. 4 for this run: (rows, columns) drawn = (engines, time steps)."""
    plt = _pyplot()
    engines = _by_engine(pairs)
    times = FIG4_TIMES[primitive]
    fig, axes = plt.subplots(
        len(engines), len(times), figsize=(2.2 * len(times), 2.6 * len(engines)), squeeze=False
    )
    for row, (engine, rows) in enumerate(engines.items()):
        for col, t in enumerate(times):
            ax = axes[row][col]
            score, real, vertices = min(rows, key=lambda p: abs(p[0].t - t))[:3]
            _draw(ax, real, vertices, faces)
            ax.set_xlabel(f't={score.t:.1f} s\nCD {score.cd:.3f}  HD {score.hd:.3f}', fontsize=7)
            if col == 0:
                ax.set_ylabel(engine)
    fig.suptitle('simulated mesh (red) over the real cloud (black), side view (y-z)'
                 + (f'\n{title}' if title else ''), fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return len(engines), len(times)


def animation(pairs: list, path: Path, faces: np.ndarray | None = None) -> tuple[Path, int]:
    """Animate sim against real over the trial, a panel per engine: MP4 with ffmpeg, else GIF."""
    plt = _pyplot()
    from matplotlib.animation import FFMpegWriter, FuncAnimation, PillowWriter  # lazy: matplotlib

    engines = _by_engine(pairs)
    count = min(len(rows) for rows in engines.values())
    picks = np.unique(np.linspace(0, count - 1, min(count, ANIMATION_FRAMES)).round().astype(int))
    fig, axes = plt.subplots(1, len(engines), figsize=(3 * len(engines), 3), squeeze=False)

    def update(i: int) -> None:
        for ax, (engine, rows) in zip(axes[0], engines.items()):
            ax.clear()
            score, real, vertices = rows[picks[i]][:3]
            _draw(ax, real, vertices, faces)
            ax.set_title(f'{engine} t={score.t:.2f} s CD {score.cd:.3f}', fontsize=7)

    anim = FuncAnimation(fig, update, frames=len(picks))
    if shutil.which('ffmpeg'):
        path = path.with_suffix('.mp4')
        anim.save(path, writer=FFMpegWriter(fps=10))
    else:
        path = path.with_suffix('.gif')
        anim.save(path, writer=PillowWriter(fps=10))
    plt.close(fig)
    return path, len(picks)


def write_comparison(
    pairs: list,
    summary: dict,
    bag_path: Path | None,
    figures_dir: Path | None,
    task: TaskLike,
    faces: np.ndarray | None = None,
) -> dict:
    """
    Every comparison output asked for; returns what was written, for the summary.

    faces: the cloth's triangles (a `--cloth-mesh`'s; None: the grid's).
    """
    run = summary['run']
    out: dict[str, Any] = {}
    if not pairs:
        return {'skipped': 'no frame was scored'}
    if bag_path is not None:
        out['bag'] = str(bag_path)
        out['bag_topics'] = write_comparison_bag(
            bag_path, pairs, task, float(run['rate_hz']), faces
        )
    if figures_dir is not None:
        figures_dir.mkdir(parents=True, exist_ok=True)
        fig_path = figures_dir / 'qualitative.png'
        out['figure'], out['figure_panels'] = (
            str(fig_path),
            qualitative_figure(pairs, run['primitive'], fig_path, faces, inputs_line(summary)),
        )
        anim_path, frames = animation(pairs, figures_dir / 'animation', faces)
        out['animation'], out['animation_frames'] = str(anim_path), frames
    return out
