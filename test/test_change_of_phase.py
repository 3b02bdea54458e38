"""The change of phase of a dynamic trial found in the data, and how runs use it."""

from __future__ import annotations

import glob
import json
from pathlib import Path

from camera_recording import CAMERA_TOPIC, EPOCH_START_NS, make_camera_recording
from cloth_bench_ros import cli
from cloth_bench_ros.core.phase import (
    CONTACT_FLOOR,
    CONTACT_MARGIN,
    contact_points,
    first_table_contact,
    in_contact,
)
from cloth_bench_ros.core.scene import TABLE_TOP_Z
from cloth_bench_ros.data import BagReader
from cloth_bench_ros.data.replay import plan_replay, ReplayOptions
from cloth_bench_ros.paths import bundled_bag, share_dir
import numpy as np
import pytest

FAST = ['--grid', '6x8']


def hanging(rng, lowest: float, n: int = 2000) -> np.ndarray:
    """Return a cloth-like cloud whose lowest points reach `lowest` (m, world z)."""
    return np.column_stack(
        [rng.uniform(0, 0.5, n), rng.normal(0, 0.01, n), rng.uniform(lowest, lowest + 0.7, n)]
    )


def falling(rng, contact_at: int, frames: int = 40, noise: float = 0.0) -> list[np.ndarray]:
    """Frames of a cloth lowered onto the table, touching it from frame `contact_at` on."""
    out = []
    for k in range(frames):
        lowest = (
            TABLE_TOP_Z + 0.003
            if k >= contact_at
            else TABLE_TOP_Z + 0.06 + 0.01 * (contact_at - k)
        )
        points = hanging(rng, lowest)
        if k >= contact_at:  # a strip of the cloth lies on the table
            points[:100, 2] = TABLE_TOP_Z + rng.uniform(0.001, 0.008, 100)
        out.append(points + rng.normal(0, noise, points.shape) if noise else points)
    return out


def test_contact_is_the_first_frame_with_cloth_at_the_table():
    rng = np.random.default_rng(0)
    assert first_table_contact(falling(rng, 25)).index == 25
    assert first_table_contact(falling(rng, 25, noise=0.002)).index == 25


def test_single_stray_points_and_noise_are_not_contact():
    rng = np.random.default_rng(1)
    frames = falling(rng, 30, noise=0.002)
    for k in (3, 10, 17):  # a few stray points at the table in frames before contact
        frames[k][:3, 2] = TABLE_TOP_Z + 0.001
    assert first_table_contact(frames).index == 30
    assert not in_contact(frames[10]) and in_contact(frames[30])


def test_no_contact_and_a_visible_table_give_no_frame():
    rng = np.random.default_rng(2)
    hanging_only = [hanging(rng, TABLE_TOP_Z + 0.1) for _ in range(20)]
    found = first_table_contact(hanging_only)
    assert found.index is None and 'no table contact in 20 frames' in found.reason
    table = np.column_stack(
        [rng.uniform(-0.2, 0.7, 500), rng.uniform(-0.8, 0.8, 500), np.full(500, TABLE_TOP_Z)]
    )
    # the table top itself is below the contact band: an uncleaned cloud finds the cloth
    with_table = [np.concatenate([f, table]) for f in falling(rng, 10)]
    assert first_table_contact(with_table).index == 10
    # a table 1.5 cm higher than the scene's is in the band from the first frame: no answer
    higher = [np.concatenate([f, table + [0, 0, 0.015]]) for f in falling(rng, 10)]
    found = first_table_contact(higher)
    assert found.index is None and 'first frame' in found.reason
    assert first_table_contact([]).index is None


def test_the_band_starts_where_the_cleaning_plane_band_ends():
    from cloth_bench_ros.core.cleaning import CleaningConfig

    # Cloth points within the plane band are removed with the table: the band starts above them.
    assert CONTACT_FLOOR == CleaningConfig().table_distance < CONTACT_MARGIN
    heights = np.linspace(0, 0.03, 50)
    on_table = np.column_stack([np.zeros(50), np.zeros(50), TABLE_TOP_Z + heights])
    assert contact_points(on_table) == np.count_nonzero((heights > 0.01) & (heights <= 0.02))


def _dynamic_bags() -> list[Path]:
    return [
        Path(p)
        for p in sorted(glob.glob(str(share_dir('bags') / '*dynamic*')))
        if Path(p).is_dir()
    ]


def test_every_bundled_dynamic_bag_has_its_first_contact_as_change_of_phase():
    bags = _dynamic_bags()
    assert len(bags) >= 4
    for bag in bags:
        reader = BagReader(bag)
        found = first_table_contact(points for _, points in reader.clouds())
        assert (
            found.index is not None and abs(found.index - reader.trial.change_of_phase_frame) <= 1
        ), bag


@pytest.mark.slow
@pytest.mark.parametrize('bag_name', [bag.name for bag in _dynamic_bags()])
def test_camera_like_copies_give_the_same_change_of_phase(bag_name, tmp_path):
    source = share_dir('bags') / bag_name
    camera = tmp_path / 'camera'
    make_camera_recording(source, camera, seed=3, pre_roll=12, noise=0.002)
    options = ReplayOptions(
        cloth='towel',
        primitive='dynamic',
        topic=CAMERA_TOPIC,
        start_time=f'{EPOCH_START_NS / 1e9:.9f}',
    )
    plan = plan_replay(BagReader(camera), options)
    cop = plan.change_of_phase
    assert plan.counts['before_start'] == 12
    assert cop['source'] == 'detected'
    assert abs(cop['frame'] - BagReader(source).trial.change_of_phase_frame) <= 1, cop
    assert plan.trial.change_of_phase_frame == cop['frame']


