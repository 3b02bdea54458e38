"""The result files of one run: summary.json (NaN as null) and frames.csv (a row per frame)."""

from __future__ import annotations

import csv
from dataclasses import asdict
import json
import math
from pathlib import Path
from typing import Iterable


def _finite_or_none(value):
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _finite_or_none(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_finite_or_none(v) for v in value]
    return value


def write_run_report(out_dir: Path, summary: dict, scores: Iterable) -> tuple[Path, Path]:
    """summary.json (NaN written as null) and frames.csv (one row per engine and real frame)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    summary_path, frames_path = out_dir / 'summary.json', out_dir / 'frames.csv'
    summary_path.write_text(json.dumps(_finite_or_none(summary), indent=2, sort_keys=True) + '\n')
    with frames_path.open('w', newline='') as f:
        writer = csv.DictWriter(
            f, fieldnames=['engine', 'frame', 't', 'cd', 'hd', 'in_window', 'diverged']
        )
        writer.writeheader()
        for s in scores:
            writer.writerow(asdict(s))
    return summary_path, frames_path
