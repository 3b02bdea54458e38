"""Settings axes of `cloth-bench sweep --mode settings`, checked by the validation layer."""

from __future__ import annotations

from typing import Sequence

from cloth_bench_ros.errors import InputError
from cloth_bench_ros.studies.cells import PRESET
from cloth_bench_ros.validation import parse_grid, parse_overrides, parse_value

__all__ = ['parse_grid', 'parse_overrides', 'parse_settings_axes', 'parse_value']


def parse_settings_axes(specs: Sequence[str]) -> dict[str, list]:
    """Axes from "name=v1,v2,..." strings ("grid=6x8,11x15"; "preset" for the preset's value)."""
    axes: dict[str, list] = {}
    for spec in specs:
        name, sep, values = spec.partition('=')
        if not sep or not name or not values:
            raise InputError(f'settings axis {spec!r} is not name=value1,value2,...')
        parsed: list = []
        for text in values.split(','):
            text = text.strip()
            if name == 'grid':
                parsed.append(parse_grid(text))
            elif text == PRESET:
                parsed.append(None)
            else:
                parsed.append(parse_value(text))
        axes[name.strip()] = parsed
    return axes
