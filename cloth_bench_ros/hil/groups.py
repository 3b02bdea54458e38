"""
The three process groups of a hardware-in-the-loop run, and how each is served.

Each group runs in its own OS process over DDS (`HilConfig.processes`, the default), on loopback
only (interface lo, no multicast, peer 127.0.0.1) and on ROS_DOMAIN_ID or a random domain:

- controller: the trajectory publisher, the controller's stand-in. It sends target k when it is
  due (first target + k / rate on the monotonic clock), receives the states, and keeps the
  timeline (due, sent, received per target) from which latency is measured, where a controller
  measures it: target due -> state received.
- simulator: one engine alone in its process (optionally pinned to a core, SCHED_FIFO, heap
  frozen). Its target subscription is keep-last 1: when late it steps to the newest target and
  counts the targets it skipped.
- observer: recorder and evaluator, off the critical path; they score the run's states (CD).

Without processes the three groups share one process on the embedded intra-process transport
(no target is ever dropped there: a late simulator queues).
"""

from __future__ import annotations

import gc
import json
import os
from pathlib import Path
import random
import signal
import subprocess
import sys
import time
from typing import Sequence

from cloth_bench_ros.core import realtime_process
from cloth_bench_ros.core.trajectory import full_targets
from cloth_bench_ros.hil.config import HilConfig, SIMULATOR_FILE
from cloth_bench_ros.nodes.common import close_nodes
from cloth_bench_ros.nodes.evaluator import Evaluator
from cloth_bench_ros.nodes.recorder import Recorder
from cloth_bench_ros.nodes.simulator import Simulator
from cloth_bench_ros.nodes.trajectory_publisher import TrajectoryPublisher
from cloth_bench_ros.runtime import (
    deserialize_message,
    Parameter,
    PointCloud2,
    PoseArray,
    rclpy,
    serialize_message,
    SingleThreadedExecutor,
)
from cloth_bench_ros.runtime.dds import loopback_environment
from cloth_bench_ros.safe_io import atomic_write_text
from cloth_bench_ros.studies.errors import RunTimeout
from cloth_bench_ros.studies.processes import node_failed
import numpy as np
import yaml

GROUPS = (
    'observer',
    'simulator',
    'controller',
)  # started in this order, so the controller starts last
SINGLE_THREADED_MATH = ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS')


# ---------------------------------------------------------------------------------- nodes


def _parameters(config: HilConfig, group: str, run_dir: Path) -> list[tuple[str, dict]]:
    """(node kind, parameter values) of each node of a group."""
    common = {'primitive': config.primitive, 'task': config.task_file,
              'rate_hz': float(config.rate_hz)}
    mesh = {'cloth_mesh': config.cloth_mesh}  # the nodes that build or score the cloth
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
                    **mesh,
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
                **mesh,
                **dict(config.live),
            },
        ),
        # The run's rate: the recording's frames after the last target are not sent (at a rate
        # whose last target falls before the motion's end they would never come due).
        ('recorder', {**common, **mesh, 'bag': str(config.bag), 'use_sim_time': True}),
    ]


def _make_nodes(config: HilConfig, group: str, run_dir: Path, context) -> list:
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

    The observer ends once the evaluator reported (it has every frame due by the last target,
    whatever the recorder has left); the simulator runs until it is told to stop.
    """
    if group == 'simulator':
        return False
    if group == 'observer':
        return all(n.done for n in nodes if isinstance(n, Evaluator))
    return all(getattr(n, 'done', True) for n in nodes)


def _waiting(nodes: list) -> str:
    """Say which nodes have not ended and what the evaluator still waits for."""
    parts = []
    for node in nodes:
        if getattr(node, 'done', True):
            continue
        waiting: list[str] = getattr(node, 'waiting_for', list)()
        parts.append(node.get_name() + (f' ({"; ".join(waiting)})' if waiting else ''))
    return ', '.join(parts) or 'nothing'


def _write_simulator_file(run_dir: Path, nodes: list, notes: Sequence[str] = ()) -> None:
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
    run_s = config.duration or len(full_targets(config.task(), config.rate_hz)) / config.rate_hz
    return 3 * run_s + 90.0  # start-up, DDS discovery and a simulator far slower than real time


def _run_in_process(config: HilConfig, run_dir: Path) -> None:
    """All three groups in one process, one executor, the embedded intra-process transport."""
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
                raise RunTimeout(
                    f'HIL {config.ident()}: the run did not finish in time, waiting for '
                    + _waiting([n for g, nodes in groups if g in _waited(config) for n in nodes])
                )
            executor.spin_once(timeout_sec=0.01)
        _write_simulator_file(run_dir, [n for _, nodes in groups for n in nodes])
    finally:
        close_nodes([n for _, nodes in groups for n in nodes])
        rclpy.shutdown(context=context)


def serve_group(config: HilConfig, group: str, run_dir: Path) -> None:
    """Run one group in this process over DDS until it finishes or gets SIGTERM."""
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
            fifo = realtime_process.request_fifo(config.realtime_priority)
            print(f'controller: {fifo}', flush=True)
        if group == 'observer':
            print(f'observer: {realtime_process.lower_priority()}', flush=True)
        if group != 'simulator':  # a pinned simulator's step loop has its core to itself
            print(f'{group}: {realtime_process.keep_off_cpu(config.cpu)}', flush=True)
        executor = SingleThreadedExecutor(context=context)
        for node in nodes:
            executor.add_node(node)
        # Polling keeps the simulator's core awake: a core that idles between targets (a VM's vCPU
        # halts) wakes slowly and steps from cold caches, 1.5-3x slower at the p99 on this machine.
        polling = group == 'simulator' and config.busy_wait
        notes = [f'poll: {realtime_process.poll_on_default_scheduler()}'] if polling else []
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
            'live': tuple(tuple(p) for p in d.get('live', ())),
        }
    )


def _run_processes(config: HilConfig, run_dir: Path) -> None:
    """Run the three groups as OS processes; the simulator is stopped once the others are done."""
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
                        'cloth_bench_ros.hil.groups',
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
            except subprocess.TimeoutExpired:  # the machine's doing, not a bug: say so
                busy = (' (the observer runs at nice 19, off the critical path, so other work on'
                        ' this machine can starve it: load average '
                        f'{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores)'
                        if group == 'observer' else '')
                raise RunTimeout(
                    f'HIL {config.ident()}: the {group} process did not finish in time{busy} '
                    f'(see {run_dir / (group + ".log")})'
                ) from None
            if code != 0:  # a bad input (2) or a bug (any other status) in that process
                raise node_failed(f'HIL {config.ident()}: the {group} process', code,
                                  run_dir / f'{group}.log')
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
        raise node_failed(f'HIL {config.ident()}: the simulator process',
                          procs['simulator'].returncode, run_dir / 'simulator.log')


def run_groups(config: HilConfig, run_dir: Path) -> None:
    """Run the three groups, as processes or in this one; return once the run is over."""
    (_run_processes if config.processes else _run_in_process)(config, run_dir)


if __name__ == '__main__':  # python -m cloth_bench_ros.hil.groups GROUP RUN_DIR CONFIG
    serve_group(_config_from_json(sys.argv[3]), sys.argv[1], Path(sys.argv[2]))
