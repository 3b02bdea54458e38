"""Report files of one run (summary JSON, per-frame CSV) and the result table the CLI prints."""

from __future__ import annotations

import csv
import json
import math
from dataclasses import asdict
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
    summary_path, frames_path = out_dir / "summary.json", out_dir / "frames.csv"
    summary_path.write_text(json.dumps(_finite_or_none(summary), indent=2, sort_keys=True) + "\n")
    with frames_path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=["engine", "frame", "t", "cd", "hd", "in_window", "diverged"])
        writer.writeheader()
        for s in scores:
            writer.writerow(asdict(s))
    return summary_path, frames_path


def _fmt(value: float | None, digits: int = 4) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    return f"{value:.{digits}f}"


def result_table(summary: dict) -> str:
    """One row per engine: CD, HD, L_s and step latency (ms), in a fixed-width table."""
    suffix = "d" if summary["run"]["primitive"] == "dynamic" else "q"
    header = (f"{'engine':<10} {'CD_' + suffix:>8} {'HD_' + suffix:>8} {'L_s':>10} "
              f"{'step mean':>10} {'p50':>8} {'p99':>8} {'max':>8}  status")
    lines = [header, "-" * len(header)]
    for engine, m in summary["engines"].items():
        st = m["step_time"]
        ms = {k: (st[k] * 1e3 if st[k] is not None else None) for k in ("mean", "p50", "p99", "max")}
        status = f"diverged at step {m['diverged_at_step']}" if m["diverged"] else "ok"
        lines.append(
            f"{engine:<10} {_fmt(m['CD_' + suffix]):>8} {_fmt(m['HD_' + suffix]):>8} {_fmt(m['L_s'], 7):>10} "
            f"{_fmt(ms['mean'], 3):>10} {_fmt(ms['p50'], 3):>8} {_fmt(ms['p99'], 3):>8} {_fmt(ms['max'], 3):>8}  {status}"
        )
    lines.append("CD/HD in m (one-sided, L1); L_s in m; step times in ms.")
    return "\n".join(lines)
