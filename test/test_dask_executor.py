"""
The Dask executor with real processes on loopback.

An external scheduler and two workers (one killed mid-run), two sweeps on one directory, and a
client killed with SIGKILL leaving no worker behind.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
import signal
import subprocess
import sys
import time

from bag_fixtures import write_hanging_cloth_bag
from cloth_bench_ros.sweep import study as sw
from identify_target import write_engine_target_bag
import psutil
import pytest

BIN = Path(sys.executable).parent
ENV = {**os.environ, 'PYTHONPATH': str(Path(__file__).resolve().parents[1])}


@pytest.fixture(scope='module')
def bag_dir(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp('executor_bags')
    write_hanging_cloth_bag(d / 'towel_dynamic')
    return d


def _sweep_argv(bag_dir: Path, out: Path, seeds: int, *extra: str) -> list[str]:
    return [
        str(BIN / 'cloth-bench'),
        'sweep',
        '--engine',
        'mujoco',
        '--rate',
        '100',
        '--cloth',
        'towel',
        '--primitive',
        'dynamic',
        '--seeds',
        str(seeds),
        '--grid',
        '5x6',
        '--bag-dir',
        str(bag_dir),
        '--output',
        str(out),
        '--no-progress',
        '--keep-frames',
        'none',
        '--set',
        'mujoco.timestep=0.01',
        *extra,
    ]


def _wait(predicate, timeout: float, what: str) -> None:
    end = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > end:
            raise AssertionError(f'timed out waiting for {what}')
        time.sleep(0.2)


def _scheduler_address(info: Path) -> str:
    try:
        return json.loads(info.read_text())['address']
    except (OSError, ValueError, KeyError):
        return ''


def _rows(out: Path) -> list[dict]:
    path = out / sw.RESULTS_FILE
    return [json.loads(line) for line in path.read_text().splitlines()] if path.exists() else []


def _stop(procs) -> None:
    for p in procs:
        if p.poll() is None:
            p.kill()
        p.wait(timeout=30)


@pytest.mark.slow
def test_sweep_and_identify_on_an_external_scheduler_survive_a_killed_worker(bag_dir, tmp_path):
    info = tmp_path / 'scheduler.json'
    scheduler = subprocess.Popen(
        [
            str(BIN / 'dask'),
            'scheduler',
            '--host',
            '127.0.0.1',
            '--port',
            '0',
            '--no-dashboard',
            '--dashboard-address',
            '127.0.0.1:0',
            '--scheduler-file',
            str(info),
        ],
        env=ENV,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    procs = [scheduler]
    try:
        # dask creates the file before it writes it: wait for its whole JSON
        _wait(lambda: _scheduler_address(info), 60, 'the scheduler file')
        address = _scheduler_address(info)
        assert address.startswith('tcp://127.0.0.1:')
        workers = [
            subprocess.Popen(
                [
                    str(BIN / 'dask'),
                    'worker',
                    address,
                    '--nthreads',
                    '1',
                    '--no-nanny',
                    '--host',
                    '127.0.0.1',
                    '--no-dashboard',
                    '--dashboard-address',
                    '127.0.0.1:0',
                ],
                env=ENV,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
            )
            for _ in range(2)
        ]
        procs += workers
        _wait(
            lambda: all(psutil.Process(p.pid).net_connections(kind='inet') for p in workers),
            60,
            'the workers',
        )
        for p in [scheduler] + workers:  # the network rule: loopback only
            for c in psutil.Process(p.pid).net_connections(kind='inet'):
                assert c.status != psutil.CONN_LISTEN or c.laddr.ip == '127.0.0.1', (
                    p.args[1],
                    c.laddr,
                )
        out = tmp_path / 'sweep'
        client = subprocess.Popen(
            _sweep_argv(bag_dir, out, 5, '--scheduler', address),
            env=ENV,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        procs.append(client)
        _wait(lambda: len(_rows(out)) >= 1, 240, 'the first finished cell')
        workers[0].kill()  # mid-run: it was running the other cell in flight
        stdout, stderr = client.communicate(timeout=300)
        assert client.returncode == 0, stderr
        rows = _rows(out)
        assert sorted(r['seed'] for r in rows) == list(range(5))  # every cell exactly once
        assert all(r['status'] == 'ok' for r in rows), [r.get('error') for r in rows]

        target = write_engine_target_bag(
            tmp_path / 'target', 'mujoco', {'damping': 2.0, 'timestep': 0.01}, (5, 6), 10
        )
        ident = tmp_path / 'ident'
        result = subprocess.run(
            [
                str(BIN / 'cloth-bench'),
                'identify',
                '--scheduler',
                address,
                '--bag',
                str(target),
                '--grid',
                '5x6',
                '--set',
                'mujoco.timestep=0.01',
                '--param',
                'damping',
                '--sampler',
                'tpe',
                '--trials',
                '6',
                '--validate-seeds',
                '1',
                '--output',
                str(ident),
                '--no-progress',
            ],
            env=ENV,
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert result.returncode == 0, result.stderr
        trials = [json.loads(line) for line in (ident / 'trials.jsonl').read_text().splitlines()]
        assert sorted(t['number'] for t in trials) == list(range(6))
        assert (
            len(_rows(ident)) == 2 and 'identified' in result.stdout
        )  # seed 1: preset and identified
    finally:
        _stop(procs)


@pytest.mark.slow
def test_two_sweeps_on_one_directory_run_every_cell_once(bag_dir, tmp_path):
    out = tmp_path / 'shared'
    first = subprocess.Popen(
        _sweep_argv(bag_dir, out, 4, '--workers', '1'),
        env=ENV,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    _wait(lambda: (out / '.results.lock').exists(), 60, "the first sweep's lock")
    second = subprocess.run(
        _sweep_argv(bag_dir, out, 4, '--workers', '1'),
        env=ENV,
        capture_output=True,
        text=True,
        timeout=120,
    )
    _, err = first.communicate(timeout=300)
    assert first.returncode == 0, err
    assert second.returncode == 2 and 'is in use by sweep' in second.stderr
    assert len(second.stderr.strip().splitlines()) == 1
    keys = [sw.row_key(r) for r in _rows(out)]
    assert len(keys) == len(set(keys)) == 4
    again = subprocess.run(
        _sweep_argv(bag_dir, out, 4, '--workers', '1'),
        env=ENV,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert again.returncode == 0 and '0 cells run' in again.stdout and len(_rows(out)) == 4


def _python_children(parent: psutil.Process) -> list:
    """Return the Python processes below parent (one that exits meanwhile is not counted)."""
    out = []
    for child in parent.children(recursive=True):
        try:
            if 'python' in child.name():
                out.append(child)
        except psutil.NoSuchProcess:
            pass
    return out


@pytest.mark.slow
def test_killing_the_client_leaves_no_worker_process(bag_dir, tmp_path):
    client = subprocess.Popen(
        _sweep_argv(bag_dir, tmp_path / 'killed', 8, '--workers', '2'),
        env=ENV,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    parent = psutil.Process(client.pid)
    try:
        _wait(lambda: len(_python_children(parent)) >= 2, 120, 'two worker processes')
        _wait(lambda: (tmp_path / 'killed' / 'workers.log').exists(), 60, 'the workers to start')
        children = parent.children(recursive=True)
    finally:
        client.send_signal(signal.SIGKILL)
        client.wait(timeout=30)
    gone, alive = psutil.wait_procs(children, timeout=30)
    assert not alive, [(p.pid, p.name()) for p in alive]


def test_a_worker_keeps_the_trees_of_the_clouds_it_has_scored():
    from cloth_bench_ros.core import metrics
    import numpy as np

    rng = np.random.default_rng(0)
    a, b = rng.uniform(size=(300, 3)), rng.uniform(size=(300, 3))
    try:
        metrics.keep_trees(500)
        first = metrics.RealCloud.of(a)
        assert metrics.RealCloud.of(a.copy()) is first  # same points: the tree is not built again
        assert metrics.RealCloud.of(b) is not first
        assert (
            metrics.RealCloud.of(a) is not first
        )  # 600 points > 500: the least recent was dropped
        v = rng.uniform(size=(20, 3))
        assert first.chamfer_hausdorff(v) == metrics.RealCloud(a).chamfer_hausdorff(v)
    finally:
        metrics.keep_trees(0)
    assert metrics.RealCloud.of(a) is not metrics.RealCloud.of(a)  # off outside workers


@pytest.mark.own_dask_cluster
def test_the_local_cluster_listens_on_loopback_only():
    from cloth_bench_ros.studies.dask_executor import open_client

    with open_client(workers=1) as client:
        assert client.scheduler.address.startswith('tcp://127.0.0.1:')
        me = psutil.Process(os.getpid())
        listening = [
            c.laddr
            for p in [me] + me.children(recursive=True)
            for c in p.net_connections(kind='inet')
            if c.status == psutil.CONN_LISTEN
        ]
    assert len(listening) >= 3  # scheduler, its HTTP routes, the worker (and its nanny)
    assert all(addr.ip == '127.0.0.1' for addr in listening), listening
