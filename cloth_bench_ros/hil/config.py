"""The configuration of a hardware-in-the-loop run and the files its processes write."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
import re

from cloth_bench_ros.core.task_data import load_task
from cloth_bench_ros.options import NODE_PARAMETERS, OPTIONS

TIMELINE = 'timeline_{engine}.csv'
SIMULATOR_FILE = 'simulator.json'
SUMMARY_FILE = 'summary.json'


@dataclass(frozen=True)
class HilConfig:
    """One real-time run: engine, rate, scene, engine configuration and process settings."""

    engine: str
    rate_hz: float
    bag: Path
    cloth: str = OPTIONS['cloth'].default
    primitive: str = OPTIONS['primitive'].default
    seed: int = 0
    grid: tuple[int, int] | None = None
    params: tuple[tuple[str, object], ...] = ()  # sorted engine parameter overrides
    config: str = 'preset'  # the configuration's name (settings-sweep label)
    processes: bool = True
    cpu: int = NODE_PARAMETERS['cpu'].default  # core to pin the simulator to (-1: not pinned)
    realtime_priority: int = (
        0  # SCHED_FIFO priority of the simulator and the controller (0: not asked)
    )
    freeze_gc: bool = True
    busy_wait: bool = (
        False  # the simulator polls for targets instead of sleeping (give it a core: cpu)
    )
    duration: float = 0.0  # s of the trajectory to run (0: all of it, scored by the observer)
    live: tuple[tuple[str, object], ...] = ()  # the evaluator's live-view parameters (--live)
    task_file: str = ''  # --task: a task file instead of the shipped task of `primitive`
    cloth_mesh: str = ''  # --cloth-mesh: the cloth as a mesh file instead of the grid

    def ident(self) -> str:
        """Return the run's directory name (engine, rate, task, seed, configuration), file-safe."""
        text = (
            f'{self.engine}_{self.rate_hz:g}hz_{self.cloth}_{self.primitive}'
            f'_s{self.seed}_{self.config}'
            + (f'_task-{Path(self.task_file).stem}' if self.task_file else '')
            + (f'_mesh-{Path(self.cloth_mesh).stem}' if self.cloth_mesh else '')
        )
        return re.sub(r'[^A-Za-z0-9_.+-]+', '-', text)

    def task(self):
        """Return the Task the run follows: its task file's, else the shipped one."""
        return load_task(self.primitive, self.task_file or None)
