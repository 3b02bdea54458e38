"""
identify and rank on a user's recordings of their own motions: the recording options of `run`.

The recordings (test/own_motion_recording.py) hold motions of the test's own, simulated with
MuJoCo's Python API directly and written with rosbags, the grippers as tf frames: two motions of
one cloth (another swing). The engines follow each recording's grippers; the task file each one
is followed along is keyed into the journals and cells, so another one is computed again.
"""

import json

from cloth_bench_ros import cli
from own_motion_recording import write_recording
import pytest
from test_cli import assert_one_line_error
from test_cli import cli as cli_process

GRIPPERS = ['--topic', '/points', '--gripper-frames', 'left_gripper,right_gripper']
TINY = ['--engine', 'mujoco', '--trials', '2', '--sampler', 'tpe', '--grid', '6x8',
        '--workers', '1', '--no-progress']


@pytest.fixture(scope='module')
def motions(tmp_path_factory):
    root = tmp_path_factory.mktemp('motions')
    write_recording(root / 'swing', seed=1)
    write_recording(root / 'small_swing', seed=2, swing=0.05)
    return root


def test_identify_follows_the_recorded_grippers_and_a_changed_task_is_never_resumed(
    motions, tmp_path, capsys
):
    out = tmp_path / 'identify'
    assert cli.main(['identify', '--bag', str(motions / 'swing'), *GRIPPERS, *TINY,
                     '--validate-seeds', '1', '--output', str(out)]) == 0
    printed = capsys.readouterr().out
    assert 'one trial along its recorded motion (tf frames left_gripper,right_gripper' in printed
    summary = json.loads((out / 'identification.json').read_text())
    # held-out seed 1 along the same recorded motion (not the shipped task's: that is ~0.2 m)
    (held,) = summary['validation']
    assert held['preset']['ok'] == held['identified']['ok'] == 1
    assert 0.0 < held['preset']['mean'] < 0.03 and 0.0 < held['identified']['mean'] < 0.03
    task = summary['tasks'][0]
    assert task['file'].endswith('task.yaml') and len(task['sha256']) == 64
    assert summary['gripper_frames'] == 'left_gripper,right_gripper'
    assert summary['cloth_mesh'] is None and summary['table_z'] is None
    # about the recording's own noise (run's CD_d of this motion on this grid is ~0.017 m)
    assert 0.0 < summary['value'] < 0.03 and 0.0 < summary['preset_value'] < 0.03
    problem = json.loads((out / 'problem.json').read_text())
    assert list(problem.values())[0]['tasks'] == [task['sha256']]
    # another table height is another task file: the journal is not resumed on it
    again = cli_process('identify', '--bag', str(motions / 'swing'), *GRIPPERS, *TINY,
                        '--table-z', '0.7', '--output', str(out))
    assert_one_line_error(again, 'another problem', 'task file')


def test_identify_and_rank_refuse_a_recording_of_another_motion_as_run_does(motions, tmp_path):
    bag = str(motions / 'swing')
    run = cli_process('run', '--bag', bag, '--topic', '/points')
    identify = cli_process('identify', '--bag', bag, '--topic', '/points', '--output',
                           str(tmp_path / 'i'))
    rank = cli_process('rank', bag, str(motions / 'small_swing'), '--topic', '/points',
                       '--output', str(tmp_path / 'r'))
    assert_one_line_error(run, 'does not match the task dynamic', '--gripper-frames')
    line = run.stderr.strip()
    for result in (identify, rank):
        assert_one_line_error(result, 'does not match the task dynamic')
        assert result.stderr.strip() == line


