"""Every real frame of a bag is accounted for: the counts add up to the bag's count."""

from __future__ import annotations

import json
from pathlib import Path

from cloth_bench_ros import cli
from cloth_bench_ros.core.scene import ClothGrid
from cloth_bench_ros.data import BagWriter, TrialInfo
import pytest

EPOCH = 1_650_000_000_000_000_000


def _bag(path: Path, frames: int, fps: float, with_trial: bool, first_ns: int = 0) -> Path:
    points = ClothGrid(10, 10).vertices()
    trial = TrialInfo('towel', 0, 'dynamic', None, 'test', fps=fps) if with_trial else None
    with BagWriter(path, trial=trial) as bag:
        for k in range(frames):
            bag.write_cloud('/points', first_ns + round(k * 1e9 / fps), points)
    return path


@pytest.mark.slow
@pytest.mark.parametrize(
    'frames,fps,sim_rate,expected',
    [
        (200, 30.0, 30.0, {'scored': 133, 'after_trajectory': 67}),  # longer than the 4.4 s fling
        (60, 30.0, 30.0, {'scored': 60, 'after_trajectory': 0}),  # shorter
        (
            132,
            30.0,
            7.0,
            {'scored': 129, 'after_trajectory': 3},
        ),  # the last 7 Hz step is at 4.286 s
        (5, 0.5, 30.0, {'scored': 3, 'after_trajectory': 2}),  # frames at 0, 2, 4, 6, 8 s
    ],
)
def test_counts_add_up(tmp_path, capsys, frames, fps, sim_rate, expected):
    bag = _bag(tmp_path / 'bag', frames, fps, with_trial=True)
    out = tmp_path / 'out'
    assert (
        cli.main(
            [
                'run',
                '--bag',
                str(bag),
                '--rate',
                str(sim_rate),
                '--grid',
                '6x8',
                '--output',
                str(out),
            ]
        )
        == 0
    )
    acc = json.loads((out / 'summary.json').read_text())['real']['accounting']
    assert acc['frames_in_bag'] == frames and acc['adds_up']
    assert {k: acc[k] for k in expected} == expected
    assert acc['before_start'] == acc['empty'] == acc['unpaired'] == acc['not_received'] == 0
    assert (
        f'real frames: {frames} on the topic = {expected["scored"]} scored'
        in capsys.readouterr().out
    )


@pytest.mark.slow
def test_plain_bag_at_7_hz_with_a_given_start(tmp_path):
    bag = _bag(tmp_path / 'bag', 50, 7.0, with_trial=False, first_ns=EPOCH)
    out = tmp_path / 'out'
    assert (
        cli.main(
            [
                'run',
                '--bag',
                str(bag),
                '--start-time',
                '1.0',
                '--grid',
                '6x8',
                '--rate',
                '30',
                '--output',
                str(out),
            ]
        )
        == 0
    )
    real = json.loads((out / 'summary.json').read_text())['real']
    acc = real['accounting']
    # frames 0-6 come before the start; frames at 0 .. 30/7 s of the motion are scored; 31/7 s >
    # 4.4 s
    assert (acc['before_start'], acc['scored'], acc['after_trajectory']) == (7, 31, 12) and acc[
        'adds_up'
    ]
    assert real['alignment']['bag_ns'] == EPOCH + 1_000_000_000
    assert real['alignment']['method'] == '--start-time (seconds from the first message)'


def test_no_frame_scored_is_an_error(tmp_path, capsys):
    bag = _bag(tmp_path / 'bag', 10, 30.0, with_trial=False, first_ns=EPOCH)
    assert (
        cli.main(
            [
                'run',
                '--bag',
                str(bag),
                '--start-time',
                '100',
                '--grid',
                '6x8',
                '--rate',
                '30',
                '--output',
                str(tmp_path / 'out'),
            ]
        )
        == 2
    )
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and 'no frame was scored' in err and '10 before start' in err
