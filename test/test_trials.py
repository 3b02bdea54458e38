"""The repetitions of a recording: found without an engine, scored one at a time by `run`."""

from __future__ import annotations

import json
from pathlib import Path

from camera_recording import CAMERA_TOPIC, make_camera_recording, make_repeated_recording
from cloth_bench_ros import cli
from cloth_bench_ros.core.trajectory import sample_quintic
from cloth_bench_ros.data import BagReader
from cloth_bench_ros.data.alignment import AlignmentError
from cloth_bench_ros.data.replay import choose_trial, read_frames, ReplayOptions, split_recording
from cloth_bench_ros.data.trials import (
    MAX_TARGET_RESIDUAL,
    split_clouds,
    split_targets,
)
from cloth_bench_ros.paths import bundled_bag
from cloth_bench_ros.rank.trials import prepare_trials
import numpy as np
import pytest

BASE_NS = 1_700_000_000_000_000_000


def _targets(starts_s: list[float], scale: float = 1.0, rate: float = 100.0, end_s: float = 20.0):
    """Targets at `rate` of the fling started at each of `starts_s`, at rest between them."""
    quintic = sample_quintic('dynamic', rate)
    stamps, positions = [], []
    for k in range(int(end_s * rate)):
        t = k / rate
        begun = [s for s in starts_s if s <= t]
        i = min(int(round((t - begun[-1]) * rate)), len(quintic) - 1) if begun else 0
        if any(0 < s - t <= 1.0 for s in starts_s):
            i = 0  # back at the start pose (one jump) a second before the next repetition
        left = quintic.left[0] + scale * (quintic.left[i] - quintic.left[0])
        right = quintic.right[0] + scale * (quintic.right[i] - quintic.right[0])
        stamps.append(BASE_NS + round(t * 1e9))
        positions.append(np.array([left, right]))
    return stamps, positions


def test_targets_give_each_repetition_and_its_start():
    stamps, positions = _targets([2.0, 8.5, 15.0])
    split = split_targets(stamps, positions, '/arm/targets', 'dynamic')
    assert [t.usable for t in split.trials] == [True] * 3
    # The grippers jump back to the start pose between repetitions (one sample): no trial.
    assert split.jumps == 2
    for trial, true_s in zip(split.trials, (2.0, 8.5, 15.0)):
        assert abs(trial.start.bag_ns - (BASE_NS + true_s * 1e9)) <= 1e6, trial
        assert trial.residual_m < 1e-6 and abs(trial.duration_s - 4.4) < 0.02
    assert split.trials[0].start.method == 'targets topic /arm/targets, fitted to the task'


def test_a_motion_that_is_not_the_task_is_left_out_with_its_reason():
    stamps, positions = _targets([2.0], scale=1.5, end_s=8.0)  # the same path, 1.5 x as far
    split = split_targets(stamps, positions, '/arm/targets', 'dynamic')
    assert len(split.trials) == 1 and not split.trials[0].usable
    assert 'residual' in split.trials[0].reason and 'does not match' in split.trials[0].reason
    assert split.trials[0].residual_m > MAX_TARGET_RESIDUAL
    with pytest.raises(AlignmentError, match='no trial of the task'):
        choose_trial(split, 0)
    with pytest.raises(AlignmentError, match='--trial 1 is left out'):
        choose_trial(split, 1)
    short = split_targets(stamps[:400], positions[:400], '/t', 'dynamic')  # cut after 2 s
    assert not short.trials[0].usable and 'lasts' in short.trials[0].reason


def test_still_clouds_hold_no_motion():
    rng = np.random.default_rng(0)
    cloth = rng.uniform(0, 0.5, (500, 3))
    clouds = [cloth + rng.normal(0, 0.001, cloth.shape) for _ in range(60)]
    split = split_clouds([BASE_NS + k * 33_333_333 for k in range(60)], clouds, 'dynamic')
    assert split.trials == [] and split.reason.startswith('no motion')
    with pytest.raises(AlignmentError, match='no motion'):
        choose_trial(split, 0)


@pytest.fixture(scope='module')
def three_flings(tmp_path_factory) -> tuple[Path, list[int]]:
    path = tmp_path_factory.mktemp('repeated') / 'three_flings'
    starts = make_repeated_recording(
        bundled_bag('towel', 'dynamic'), path, rest_s=1.0, jitter_ns=20_000_000
    )
    return path, starts


