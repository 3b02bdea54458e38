"""Command-line strings of the studies: grids, parameter values, --set overrides, settings axes."""

from __future__ import annotations

import re
from typing import Sequence

from cloth_bench_ros.studies.cells import PRESET


def parse_settings_axes(specs: Sequence[str]) -> dict[str, list]:
    """Axes from "name=v1,v2,..." strings ("grid=6x8,11x15"; "preset" for the preset's value)."""
    axes: dict[str, list] = {}
    for spec in specs:
        name, sep, values = spec.partition("=")
        if not sep or not name or not values:
            raise ValueError(f"settings axis {spec!r} is not name=value1,value2,...")
        parsed = []
        for text in values.split(","):
            text = text.strip()
            if name == "grid":
                parsed.append(parse_grid(text))
            elif text == PRESET:
                parsed.append(None)
            else:
                parsed.append(parse_value(text))
        axes[name.strip()] = parsed
    return axes


def parse_grid(text: str) -> tuple[int, int]:
    """Grid text to vertices: "11x15" -> (11, 15); ValueError on anything else."""
    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    if not m or int(m.group(1)) < 2 or int(m.group(2)) < 2:
        raise ValueError(f"grid {text!r} is not NXxNZ with at least 2 vertices per side (e.g. 11x15)")
    return int(m.group(1)), int(m.group(2))


def parse_value(text: str):
    """A parameter value from the command line: bool, int, float or string."""
    low = text.strip().lower()
    if low in ("true", "on", "yes"):
        return True
    if low in ("false", "off", "no"):
        return False
    try:
        return int(text)
    except ValueError:
        pass
    try:
        return float(text)
    except ValueError:
        return text.strip()


def parse_overrides(specs: Sequence[str] | None) -> dict[str, dict]:
    """{"engine": {"param": value}} from "engine.param=value" strings."""
    out: dict[str, dict] = {}
    for spec in specs or ():
        lhs, sep, value = spec.partition("=")
        engine, dot, param = lhs.partition(".")
        if not sep or not dot or not engine or not param:
            raise ValueError(f"--set {spec!r} is not engine.param=value (e.g. mujoco.self_collision=true)")
        out.setdefault(engine.strip(), {})[param.strip()] = parse_value(value)
    return out
