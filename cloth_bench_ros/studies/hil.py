"""
Hardware in the loop: the node graph with targets on the wall clock, laid out as a robot sees it.

Three groups of nodes, each in its own OS process over DDS (`processes=True`, the default), on
loopback only (interface lo, no multicast, peer 127.0.0.1) and on ROS_DOMAIN_ID or a random domain:

- controller: the trajectory publisher, the controller's stand-in. It sends target k when it is
  due (first target + k / rate on the monotonic clock), receives the states, and keeps the
  timeline (due, sent, received per target) from which latency is measured, where a controller
  measures it: target due -> state received.
- simulator: one engine alone in its process (optionally pinned to a core, SCHED_FIFO, heap
  frozen). Its target subscription is keep-last 1: when late it steps to the newest target and
  counts the targets it skipped.
- observer: recorder and evaluator, off the critical path; they score the run's states (CD).

`processes=False` composes the three groups in one process on the embedded intra-process
transport instead (no target is ever dropped there: a late simulator queues).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
import gc
import json
import math
import os
from pathlib import Path
import random
import re
import signal
import subprocess
import sys
import time
from typing import Sequence

from cloth_bench_ros.core.hil_timing import (
    check_bookkeeping,
    hil_figures,
    HilFigures,
    TargetTimeline,
)
from cloth_bench_ros.studies.recommend import DEADLINE_BUDGET
import numpy as np
import yaml

GROUPS = (
    'observer',
    'simulator',
    'controller',
)  # started in this order, so the controller starts last
SINGLE_THREADED_MATH = ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS')
TIMELINE = 'timeline_{engine}.csv'
SIMULATOR_FILE = 'simulator.json'
SUMMARY_FILE = 'summary.json'


@dataclass(frozen=True)
class HilConfig:
    """One real-time run: engine, rate, scene, engine configuration and process settings."""

    engine: str
    rate_hz: float
    bag: Path
    cloth: str = 'towel'
    primitive: str = 'dynamic'
    seed: int = 0
    grid: tuple[int, int] | None = None
    params: tuple[tuple[str, object], ...] = ()  # sorted engine parameter overrides
    config: str = 'preset'  # the configuration's name (settings-sweep label)
    processes: bool = True
    cpu: int = -1  # core to pin the simulator to (-1: not pinned)
    realtime_priority: int = (
        0  # SCHED_FIFO priority of the simulator and the controller (0: not asked)
    )
    freeze_gc: bool = True
    busy_wait: bool = (
        False  # the simulator polls for targets instead of sleeping (give it a core: cpu)
    )
    duration: float = 0.0  # s of the trajectory to run (0: all of it, scored by the observer)

    def ident(self) -> str:
        """Return the run's directory name (engine, rate, task, seed, configuration), file-safe."""
        text = (
            f'{self.engine}_{self.rate_hz:g}hz_{self.cloth}_{self.primitive}'
            f'_s{self.seed}_{self.config}'
        )
        return re.sub(r'[^A-Za-z0-9_.+-]+', '-', text)


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


# ---------------------------------------------------------------------------------- nodes


def _parameters(config: HilConfig, group: str, run_dir: Path) -> list[tuple[str, dict]]:
    """(node kind, parameter values) of each node of a group."""
    common = {'primitive': config.primitive, 'rate_hz': float(config.rate_hz)}
    if group == 'controller':
        return [
            (
                'trajectory_publisher',
                {
                    **common,
                    'engines': [config.engine],
                    'pacing': 'realtime',
                    'timing_log': str(run_dir),
                    'duration': float(config.duration),
                },
            )
        ]
    if group == 'simulator':
        nx, nz = config.grid or (0, 0)
        # No /clock: the simulator never reads time, and a 1 kHz /clock would sit on its critical
        # path.
        return [
            (
                'simulator',
                {
                    **common,
                    'engine': config.engine,
                    'cloth': config.cloth,
                    'seed': int(config.seed),
                    'grid_nx': nx,
                    'grid_nz': nz,
                    'engine_params': yaml.safe_dump(dict(config.params)),
                    'use_sim_time': False,
                    'cpu': int(config.cpu),
                    'realtime_priority': int(config.realtime_priority),
                    'freeze_gc': bool(config.freeze_gc),
                },
            )
        ]
    return [
        (
            'evaluator',
            {
                **common,
                'engines': [config.engine],
                'output_dir': str(run_dir),
                'cloth': config.cloth,
                'seed': int(config.seed),
                'pacing': 'realtime',
                'use_sim_time': True,
            },
        ),
        ('recorder', {'bag': str(config.bag), 'use_sim_time': True}),
    ]


