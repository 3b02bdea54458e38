"""
The report's section of qualitative comparisons: the figures and animations runs wrote.

`cloth-bench run --figures` has the evaluator draw them (nodes/comparison.py).
"""

from __future__ import annotations

from functools import partial
from pathlib import Path
import shutil

from cloth_bench_ros.report.blocks import figure_block, heading, paragraph
from cloth_bench_ros.report.metric_sections import fig4_blocks


def comparison_section(results_dir: Path) -> list:
    """
    Report blocks: each run directory with a qualitative figure (`cloth-bench run --figures`).

    Run directories are results_dir or one level below; the figure and its animation are copied
    into the report directory when the report is written.
    """
    found = sorted({*results_dir.glob('qualitative.png'), *results_dir.glob('*/qualitative.png')})
    if not found:
        return []
    blocks = [
        heading(2, "Qualitative comparison (the paper's Fig. 4)"),
        paragraph(
            "Simulated mesh in red over the real cloud in black at the paper's time steps, CD/HD"
            ' (m) under each panel, one row per engine; the animation shows the whole trial.'
        ),
    ]
    for figure in found:
        run = figure.parent.name
        for src in [figure, *sorted(figure.parent.glob('animation.*'))]:
            what = 'qualitative figure' if src == figure else 'animation'
            blocks.append(
                figure_block(f'{run}_{src.name}', f'{run}: {what}', partial(_copy_into, src))
            )
    return blocks + fig4_blocks(results_dir)


def _copy_into(src: Path, dst: Path) -> Path:
    shutil.copyfile(src, dst)
    return dst
