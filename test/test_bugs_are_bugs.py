"""A bug in an engine step is a bug (exit 1), never a divergence: in every command and process."""

from __future__ import annotations

import json
import os
from pathlib import Path
import subprocess
import sys

from camera_recording import CAMERA_TOPIC, make_camera_recording
from cloth_bench_ros.engines.base import Instability
from cloth_bench_ros.engines.mujoco_cloth import MujocoCloth
from cloth_bench_ros.identify.objective import evaluate, Trial
from cloth_bench_ros.paths import bundled_bag
import numpy as np
import pytest

PLANTED_DIR = Path(__file__).parent / 'planted_bug'
PLANTED = 'planted bug in MujocoCloth._step'  # planted_bug/sitecustomize.py's message
BUG_LINE = f'cloth-bench: internal error (a bug): ValueError: {PLANTED}'
SMALL = ['--grid', '6x8']


def planted(*args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    """Run `cloth-bench ARGS` with the bug planted in it and in every process it starts."""
    path = os.pathsep.join(p for p in (str(PLANTED_DIR), os.environ.get('PYTHONPATH')) if p)
    return subprocess.run(
        [sys.executable, '-m', 'cloth_bench_ros.cli', *args],
        env={**os.environ, 'PYTHONPATH': path}, capture_output=True, text=True, timeout=timeout,
    )


def assert_a_bug(result: subprocess.CompletedProcess) -> None:
    """Exit 1 with the internal-error line naming the planted ValueError; no divergence said."""
    assert result.returncode == 1, result.stdout[-2000:] + result.stderr[-3000:]
    assert BUG_LINE in result.stderr, result.stderr[-3000:]
    assert 'diverged' not in result.stdout + result.stderr, result.stdout + result.stderr


class _BrokenMujoco(MujocoCloth):
    def _step(self, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        raise ValueError(PLANTED)


class _UnstableMujoco(MujocoCloth):
    def _step(self, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        raise Instability('MuJoCo mjWARN_BADQACC: the state went NaN, Inf or huge')


def test_only_an_engines_own_instability_signal_is_a_divergence():
    left, right = np.array([-0.25, 0.0, 0.6]), np.array([0.25, 0.0, 0.6])
    broken = _BrokenMujoco(100.0)
    broken.reset(0, left, right)
    with pytest.raises(ValueError, match=PLANTED):
        broken.step(left, right)
    assert not broken.diverged
    unstable = _UnstableMujoco(100.0)
    before = unstable.reset(0, left, right)
    after = unstable.step(left, right)
    assert unstable.divergence.step == 1 and 'BADQACC' in unstable.divergence.reason
    assert np.array_equal(after, before)  # the last sound state, not MuJoCo's reset one
    assert MujocoCloth.instability_signals and all(
        'mjWARN_BADQ' in s for s in MujocoCloth.instability_signals)


def test_a_trial_raises_a_bug_and_keeps_a_refused_input_an_error_row():
    trial = Trial('mujoco', 'towel', 'dynamic', str(bundled_bag('towel', 'dynamic')), (),
                  grid=(5, 6), max_frames=3)
    original = MujocoCloth._step
    try:
        MujocoCloth._step = _BrokenMujoco._step  # type: ignore[method-assign]
        with pytest.raises(ValueError, match=PLANTED):
            evaluate(trial)
    finally:
        MujocoCloth._step = original  # type: ignore[method-assign]
    refused = evaluate(Trial('mujoco', 'towel', 'dynamic', trial.bag, (('mass', -1.0),),
                             grid=(5, 6), max_frames=3))
    assert refused['status'] == 'error' and 'mass' in refused['reason']
    assert refused['step'] is None


def test_run_with_a_bug_in_the_step_exits_1_with_the_traceback_under_verbose(tmp_path):
    result = planted('run', '--engine', 'mujoco', *SMALL, '--output', str(tmp_path / 'run'))
    assert_a_bug(result)
    assert '(--verbose shows the traceback)' in result.stderr
    assert not (tmp_path / 'run' / 'summary.json').exists()
    verbose = planted('--verbose', 'run', '--engine', 'mujoco', *SMALL,
                      '--output', str(tmp_path / 'verbose'))
    assert verbose.returncode == 1
    assert 'Traceback (most recent call last)' in verbose.stderr
    assert f'ValueError: {PLANTED}' in verbose.stderr.splitlines()[-1]


@pytest.mark.slow
def test_a_simulator_node_process_with_a_bug_fails_as_a_bug_not_a_divergence(tmp_path):
    result = planted('run', '--processes', '--engine', 'mujoco', *SMALL,
                     '--output', str(tmp_path / 'run'))
    assert result.returncode == 1, result.stderr[-3000:]
    assert 'internal error (a bug): RuntimeError: node simulator_mujoco exited with status 1: ' \
        f'ValueError: {PLANTED}' in result.stderr
    assert 'diverged' not in result.stdout + result.stderr


def test_sweep_on_dask_workers_with_a_bug_exits_1_and_writes_no_diverged_row(tmp_path):
    out = tmp_path / 'sweep'
    result = planted('sweep', '--engine', 'mujoco', '--rate', '100', '--cloth', 'towel',
                     '--primitive', 'dynamic', '--seeds', '1', *SMALL, '--workers', '1',
                     '--no-progress', '--keep-frames', 'none', '--output', str(out))
    assert_a_bug(result)
    rows = (out / 'results.jsonl').read_text().splitlines() if (out / 'results.jsonl').exists() \
        else []
    assert not rows


def test_stress_with_a_bug_exits_1(tmp_path):
    result = planted('stress', '--engine', 'mujoco', '--case', 'light_cloth', '--workers', '1',
                     '--no-progress', '--output', str(tmp_path / 'stress'))
    assert_a_bug(result)
    assert not (tmp_path / 'stress' / 'stress.jsonl').exists()


@pytest.mark.slow
def test_identify_with_a_bug_exits_1_and_records_no_diverged_trial(tmp_path):
    out = tmp_path / 'identify'
    bag = str(bundled_bag('towel', 'dynamic'))
    result = planted('identify', '--engine', 'mujoco', '--bag', bag,
                     '--sampler', 'tpe', '--trials', '2', '--param', 'damping', '--grid', '5x6',
                     '--max-frames', '5', '--validate-seeds', '0', '--workers', '1',
                     '--no-progress', '--output', str(out))
    assert_a_bug(result)
    trials = out / 'trials.jsonl'
    statuses = [json.loads(line)['status'] for line in trials.read_text().splitlines()] \
        if trials.exists() else []
    assert 'diverged' not in statuses


@pytest.mark.slow
def test_hil_with_a_bug_exits_1(tmp_path):
    result = planted('hil', '--engine', 'mujoco', '--rate', '100', '--grid', '4x5',
                     '--no-lockstep', '--output', str(tmp_path / 'hil'))
    assert_a_bug(result)


@pytest.mark.slow
def test_rank_with_a_bug_exits_1(tmp_path):
    source = bundled_bag('towel', 'dynamic')
    for seed, name in ((1, 'first'), (2, 'second')):
        make_camera_recording(source, tmp_path / name, seed=seed, pre_roll=30, noise=0.002)
    result = planted('rank', str(tmp_path / 'first'), str(tmp_path / 'second'),
                     '--topic', CAMERA_TOPIC, '--engine', 'mujoco', '--trials', '2',
                     '--sampler', 'tpe', '--seeds', '1', *SMALL, '--recommend-rate', '100',
                     '--max-frames', '6', '--workers', '1', '--no-progress',
                     '--output', str(tmp_path / 'rank'))
    assert_a_bug(result)
    assert not (tmp_path / 'rank' / 'rank.json').exists()
