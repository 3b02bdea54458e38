"""`cloth-bench` as a user meets it: bad input gets one clear line and exit status 2."""

import os
import subprocess
import sys

from cloth_bench_ros.core.trajectory import CSV_HEADER
import pytest


def cli(*args, cwd=None):
    return subprocess.run(
        [sys.executable, '-m', 'cloth_bench_ros.cli', *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=300,
    )


def assert_one_line_error(result, *words):
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert 'Traceback' not in result.stderr
    for word in words:
        assert word in lines[0], lines[0]


def test_missing_bag(tmp_path):
    assert_one_line_error(cli('run', '--bag', str(tmp_path / 'nope')), 'nope')


@pytest.mark.slow
def test_random_bytes_bag(tmp_path):
    bag = tmp_path / 'random.mcap'
    bag.write_bytes(os.urandom(4096))
    assert_one_line_error(cli('run', '--bag', str(bag)), 'random.mcap')


def test_corrupt_bag(tmp_path, hanging_bag):
    bad = tmp_path / 'corrupt'
    bad.mkdir()
    for f in hanging_bag.iterdir():
        data = f.read_bytes()
        if f.suffix == '.mcap':
            data = data[:64] + os.urandom(len(data) - 128) + data[-64:]
        (bad / f.name).write_bytes(data)
    result = cli('run', '--bag', str(bad))
    assert_one_line_error(result, 'corrupt')


def test_bag_without_pointcloud2(tmp_path):
    from cloth_bench_ros.data import BagWriter
    from cloth_bench_ros.data.messages import serialize
    from cloth_bench_ros.runtime.messages import String

    path = tmp_path / 'strings'
    with BagWriter(path) as bag:
        bag.write('/chatter', 'std_msgs/msg/String', 0, serialize(String(data='hi')))
    assert_one_line_error(cli('run', '--bag', str(path)), 'PointCloud2')


@pytest.mark.parametrize(
    'args,words',
    [
        (['run', '--engine', 'nosuch'], ['nosuch']),
        (['run', '--rate', '0'], ['rate']),
        (['run', '--rate', '-10'], ['rate']),
        (['run', '--cloth', 'silk'], ['silk']),
        (['run', '--primitive', 'twirl'], ['twirl']),
        (['trajectory', '--rate', '0'], ['rate']),
    ],
)
def test_bad_arguments(args, words):
    assert_one_line_error(cli(*args), *words)


def test_trajectory_prints_csv():
    result = cli('trajectory', '--primitive', 'quasi_static', '--rate', '10')
    assert result.returncode == 0
    lines = result.stdout.splitlines()
    assert lines[0] == CSV_HEADER and len(lines) == 142


def test_import_command_with_a_transform_file(tmp_path):
    from cloth_bench_ros.data import BagReader
    from test_importer import make_tree

    make_tree(tmp_path / 'data')
    shift = tmp_path / 'shift.txt'
    shift.write_text('1 0 0 0.5\n0 1 0 0\n0 0 1 0\n0 0 0 1\n')
    result = cli(
        'import',
        str(tmp_path / 'data'),
        '--output',
        str(tmp_path / 'bags'),
        '--transform',
        str(shift),
        '--no-progress',
    )
    assert result.returncode == 0, result.stderr
    assert 'imported 3 trial(s)' in result.stdout
    trial = BagReader(tmp_path / 'bags' / 'towel_0_dynamic').trial
    assert trial.transform[0][3] == 0.5 and trial.change_of_phase_frame == 99


def test_import_command_refuses_a_bad_transform(tmp_path):
    bad = tmp_path / 'bad.txt'
    bad.write_text('1 2 3')
    assert_one_line_error(
        cli('import', str(tmp_path), '--output', str(tmp_path / 'o'), '--transform', str(bad)),
        'bad.txt',
    )


@pytest.mark.slow
def test_engines_lists_available_and_unavailable_engines_with_reasons():
    result = cli('engines')
    assert result.returncode == 0
    rows = {line.split()[0]: line.split(None, 3) for line in result.stdout.splitlines()[1:]}
    assert rows['mujoco'][1] == 'yes' and rows['bullet'][1] == 'yes'
    assert rows['flex'][1] == 'no' and 'CUDA' in rows['flex'][3]
    assert rows['sofa'][1] == 'no' and 'PyPI' in rows['sofa'][3]


def test_cloud_without_xyz_names_the_bag(tmp_path):
    from cloth_bench_ros.core.pointcloud2 import create_cloud_xyz32
    from cloth_bench_ros.data import BagWriter
    from cloth_bench_ros.data.messages import serialize
    from cloth_bench_ros.runtime.messages import Header, PointCloud2, PointField

    msg = create_cloud_xyz32(Header(frame_id='world'), [[0, 0, 1]], PointCloud2, PointField)
    msg.fields = msg.fields[:2]
    path = tmp_path / 'no_z'
    with BagWriter(path) as bag:
        bag.write('/cloth_bench/real/cloud', 'sensor_msgs/msg/PointCloud2', 0, serialize(msg))
    assert_one_line_error(cli('run', '--bag', str(path)), 'no_z', 'no z field')


@pytest.mark.slow
def test_nan_points_empty_clouds_and_irregular_frames_are_counted_and_reported(tmp_path):
    from cloth_bench_ros.core.scene import ClothGrid
    from cloth_bench_ros.data import BagWriter, TrialInfo
    import numpy as np

    grid = ClothGrid(10, 10).vertices()
    path = tmp_path / 'messy'
    trial = TrialInfo(
        cloth='towel', trial=0, primitive='dynamic', change_of_phase_frame=99, source='test'
    )
    with BagWriter(path, trial=trial) as bag:
        for k in range(132):
            if k == 50:
                continue  # a dropped frame: one interval of 2/30 s
            points = grid.copy()
            if k % 10 == 0:
                points[:3] = np.nan  # 3 NaN points in 13 frames
            if k == 7:
                points = points[:0]  # an empty cloud
            bag.write_cloud('/cloth_bench/real/cloud', round(k * 1e9 / 30), points)
    result = cli('run', '--bag', str(path), '--output', str(tmp_path / 'out'))
    assert result.returncode == 0, result.stderr
    assert 'real frames: 131 on the topic = 130 scored + 1 empty (adds up)' in result.stdout
    assert 'real points: 39 NaN points dropped, 1 intervals not at 30 Hz' in result.stdout


@pytest.mark.parametrize(
    'setting,words',
    [
        ('mujoco.mass=-1', ['mass', '-1']),
        ('mujoco.stiffnesss=3', ['stiffnesss']),
        ('mujoco.poisson=0.9', ['poisson', 'outside']),
    ],
)
def test_bad_engine_parameters(setting, words):
    assert_one_line_error(cli('run', '--set', setting), *words)


def test_malformed_preset_file(tmp_path):
    (tmp_path / 'mujoco.yaml').write_text(
        'engine: mujoco\npresets: {towel: {dynamic: [not, a, mapping]}}\n'
    )
    assert_one_line_error(cli('run', '--presets', str(tmp_path)), 'mujoco.yaml')