def _make_nodes(config: HilConfig, group: str, run_dir: Path, context) -> list:
    from cloth_bench_ros.nodes.evaluator import Evaluator
    from cloth_bench_ros.nodes.recorder import Recorder
    from cloth_bench_ros.nodes.simulator import Simulator
    from cloth_bench_ros.nodes.trajectory_publisher import TrajectoryPublisher
    from cloth_bench_ros.runtime import Parameter

    kinds = {
        'trajectory_publisher': TrajectoryPublisher,
        'simulator': Simulator,
        'evaluator': Evaluator,
        'recorder': Recorder,
    }
    nodes = []
    for kind, values in _parameters(config, group, run_dir):
        extra = {'node_name': f'simulator_{config.engine}'} if kind == 'simulator' else {}
        nodes.append(
            kinds[kind](
                context=context,
                parameter_overrides=[Parameter(k, value=v) for k, v in values.items()],
                **extra,
            )
        )
    return nodes


def _finished(group: str, nodes: list) -> bool:
    """
    Return the groups' ends: controller once its timeline is written, observer once scored.

    The observer ends once the evaluator reported; the simulator runs until it is told to stop.
    """
    if group == 'simulator':
        return False
    return all(getattr(n, 'done', True) for n in nodes)


def _write_simulator_file(run_dir: Path, nodes: list, notes: Sequence[str] = ()) -> None:
    from cloth_bench_ros.nodes.simulator import Simulator
    from cloth_bench_ros.safe_io import atomic_write_text

    for node in nodes:
        if isinstance(node, Simulator):
            times = node.step_times[1:node.step + 1]  # step 0 is the reset
            times = times[np.isfinite(times)]
            step_time = (
                {
                    'p50': float(np.percentile(times, 50)),
                    'p99': float(np.percentile(times, 99)),
                    'max': float(times.max()),
                }
                if times.size
                else {}
            )
            info = {
                'stepped': node.step + 1,
                'skipped': node.skipped,
                'realtime': node.realtime.lines() + list(notes),
                'step_time': step_time,
            }
            atomic_write_text(run_dir / SIMULATOR_FILE, json.dumps(info))


# -------------------------------------------------------------------------------- running


def _waited(config: HilConfig) -> list[str]:
    """Return the groups whose end ends the run (a shortened run is not scored)."""
    return ['controller'] if config.duration else ['controller', 'observer']


def _time_budget(config: HilConfig) -> float:
    from cloth_bench_ros.core.trajectory import full_targets

    run_s = config.duration or len(full_targets(config.primitive, config.rate_hz)) / config.rate_hz
    return 3 * run_s + 90.0  # start-up, DDS discovery and a simulator far slower than real time


def _run_in_process(config: HilConfig, run_dir: Path) -> None:
    """All three groups in one process, one executor, the embedded intra-process transport."""
    from cloth_bench_ros.nodes.common import close_nodes
    from cloth_bench_ros.runtime import rclpy, SingleThreadedExecutor

    context = rclpy.Context()
    rclpy.init(args=[], context=context, transport='intra')
    groups: list[tuple[str, list]] = []
    try:
        for group in GROUPS:
            groups.append((group, _make_nodes(config, group, run_dir, context)))
        executor = SingleThreadedExecutor(context=context)
        for _, nodes in groups:
            for node in nodes:
                executor.add_node(node)
        deadline = time.monotonic() + _time_budget(config)
        while not all(_finished(g, n) for g, n in groups if g in _waited(config)):
            if time.monotonic() > deadline:
                raise RuntimeError(f'HIL {config.ident()}: the run did not finish in time')
            executor.spin_once(timeout_sec=0.01)
        _write_simulator_file(run_dir, [n for _, nodes in groups for n in nodes])
    finally:
        close_nodes([n for _, nodes in groups for n in nodes])
        rclpy.shutdown(context=context)


