"""What one run is: the bag, the engines, the rate, the task and the options of the graph."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from cloth_bench_ros.engines.settle import FULL
from cloth_bench_ros.options import OPTIONS


@dataclass
class RunConfig:
    bag: Path
    engines: list[str] = field(default_factory=lambda: ['mujoco'])
    rate_hz: float = OPTIONS['rate_hz'].default
    cloth: str = OPTIONS['cloth'].default
    primitive: str = OPTIONS['primitive'].default
    task: str = ''  # a task file (--task); '': the shipped task of `primitive`
    seed: int = 0
    pacing: str = OPTIONS['pacing'].default
    output_dir: Path | None = None
    engine_params: dict[str, dict] = field(default_factory=dict)  # engine -> parameter overrides
    grid: tuple[int, int] | None = None  # (nx, nz) vertices; None: the engine's default
    cloth_size: tuple[float, float] | None = None  # (W, L) m; None: the benchmark's 0.5 x 0.7
    cloth_mass: float | None = None  # kg, the whole cloth; None: the preset's per area
    cloth_mesh: str | None = None  # OBJ, PLY or STL file of the cloth; None: the grid
    presets_dir: Path | None = None  # directory of <engine>.yaml presets; None: config/presets
    all_metrics: bool = True  # the direct path (studies/direct.py): False scores CD/HD only
    settle: str = FULL  # the settle phase (engines.settle): full (the paper's) or fast
    replay: dict = field(
        default_factory=dict
    )  # recorder parameters for plain bags (topic, start_time, ...)
    change_of_phase_frame: int | None = None  # None: the bag's own
    record_comparison: Path | None = None  # comparison MCAP bag to write
    comparison_figures: bool = False  # qualitative figure and animation in output_dir
    live: dict = field(default_factory=dict)  # evaluator's live, live_host, live_port, live_wait