@pytest.mark.slow
def test_a_plain_recording_is_scored_up_to_the_detected_change_of_phase(tmp_path, capsys):
    camera = tmp_path / 'camera'
    make_camera_recording(bundled_bag('towel', 'dynamic'), camera, noise=0.002)
    out = tmp_path / 'run'
    args = [
        'run',
        '--bag',
        str(camera),
        '--topic',
        CAMERA_TOPIC,
        '--start-time',
        f'{EPOCH_START_NS / 1e9:.9f}',
        '--output',
        str(out),
        *FAST,
    ]
    assert cli.main(args) == 0
    printed = capsys.readouterr().out
    summary = json.loads((out / 'summary.json').read_text())
    cop = summary['real']['change_of_phase']
    expected = BagReader(bundled_bag('towel', 'dynamic')).trial.change_of_phase_frame
    assert cop['source'] == 'detected' and abs(cop['frame'] - expected) <= 1
    assert (
        f'CD_d/HD_d over frames 0-{cop["frame"] - 1}: change of phase at frame {cop["frame"]},'
        f' detected (first table contact, t = {cop["t_s"]:.2f} s)'
        in printed
    )
    assert summary['engines']['mujoco']['frames_in_window'] == cop['frame']
    # The option wins over the data, and says so.
    out2 = tmp_path / 'run2'
    assert (
        cli.main([*args[:-4], '--output', str(out2), *FAST, '--change-of-phase-frame', '80']) == 0
    )
    assert (
        'change of phase at frame 80, given by --change-of-phase-frame' in capsys.readouterr().out
    )
    summary2 = json.loads((out2 / 'summary.json').read_text())
    assert summary2['real']['change_of_phase']['source'] == 'option'
    assert summary2['engines']['mujoco']['frames_in_window'] == 80


@pytest.mark.slow
def test_no_contact_scores_every_frame_and_says_so(tmp_path, capsys):
    camera = tmp_path / 'camera'
    make_camera_recording(bundled_bag('towel', 'dynamic'), camera, frames=60, pre_roll=0)
    out = tmp_path / 'run'
    assert (
        cli.main(
            [
                'run',
                '--bag',
                str(camera),
                '--topic',
                CAMERA_TOPIC,
                '--start-time',
                f'{EPOCH_START_NS / 1e9:.9f}',
                '--output',
                str(out),
                *FAST,
            ]
        )
        == 0
    )
    printed = capsys.readouterr().out
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['real']['change_of_phase']['source'] == 'none'
    assert (
        'CD_d/HD_d over every frame: no change of phase (no table contact in 60 frames)' in printed
    )
    m = summary['engines']['mujoco']
    assert m['frames_in_window'] == m['frames_scored'] == 60


@pytest.mark.slow
def test_quasi_static_is_scored_over_its_whole_length(tmp_path, capsys):
    out = tmp_path / 'run'
    assert cli.main(['run', '--primitive', 'quasi_static', '--output', str(out), *FAST]) == 0
    assert 'CD_d/HD_d' not in capsys.readouterr().out
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['real']['change_of_phase']['frame'] is None
    m = summary['engines']['mujoco']
    assert m['frames_in_window'] == m['frames_scored']


@pytest.mark.slow
@pytest.mark.parametrize('storage, compression', [('sqlite3', 'message'), ('mcap', 'file')])
def test_the_same_recording_in_another_storage_scores_exactly_alike(
    storage, compression, tmp_path
):
    # Lossless variants of one camera-like recording (rosbags' Writer): same detected frame, same
    # digits.
    source = bundled_bag('towel', 'dynamic')
    summaries = []
    for name, kind, mode in (('mcap', 'mcap', 'none'), ('variant', storage, compression)):
        bag = tmp_path / name
        make_camera_recording(
            source, bag, seed=5, pre_roll=7, noise=0.002, storage=kind, compression=mode
        )
        out = tmp_path / f'run_{name}'
        assert (
            cli.main(
                [
                    'run',
                    '--bag',
                    str(bag),
                    '--topic',
                    CAMERA_TOPIC,
                    '--start-time',
                    f'{EPOCH_START_NS / 1e9:.9f}',
                    '--output',
                    str(out),
                    *FAST,
                ]
            )
            == 0
        )
        summaries.append(json.loads((out / 'summary.json').read_text()))
    assert BagReader(tmp_path / 'variant').storage.startswith(
        f'{storage}, compression {compression}:zstd'
    )
    mcap, variant = (
        {
            'cop': s['real']['change_of_phase'],
            'accounting': s['real']['accounting'],
            **{
                k: s['engines']['mujoco'][k]
                for k in ('CD_d', 'HD_d', 'frames_scored', 'frames_in_window')
            },
        }
        for s in summaries
    )
    assert mcap['cop']['source'] == 'detected' and variant == mcap
