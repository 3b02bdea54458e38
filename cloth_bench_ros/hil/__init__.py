"""
Hardware-in-the-loop: the simulator paced against a wall clock, its deadlines and highest rate.

Modules: `config` (a run's settings), `layout` (CPUs, SCHED_FIFO, busy wait), `warmup` (the grid a
rate can hold), `groups` (the node processes, run as `python -m cloth_bench_ros.hil.groups`),
`study` (`run_hil`, `HilResult`), `find_rate` (the highest rate held) and `recommendation` (the
recommendation file from a settings sweep). The package root imports only the light modules, so
that `groups` starts without the study. The timeline, the deadline rule and the real-time process
settings stay in core: the nodes and rank use them too.
"""

from cloth_bench_ros.hil.config import HilConfig
from cloth_bench_ros.hil.layout import Layout, resolve_layout
from cloth_bench_ros.hil.warmup import coarser_grids, Warmup, warmup

__all__ = ['HilConfig', 'Layout', 'Warmup', 'coarser_grids', 'resolve_layout', 'warmup']