def serve_group(config: HilConfig, group: str, run_dir: Path) -> None:
    """Run one group in this process over DDS until it finishes or gets SIGTERM."""
    from cloth_bench_ros.nodes.common import close_nodes
    from cloth_bench_ros.runtime import rclpy, realtime, SingleThreadedExecutor

    stopped: list[bool] = []
    signal.signal(signal.SIGTERM, lambda *_: stopped.append(True))
    context = rclpy.Context()
    rclpy.init(args=[], context=context, transport='dds')
    nodes: list = []
    try:
        nodes = _make_nodes(config, group, run_dir, context)
        if group == 'controller':  # it starts sending once its graph is complete (graph_ready)
            _warm_up_messages()
            # start-up objects out of the collector's way (the simulator also stops it)
            gc.freeze()
            # The controller is the robot's real-time loop: the same scheduling request as the
            # simulator.
            print(f'controller: {realtime.request_fifo(config.realtime_priority)}', flush=True)
        if group == 'observer':
            print(f'observer: {realtime.lower_priority()}', flush=True)
        if group != 'simulator':  # a pinned simulator's step loop has its core to itself
            print(f'{group}: {realtime.keep_off_cpu(config.cpu)}', flush=True)
        executor = SingleThreadedExecutor(context=context)
        for node in nodes:
            executor.add_node(node)
        # Polling keeps the simulator's core awake: a core that idles between targets (a VM's vCPU
        # halts) wakes slowly and steps from cold caches, 1.5-3x slower at the p99 on this machine.
        polling = group == 'simulator' and config.busy_wait
        notes = [f'poll: {realtime.poll_on_default_scheduler()}'] if polling else []
        for note in notes:
            print(f'{group}: {note}', flush=True)
        timeout = 0.0 if polling else 0.05
        while not stopped and not _finished(group, nodes):
            executor.spin_once(timeout_sec=timeout)
        _write_simulator_file(run_dir, nodes, notes)
    finally:
        close_nodes(nodes)
        rclpy.shutdown(context=context)


def _warm_up_messages() -> None:
    """Make the controller's serialisers (targets out, states in) before any deadline."""
    from cloth_bench_ros.runtime import (
        deserialize_message,
        PointCloud2,
        PoseArray,
        serialize_message,
    )

    for msg_type in (PoseArray, PointCloud2):
        deserialize_message(serialize_message(msg_type()), msg_type)


def _config_json(config: HilConfig) -> str:
    return json.dumps(
        {**config.__dict__, 'bag': str(config.bag), 'params': [list(p) for p in config.params]}
    )


def _config_from_json(text: str) -> HilConfig:
    d = json.loads(text)
    return HilConfig(
        **{
            **d,
            'bag': Path(d['bag']),
            'grid': tuple(d['grid']) if d['grid'] else None,
            'params': tuple(tuple(p) for p in d['params']),
        }
    )


