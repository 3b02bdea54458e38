"""
The node graph as one OS process per node over DDS on loopback: `cloth-bench run --processes`.

The same nodes and parameters as studies/run_pipeline.py's in-process run, each started as its
console script's module (`python -m cloth_bench_ros.nodes.<node> --ros-args ...`) with one
parameter file, on the DDS transport confined to loopback (interface lo, no multicast, peer
127.0.0.1) on ROS_DOMAIN_ID, or a random domain when it is not set. The nodes find each other by
name (the trajectory publisher's graph_ready); the evaluator ends the run and writes summary.json,
which is what this returns, with the same CD/HD/L_s as the lockstep in-process run.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
import random
import subprocess
import sys
import tempfile
import time

from cloth_bench_ros.nodes.common import NAMESPACE
from cloth_bench_ros.runtime.dds import loopback_environment
from cloth_bench_ros.studies.errors import ProcessRunError, RunTimeout
from cloth_bench_ros.studies.run_pipeline import node_parameters, RunConfig
import yaml


def node_failed(what: str, status: int, log: Path) -> Exception:
    """
    Return the error of a process (`what`, e.g. `node evaluator`) that exited with `status`.

    Status 2 is bad input (the nodes' mains: one line), any other a bug.

    A bug's cause holds what the process printed (its traceback), shown under `--verbose`.
    """
    message = f'{what} exited with status {status}: {_last_line(log)}'
    if status == 2:
        return ProcessRunError(message)
    crashed = RuntimeError(message)
    crashed.__cause__ = RuntimeError(log.read_text(errors='replace').rstrip())
    return crashed


def _command(name: str, params_file: Path) -> list[str]:
    module = 'simulator' if name.startswith('simulator_') else name
    return [
        sys.executable,
        '-m',
        f'cloth_bench_ros.nodes.{module}',
        '--ros-args',
        '-r',
        f'__ns:=/{NAMESPACE}',
        '-r',
        f'__node:={name}',
        '--params-file',
        str(params_file),
    ]


def _last_line(path: Path) -> str:
    lines = [line for line in path.read_text(errors='replace').splitlines() if line.strip()]
    return lines[-1] if lines else '(no output)'


def run_processes(config: RunConfig, timeout_s: float = 900.0) -> dict:
    """Run the graph of `config`, one process per node, until the evaluator ends; its summary."""
    domain = (
        int(os.environ['ROS_DOMAIN_ID'])
        if os.environ.get('ROS_DOMAIN_ID')
        else random.randint(1, 200)
    )
    env = {**os.environ, **loopback_environment(domain), 'CLOTH_BENCH_TRANSPORT': 'dds'}
    with tempfile.TemporaryDirectory(prefix='cloth_bench_processes_') as tmp:
        work = Path(tmp)
        output_dir = Path(config.output_dir) if config.output_dir else work / 'report'
        params = {
            f'/{NAMESPACE}/{name}': {'ros__parameters': p}
            for name, p in node_parameters(config, output_dir).items()
        }
        params_file = work / 'params.yaml'
        params_file.write_text(yaml.safe_dump(params))
        procs: dict[str, subprocess.Popen] = {}
        logs: dict[str, Path] = {}
        try:
            for name in params:  # all at once: start-up does not depend on the order
                node = name.rsplit('/', 1)[-1]
                logs[node] = work / f'{node}.log'
                with logs[node].open('w') as log:
                    procs[node] = subprocess.Popen(
                        _command(node, params_file), env=env, stdout=log, stderr=subprocess.STDOUT
                    )
            deadline = time.monotonic() + timeout_s
            while procs['evaluator'].poll() is None:
                for node, proc in procs.items():
                    if proc.poll() not in (None, 0):
                        raise node_failed(f'node {node}', proc.returncode, logs[node])
                if time.monotonic() > deadline:
                    raise RunTimeout(f'the run did not end within {timeout_s:.0f} s')
                time.sleep(0.05)
            if procs['evaluator'].returncode != 0:
                raise node_failed('node evaluator', procs['evaluator'].returncode,
                                  logs['evaluator'])
            return json.loads((output_dir / 'summary.json').read_text())
        finally:
            for proc in procs.values():
                if proc.poll() is None:
                    proc.terminate()  # SIGTERM: each node's run loop stops between callbacks
            for proc in procs.values():
                try:
                    proc.wait(10)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait()
