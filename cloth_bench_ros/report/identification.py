"""Identification in the report: before/after table, convergence per sampler, parameter importance."""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

from cloth_bench_ros.report.blocks import Block


def find_identifications(results_dir: Path) -> list[dict]:
    return []


def identification_section(ident: dict, rows: Sequence[dict]) -> list[Block]:
    return []