@pytest.mark.slow
def test_run_scores_the_chosen_repetition_and_accounts_for_the_others(
    three_flings, tmp_path, capsys
):
    path, starts = three_flings
    out = tmp_path / 'run'
    args = ['run', '--bag', str(path), '--topic', CAMERA_TOPIC, '--trial', '2', '--align',
            'onset', '--grid', '6x8', '--output', str(out)]
    assert cli.main(args) == 0
    printed = capsys.readouterr().out
    summary = json.loads((out / 'summary.json').read_text())
    split = summary['real']['trials']
    assert split['source'] == 'clouds' and split['scored'] == 2
    assert [t['usable'] for t in split['trials']] == [True] * 3 and split['jumps'] == 2
    for trial, true_ns in zip(split['trials'], starts):
        late_ms = (trial['start']['bag_ns'] - true_ns) / 1e6
        assert 0 <= late_ms <= 20, late_ms  # the corners lag their grippers: about 10 ms here
        assert trial['frames'] == 132
    assert summary['real']['alignment']['bag_ns'] == split['trials'][1]['start']['bag_ns']
    acc = summary['real']['accounting']
    assert acc['adds_up'] and acc['frames_in_bag'] == 3 * (132 + 60)
    # Trial 2's own frames: its rest before it, its motion, its rest after; the rest is others'.
    assert acc['other_trials'] >= 2 * 132 and acc['scored'] >= 0.9 * 105
    assert acc['before_start'] <= 61 and acc['after_trajectory'] <= 61
    assert '3 trials found in the clouds (3 usable, 2 jumps between rests ignored); scoring ' \
        'trial 2' in printed
    assert 'trial 2: bag time 7.' in printed and '132 frames, start +/- ' in printed
    assert 'other trials' in printed and '(adds up)' in printed


@pytest.mark.parametrize(
    'pre_roll, noise', [(5, 0.0), pytest.param(30, 0.002, marks=pytest.mark.slow)]
)
def test_the_slow_drag_splits_into_its_one_trial_with_its_start(pre_roll, noise, tmp_path):
    # The drag's first second lowers the cloth 5 cm in its own plane, which the clouds barely
    # show: they move visibly only some 4 s in, and its last 3 s are as slow.
    path = tmp_path / 'drag'
    true_ns = make_camera_recording(
        bundled_bag('towel', 'quasi_static'), path, seed=1, pre_roll=pre_roll, noise=noise
    )
    options = ReplayOptions(primitive='quasi_static', topic=CAMERA_TOPIC)
    with BagReader(path) as reader:
        frames = read_frames(reader, options)
        split = split_recording(reader, options, frames.stamps, frames.clouds)
    assert [t.usable for t in split.trials] == [True], split.as_dict()
    (trial,) = split.trials
    assert (trial.first_ns - true_ns) / 1e9 > 2.0  # the first moving frame, seconds late
    assert abs(trial.start.bag_ns - true_ns) <= 50e6, (trial.start.bag_ns - true_ns) / 1e6
    assert abs(trial.frames - 420) <= 1 and trial.residual_m < 0.015  # 30 Hz over 14 s
    if not noise:
        return
    lines: list[str] = []  # rank takes it as the rank's own recordings (2 mm noise, 1 s of rest)
    found = prepare_trials([path], options, tmp_path / 'rank', lines.append)
    assert len(found) == 1 and found[0].frames == trial.frames, lines


def test_a_split_is_kept_only_while_the_splitter_is_the_same(tmp_path, monkeypatch):
    from cloth_bench_ros.data import trials

    path = tmp_path / 'fling'
    make_camera_recording(bundled_bag('towel', 'dynamic'), path, pre_roll=10)
    options = ReplayOptions(primitive='dynamic', topic=CAMERA_TOPIC)

    def written() -> int:
        (found,) = prepare_trials([path], options, tmp_path / 'rank', lambda line: None)
        return (Path(found.bag) / 'metadata.yaml').stat().st_mtime_ns

    first = written()
    assert written() == first  # read back
    monkeypatch.setattr(trials, 'CORNER_POINTS', trials.CORNER_POINTS + 1)
    assert written() != first  # another splitter: split again
