"""
Hardware in the loop: the node graph with targets on the wall clock, laid out as a robot sees it.

`run_hil` runs the three groups of `hil.groups` (controller, simulator, observer) and collects
what they measured: latency per target, deadline misses, skipped targets, the engine's step time,
the machine's load, and the CD of the states the run produced. `recommended` picks a rate's
configuration from the settings sweep.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
import json
import math
import os
from pathlib import Path

from cloth_bench_ros.core.deadline import DEADLINE_BUDGET
from cloth_bench_ros.core.hil_timing import (
    check_bookkeeping,
    hil_figures,
    HilFigures,
    TargetTimeline,
)
from cloth_bench_ros.errors import InputError
from cloth_bench_ros.hil.config import HilConfig, SIMULATOR_FILE, SUMMARY_FILE, TIMELINE
from cloth_bench_ros.paths import share_dir
from cloth_bench_ros.studies.cloth import study_inputs
from cloth_bench_ros.studies.results import append_row, load_rows
from cloth_bench_ros.studies.run_config import RunConfig
from cloth_bench_ros.sweep.recommend import load_recommendations, recommend_for_rate


@dataclass
class HilResult:
    """What a real-time run measured, and whether its bookkeeping adds up."""

    config: HilConfig
    figures: HilFigures
    stepped: int
    skipped: int
    problems: list[str]  # bookkeeping that does not add up (empty: all does)
    realtime: list[str]  # what the simulator process asked for and got (cpu, scheduler, gc)
    load: dict  # CPU load during the run
    step_time: dict = field(default_factory=dict)  # the engine's own step time (s): p50, p99, max
    cd_realtime: float = math.nan  # CD of the states this run produced (skips change the physics)
    cd_lockstep: float = math.nan  # CD of the same configuration in lockstep
    observer_states: int | None = (
        None  # steps whose state the observer scored (all of them, or a problem)
    )
    diverged: bool = False
    run_dir: Path | None = None

    def row(self) -> dict:
        """Return the run as a flat JSON-safe row of hil.jsonl."""
        c = self.config
        return {
            'engine': c.engine,
            'rate_hz': c.rate_hz,
            'cloth': c.cloth,
            'primitive': c.primitive,
            'seed': c.seed,
            'config': c.config,
            'grid': f'{c.grid[0]}x{c.grid[1]}' if c.grid else None,
            'params': dict(c.params),
            'processes': c.processes,
            **study_inputs(c.primitive, c.task_file, c.cloth_mesh, c.grid, None, c.rate_hz),
            **self.figures.as_dict(),
            'stepped': self.stepped,
            'problems': self.problems,
            'realtime': self.realtime,
            **self.load,
            'step_time_p50': self.step_time.get('p50'),
            'step_time_p99': self.step_time.get('p99'),
            'step_time_max': self.step_time.get('max'),
            'cd_realtime': self.cd_realtime,
            'cd_lockstep': self.cd_lockstep,
            'observer_states': self.observer_states,
            'diverged': self.diverged,
            'run_dir': self.run_dir.name if self.run_dir else None,
        }


# ----------------------------------------------------------------------------------- load


def _cpu_times() -> tuple[int, int, int] | None:
    """(busy, steal, total) jiffies of all cores from /proc/stat, or None where there is none."""
    try:
        with open('/proc/stat') as f:
            fields = [int(v) for v in f.readline().split()[1:9]]
    except (OSError, ValueError):
        return None
    idle = fields[3] + fields[4]  # idle + iowait
    return sum(fields) - idle, fields[7], sum(fields)


class LoadMeter:
    """
    The machine's CPU load over a span: busy share, steal and load averages.

    Busy share of all cores (/proc/stat), the share the hypervisor took from a virtual machine
    (steal: the vCPU runnable but not running), load averages.
    """

    def __enter__(self) -> 'LoadMeter':
        self.start = _cpu_times()
        self.loadavg_before = os.getloadavg()[0] if hasattr(os, 'getloadavg') else math.nan
        return self

    def __exit__(self, *exc) -> None:
        end = _cpu_times()
        self.busy = self.steal = math.nan
        if self.start and end and end[2] > self.start[2]:
            total = end[2] - self.start[2]
            self.busy = (end[0] - self.start[0]) / total
            self.steal = (end[1] - self.start[1]) / total
        self.loadavg_after = os.getloadavg()[0] if hasattr(os, 'getloadavg') else math.nan

    def as_dict(self) -> dict:
        return {
            'cpu_busy': self.busy,
            'cpu_steal': self.steal,
            'loadavg_before': self.loadavg_before,
            'loadavg_after': self.loadavg_after,
            'cpu_count': os.cpu_count(),
        }


def run_hil(config: HilConfig, out_dir: Path, lockstep: bool = True) -> HilResult:
    """One real-time run (and, if asked, the same configuration in lockstep for its CD)."""
    from cloth_bench_ros.hil.groups import run_groups  # lazy: the nodes, +0.9 s on --help

    run_dir = Path(out_dir) / config.ident()
    run_dir.mkdir(parents=True, exist_ok=True)
    for stale in (SIMULATOR_FILE, SUMMARY_FILE, TIMELINE.format(engine=config.engine)):
        (run_dir / stale).unlink(missing_ok=True)
    with LoadMeter() as load:
        run_groups(config, run_dir)
    result = collect(config, run_dir, load.as_dict())
    if lockstep:
        result.cd_lockstep = lockstep_cd(config)
    return result


def collect(config: HilConfig, run_dir: Path, load: dict) -> HilResult:
    """Read what the processes wrote: the controller's timeline, simulator's counts, summary."""
    timeline_file = run_dir / TIMELINE.format(engine=config.engine)
    if not timeline_file.is_file() or not (run_dir / SIMULATOR_FILE).is_file():
        raise RuntimeError(f'HIL {config.ident()}: no timeline or simulator counts in {run_dir}')
    timeline = TargetTimeline.from_csv(timeline_file.read_text())
    sim = json.loads((run_dir / SIMULATOR_FILE).read_text())
    result = HilResult(
        config,
        hil_figures(timeline, sim['skipped'], 1.0 / config.rate_hz),
        sim['stepped'],
        sim['skipped'],
        check_bookkeeping(timeline, sim['stepped'], sim['skipped']),
        sim['realtime'],
        load,
        sim.get('step_time') or {},
        run_dir=run_dir,
    )
    if (run_dir / SUMMARY_FILE).is_file():
        m = json.loads((run_dir / SUMMARY_FILE).read_text())['engines'][config.engine]
        result.cd_realtime = _cd(m, config)
        result.diverged = bool(m['diverged'])
        heard, stepped = m['step_time']['count'], sim['stepped'] - 1  # step 0 is the reset
        result.observer_states = heard
        if (
            heard != stepped
        ):  # states the observer missed make its CD realtime a CD of fewer states
            result.problems.append(f"observer received {heard} of the {stepped} steps' states")
    return result


def _cd(metrics: dict, config: HilConfig) -> float:
    value = metrics.get(f'CD_{config.task().suffix}')  # the task's window
    return math.nan if value is None else float(value)


def lockstep_cd(config: HilConfig) -> float:
    """CD of the same configuration run in lockstep (in one process: deterministic)."""
    from cloth_bench_ros.studies.run_pipeline import run_pipeline  # lazy: +0.6 s on --help

    summary = run_pipeline(
        RunConfig(
            bag=Path(config.bag),
            engines=[config.engine],
            rate_hz=config.rate_hz,
            cloth=config.cloth,
            primitive=config.primitive,
            seed=config.seed,
            engine_params={config.engine: dict(config.params)},
            grid=config.grid,
            task=config.task_file,
            cloth_mesh=config.cloth_mesh or None,
        )
    )
    if summary is None:
        raise RuntimeError('the node graph ended before the evaluator finished')
    return _cd(summary['engines'][config.engine], config)


def write_results(results: list[HilResult], out_dir: Path) -> Path:
    """Append each run's row to <out_dir>/hil.jsonl; its path."""
    path = Path(out_dir) / 'hil.jsonl'
    for result in results:
        append_row(path, result.row())
    return path