@pytest.mark.slow
def test_rank_pools_two_recorded_motions_checks_across_them_and_recomputes_a_changed_task(
    motions, tmp_path, capsys
):
    out = tmp_path / 'rank'
    argv = ['rank', str(motions / 'swing'), str(motions / 'small_swing'), *GRIPPERS, *TINY,
            '--seeds', '1', '--recommend-rate', '100', '--output', str(out)]
    assert cli.main(argv) == 0
    printed = capsys.readouterr().out
    assert 'cells: 5 (0 kept from an earlier run)' in printed
    assert 'fitted on other motions, scored on 2 held-out runs' in printed
    result = json.loads((out / 'rank.json').read_text())
    group = result['groups']['towel_dynamic']
    assert len(group['trials']) == 2 and group['motions'] == 2  # pooled: one cloth
    shas = {t['task_sha256'] for t in result['trials']}
    assert len(shas) == 2 and '' not in shas
    assert result['spec']['gripper_frames'] == 'left_gripper,right_gripper'
    assert [t['sha256'] for t in result['spec']['tasks']] != []
    held = [c for c in result['cells'] if c['kind'] == 'held_out']
    assert held and all(c['other_motion'] for c in held)
    assert all(0.0 < c['CD'] < 0.03 for c in held), [c['CD'] for c in held]
    cross = result['answer']['towel_dynamic']['cross_motion']['mujoco']
    assert cross['mean'] == pytest.approx(
        sum(c['CD'] for c in held if c['config'] == 'identified') / 2)
    assert cli.main(argv) == 0  # the same: every cell kept
    assert 'cells: 5 (5 kept from an earlier run)' in capsys.readouterr().out
    assert cli.main([*argv, '--table-z', '0.74']) == 0  # other task files: computed again
    printed = capsys.readouterr().out
    assert 'cells: 5 (0 kept from an earlier run)' in printed
    assert 'identified again' in printed


@pytest.fixture(scope='module')
def garment(tmp_path_factory):
    """Return a T-shirt mesh and its MuJoCo-direct reference along the fling (helpers beside)."""
    from test_cloth_mesh import t_shirt, write_mesh
    from test_cloth_mesh_reference import reference_states, write_reference_bag

    folder = tmp_path_factory.mktemp('garment')
    vertices, faces = t_shirt()
    mesh = write_mesh(folder / 'shirt.obj', vertices, faces)
    reference, other = (reference_states(vertices, faces, seed) for seed in (1, 2))
    bag, _ = write_reference_bag(folder / 'bag', reference, faces, other)
    return mesh, bag


@pytest.mark.slow
def test_identify_on_a_mesh_records_it_and_never_resumes_another_mesh(garment, tmp_path, capsys):
    mesh, bag = garment
    out = tmp_path / 'identify'
    argv = ['identify', '--bag', str(bag), '--topic', '/points', '--start-time', '0', '--clean',
            'off', '--engine', 'mujoco', '--trials', '2', '--sampler', 'tpe', '--workers', '1',
            '--no-progress', '--output', str(out)]
    assert cli.main([*argv, '--cloth-mesh', str(mesh)]) == 0
    assert f'cloth: mesh {mesh}, ' in capsys.readouterr().out
    summary = json.loads((out / 'identification.json').read_text())
    assert summary['cloth_mesh']['file'] == str(mesh)
    assert 0.0 < summary['preset_value'] < 0.02  # the garment's own (the rectangle: far above)
    other = tmp_path / 'shirt.obj'  # the same garment, other bytes: another file
    other.write_text(mesh.read_text() + '# edited\n')
    again = cli_process(*argv, '--cloth-mesh', str(other))
    assert_one_line_error(again, 'another problem', 'cloth mesh')


@pytest.mark.parametrize('command', ['identify', 'rank'])
def test_identify_and_rank_refuse_a_start_searched_with_an_engine(command, tmp_path, capsys):
    bag = str(tmp_path / 'no_bag')  # refused before any bag is read
    argv = ([command, '--bag', bag] if command == 'identify' else [command, bag])
    assert cli.main([*argv, '--align', 'simulation', '--output', str(tmp_path / 'o')]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and '--align simulation' in err and 'without an' in err