def _run_processes(config: HilConfig, run_dir: Path) -> None:
    """Run the three groups as OS processes; the simulator is stopped once the others are done."""
    from cloth_bench_ros.runtime.dds import loopback_environment

    # As `cloth-bench run --processes`: DDS on loopback only, on ROS_DOMAIN_ID or a random domain.
    domain = (
        int(os.environ['ROS_DOMAIN_ID'])
        if os.environ.get('ROS_DOMAIN_ID')
        else random.randint(1, 200)
    )
    # One thread per BLAS / OpenMP library: their pools spin between calls, on a core that the
    # controller (SCHED_FIFO) or the step loop needs.
    single_threaded = dict.fromkeys(SINGLE_THREADED_MATH, '1')
    env = {**os.environ, **loopback_environment(domain), **single_threaded}
    procs: dict[str, subprocess.Popen] = {}
    deadline = time.monotonic() + _time_budget(config)
    try:
        for group in GROUPS:
            with open(run_dir / f'{group}.log', 'wb') as log:
                procs[group] = subprocess.Popen(
                    [
                        sys.executable,
                        '-m',
                        'cloth_bench_ros.studies.hil',
                        group,
                        str(run_dir),
                        _config_json(config),
                    ],
                    env=env,
                    stdout=log,
                    stderr=subprocess.STDOUT,
                    stdin=subprocess.DEVNULL,
                )
        for group in _waited(config):
            try:
                code = procs[group].wait(max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                raise RuntimeError(
                    f'HIL {config.ident()}: the {group} process did not finish in time '
                    f'(see {run_dir / (group + ".log")})'
                ) from None
            if code != 0:
                raise RuntimeError(
                    f'HIL {config.ident()}: the {group} process failed with exit status {code} '
                    f'(see {run_dir / (group + ".log")})'
                )
    finally:
        for (
            proc
        ) in procs.values():  # the simulator (and, on failure, the rest): SIGTERM, then wait
            if proc.poll() is None:
                proc.terminate()
        for proc in procs.values():
            try:
                proc.wait(10.0)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
    if procs['simulator'].returncode != 0:
        raise RuntimeError(
            f'HIL {config.ident()}: the simulator process failed with exit status '
            f'{procs["simulator"].returncode} (see {run_dir / "simulator.log"})'
        )


def run_hil(config: HilConfig, out_dir: Path, lockstep: bool = True) -> HilResult:
    """One real-time run (and, if asked, the same configuration in lockstep for its CD)."""
    run_dir = Path(out_dir) / config.ident()
    run_dir.mkdir(parents=True, exist_ok=True)
    for stale in (SIMULATOR_FILE, SUMMARY_FILE, TIMELINE.format(engine=config.engine)):
        (run_dir / stale).unlink(missing_ok=True)
    with LoadMeter() as load:
        (_run_processes if config.processes else _run_in_process)(config, run_dir)
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
        result.cd_realtime = _cd(m, config.primitive)
        result.diverged = bool(m['diverged'])
        heard, stepped = m['step_time']['count'], sim['stepped'] - 1  # step 0 is the reset
        result.observer_states = heard
        if (
            heard != stepped
        ):  # states the observer missed make its CD realtime a CD of fewer states
            result.problems.append(f"observer received {heard} of the {stepped} steps' states")
    return result


def _cd(metrics: dict, primitive: str) -> float:
    value = metrics.get('CD_d' if primitive == 'dynamic' else 'CD_q')
    return math.nan if value is None else float(value)


def lockstep_cd(config: HilConfig) -> float:
    """CD of the same configuration run in lockstep (in one process: deterministic)."""
    from cloth_bench_ros.studies.pipeline import run_pipeline, RunConfig

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
        )
    )
    if summary is None:
        raise RuntimeError('the node graph ended before the evaluator finished')
    return _cd(summary['engines'][config.engine], config.primitive)


def write_results(results: list[HilResult], out_dir: Path) -> Path:
    """Append each run's row to <out_dir>/hil.jsonl; its path."""
    from cloth_bench_ros.studies.sweep import append_row

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
    DEADLINE_BUDGET  # the step's share of the period (studies/recommend.py says why)
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
    from cloth_bench_ros.paths import share_dir
    from cloth_bench_ros.studies.recommend import load_recommendations, recommend_for_rate
    from cloth_bench_ros.studies.sweep import load_rows

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
    raise ValueError(
        f'--config recommended: no settings-sweep result for {engine}, {cloth} {primitive} at'
        f' {rate_hz:g} Hz in {settings} and no entry in {shipped}; run `cloth-bench sweep --mode'
        f' settings --engine {engine} --rate {rate_hz:g} --cloth {cloth} --primitive {primitive}`'
        ' first'
    )


if __name__ == '__main__':  # python -m cloth_bench_ros.studies.hil GROUP RUN_DIR CONFIG_JSON
    serve_group(_config_from_json(sys.argv[3]), sys.argv[1], Path(sys.argv[2]))

__all__ = [
    'HilConfig',
    'HilResult',
    'LoadMeter',
    'run_hil',
    'collect',
    'lockstep_cd',
    'write_results',
    'with_config',
    'serve_group',
]