def with_config(
    config: HilConfig, label: str, grid: tuple[int, int] | None, params: dict
) -> HilConfig:
    """Return the same run with another engine configuration."""
    return replace(config, config=label, grid=grid, params=tuple(sorted(params.items())))


RECOMMENDED_FILE = 'hil_recommended.yaml'
HIL_DEADLINE_BUDGET = (
    DEADLINE_BUDGET  # the step's share of the period (the deadline rule, core/deadline.py)
)
DEFAULT_SETTINGS = Path('results') / 'settings'  # where `cloth-bench sweep --mode settings` writes


def recommended(
    engine: str,
    cloth: str,
    primitive: str,
    rate_hz: float,
    settings: Path | None = DEFAULT_SETTINGS,
    tol_rel: float = 0.05,
    tol_abs: float = 0.002,
    budget: float = HIL_DEADLINE_BUDGET,
):
    """
    Return the configuration `--config recommended` runs and where it comes from.

    The settings sweep's results if they hold this engine, task and rate, else the shipped
    config/hil_recommended.yaml.
    """
    if settings is not None and Path(settings).exists():
        rec = recommend_for_rate(
            load_rows(Path(settings)), engine, cloth, primitive, rate_hz, tol_rel, tol_abs, budget
        )
        if rec is not None:
            return rec, f'settings sweep {settings}'
    shipped = share_dir('config') / RECOMMENDED_FILE
    for rec in load_recommendations(shipped) if shipped.is_file() else []:
        if (rec.engine, rec.cloth, rec.primitive, rec.rate_hz) == (
            engine,
            cloth,
            primitive,
            float(rate_hz),
        ):
            return rec, f'{shipped} (shipped; no settings-sweep result for it in {settings})'
    raise InputError(
        f'--config recommended: no settings-sweep result for {engine}, {cloth} {primitive} at'
        f' {rate_hz:g} Hz in {settings} and no entry in {shipped}; run `cloth-bench sweep --mode'
        f' settings --engine {engine} --rate {rate_hz:g} --cloth {cloth} --primitive {primitive}`'
        ' first'
    )


__all__ = [
    'HilConfig',
    'HilResult',
    'LoadMeter',
    'run_hil',
    'collect',
    'lockstep_cd',
    'write_results',
    'with_config',
]
