"""
Your own motion: the engines follow the recorded grippers, in any frame; a wrong motion is refused.

The recordings (test/own_motion_recording.py) hold a motion of the test's own, simulated with
MuJoCo's Python API directly and written with rosbags: once in the world, once in a robot-base
frame turned 35 degrees about z, the grippers as tf frames.
"""

import json

from cloth_bench_ros import cli
from own_motion_recording import noise_floor, write_recording
import pytest
from test_cli import assert_one_line_error
from test_cli import cli as cli_process

GRIPPERS = ('--gripper-frames', 'left_gripper,right_gripper')


@pytest.fixture(scope='module')
def recordings(tmp_path_factory):
    root = tmp_path_factory.mktemp('own_motion')
    world = write_recording(root / 'world', targets_topic='/arm/targets')
    write_recording(root / 'base', frame='base_link')
    return root, world


def _run(bag, out, *extra, grid='6x8'):
    args = ['run', '--bag', str(bag), '--topic', '/points', '--grid', grid, '--output', str(out)]
    assert cli.main([*args, *extra]) == 0
    return json.loads((out / 'summary.json').read_text())


def _scored(summary):
    """CD_d of mujoco and the time its window ends (the first table contact, else the end)."""
    cop = summary['real']['change_of_phase']
    until = cop.get('t_s', float('inf')) if cop.get('frame') is not None else float('inf')
    return summary['engines']['mujoco']['CD_d'], until


def test_the_recorded_grippers_are_followed_in_the_world_and_in_a_turned_base_frame(
    recordings, tmp_path, capsys
):
    root, reference = recordings
    world = _run(root / 'world', tmp_path / 'world', *GRIPPERS)
    base = _run(root / 'base', tmp_path / 'base', *GRIPPERS)
    printed = capsys.readouterr().out
    assert 'table: top at z = 0.750 m in world, from the plane found in the first cloud' in printed
    assert 'table: top at z = 0.650 m in base_link' in printed  # the base is 0.1 m up
    cd_world, until = _scored(world)
    cd_base, _ = _scored(base)
    floor = noise_floor(reference['floors'], until)
    assert 0.8 < until < 1.6  # the cloth reaches the table while it is lowered
    assert cd_world == pytest.approx(cd_base, abs=1e-4)  # CD does not change with the frame
    assert cd_world < floor + 0.02, (cd_world, floor)
    motion = world['run']['motion']
    assert motion['source'] == 'tf frames left_gripper,right_gripper'
    assert motion['table_z'] == pytest.approx(0.75, abs=0.002) and motion['frame'] == 'world'
    assert world['run']['task_sha256'] != base['run']['task_sha256']


@pytest.mark.slow
def test_the_papers_motion_scores_far_worse_on_it(recordings, tmp_path, capsys):
    root, reference = recordings
    followed, _ = _scored(_run(root / 'world', tmp_path / 'own', *GRIPPERS))
    wrong = _run(root / 'world', tmp_path / 'wrong', '--motion', 'task')
    assert "motion: the task's, as --motion task asks" in capsys.readouterr().out
    assert wrong['engines']['mujoco']['CD_d'] > 5 * followed


def test_the_targets_topic_is_followed_as_the_tf_frames_are(recordings, tmp_path):
    root, _ = recordings
    frames = _scored(_run(root / 'world', tmp_path / 'tf', *GRIPPERS, grid='4x5'))[0]
    targets = _run(root / 'world', tmp_path / 'targets', '--targets-topic', '/arm/targets',
                   grid='4x5')
    assert targets['run']['motion']['source'] == 'targets topic /arm/targets'
    assert _scored(targets)[0] == pytest.approx(frames, abs=1e-6)  # the same samples


def test_a_recording_of_another_motion_is_refused_in_one_line(recordings):
    root, _ = recordings
    result = cli_process('run', '--bag', str(root / 'world'), '--topic', '/points')
    assert_one_line_error(result, 'does not match the task dynamic', '--gripper-frames',
                          '--targets-topic')


@pytest.mark.parametrize('kind,words', [
    ('gap', ['gap of', 'at most 0.1 s']),
    ('late', ['missing at the start']),
])
def test_gripper_samples_with_a_gap_or_missing_at_the_start_are_refused(tmp_path, kind, words):
    bag = tmp_path / kind
    if kind == 'gap':
        write_recording(bag, tf_gap=(0.8, 1.1))
    else:
        write_recording(bag, tf_from=0.4)
    result = cli_process('run', '--bag', str(bag), '--topic', '/points', *GRIPPERS)
    assert_one_line_error(result, *words)


def test_grippers_further_apart_than_the_cloth_is_wide_are_refused(recordings, tmp_path):
    root, _ = recordings
    result = cli_process('run', '--bag', str(root / 'world'), '--topic', '/points', *GRIPPERS,
                         '--cloth-size', '0.4,0.6', '--output', str(tmp_path / 'out'))
    assert_one_line_error(result, 'grippers start 0.500 m apart', '0.400 m')


def test_the_motion_command_writes_the_task_file_the_nodes_take(recordings, tmp_path):
    from cloth_bench_ros.core.task_data import load_task
    from cloth_bench_ros.core.trajectory import full_targets
    from cloth_bench_ros.nodes.trajectory_publisher import TrajectoryPublisher
    from cloth_bench_ros.runtime import Parameter, rclpy

    root, _ = recordings
    path = tmp_path / 'motion.yaml'
    assert cli.main(['motion', '--bag', str(root / 'base'), '--topic', '/points', *GRIPPERS,
                     '--table-z', '0.65', '--output', str(path)]) == 0
    task = load_task('dynamic', path)
    assert task.recorded is not None and task.recorded.table_source == '--table-z'
    context = rclpy.Context()
    rclpy.init(args=['prog'], context=context)
    try:
        node = TrajectoryPublisher(
            context=context, parameter_overrides=[Parameter('task', value=str(path))]
        )
        expected = full_targets(task, 100.0)  # the node streams the recorded grippers
        assert (node.targets.left == expected.left).all()
        assert node.targets.left[-1] == pytest.approx(task.recorded.left[-1])
        node.destroy_node()
    finally:
        context.shutdown()


def test_the_turn_into_the_scene_puts_the_grippers_on_x_and_the_table_at_its_height():
    import math

    from cloth_bench_ros.core import scene
    from cloth_bench_ros.data.recorded_motion import table_line, to_scene_matrix
    from cloth_bench_ros.data.tf_buffer import apply
    import numpy as np

    left = np.array([1.0, 2.0, 1.4])
    right = left + 0.45 * np.array([math.cos(2.5), math.sin(2.5), 0.0])  # along 143 degrees
    for table_z, z_left in ((0.7, 1.4 - 0.7 + scene.TABLE_TOP_Z), (None, 1.0)):
        m = to_scene_matrix(left, right, table_z)
        moved = apply(m, np.array([left, right]))
        assert moved == pytest.approx(np.array([[0, 0, z_left], [0.45, 0, z_left]]), abs=1e-12)
        assert np.allclose(m[:3, :3] @ m[:3, :3].T, np.eye(3))  # rigid: distances kept
    line = table_line({'recorded': {'table_z': None, 'frame': 'base', 'table_source': 'none'}})
    assert line.startswith('table: none') and '0.805 m below' in line
