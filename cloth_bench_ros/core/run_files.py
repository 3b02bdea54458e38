"""The result files of one run: summary.json (NaN as null) and frames.csv (a row per frame)."""

from __future__ import annotations

import csv
from dataclasses import asdict, fields
import json
import math
from pathlib import Path
from typing import Sequence


def _finite_or_none(value):
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _finite_or_none(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_finite_or_none(v) for v in value]
    return value


FRAME_COLUMNS = ('engine', 'frame', 't', 'cd', 'hd', 'in_window', 'diverged')


def write_run_report(out_dir: Path, summary: dict, scores: Sequence) -> tuple[Path, Path]:
    """summary.json (NaN written as null) and frames.csv (one row per engine and real frame)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    summary_path, frames_path = out_dir / 'summary.json', out_dir / 'frames.csv'
    summary_path.write_text(json.dumps(_finite_or_none(summary), indent=2, sort_keys=True) + '\n')
    rows = [asdict(s) for s in scores]
    columns = [f.name for f in fields(scores[0])] if rows else list(FRAME_COLUMNS)
    with frames_path.open('w', newline='') as f:
        writer = csv.DictWriter(f, fieldnames=columns)
        writer.writeheader()
        for row in rows:  # a value not computed (no surface metrics, no contact rule) is empty
            writer.writerow({k: '' if v is None else v for k, v in row.items()})
    return summary_path, frames_path
