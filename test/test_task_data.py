"""A task as data: the shipped files give the paper's motion, a user's its own, bad ones a line."""

import math

from cloth_bench_ros.core.task_data import load_task, task_file
from cloth_bench_ros.core.trajectory import full_targets, sample_quintic, to_csv
from cloth_bench_ros.errors import InputError
import numpy as np
import pytest
from test_cli import assert_one_line_error, cli
import yaml

# A motion of the test's own, in the documented format: both arms lift 0.1 m in 1 s, then the
# right one moves 0.05 m back along y in 0.5 s; the roll turns by 10 degrees and holds.
OWN_TASK = """
settle: {hold_start: 0.5, move: 0.5, hold_end: 0.25}
grasp: {left: [0.02, 0.0, 1.0], right: [0.498, 0.0, 1.0]}
motion:
  left: {x: 0.0, y: 0.0, z: [{duration: 1.0, start: [0, 0, 0], end: [0.1, 0, 0]}]}
  right:
    x: 0.0
    y:
      - {duration: 1.0, start: [0, 0, 0], end: [0, 0, 0]}
      - {duration: 0.5, start: [0, 0, 0], end: [-0.05, 0, 0]}
    z: [{duration: 1.0, start: [0, 0, 0], end: [0.1, 0, 0]}]
  roll: [{duration: 1.0, start: [-180, 0, 0], end: [-170, 0, 0]}]
  pitch: 0.0
  yaw: 0.0
window: whole_motion
"""


def _write(tmp_path, text, name='own.yaml'):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_own_task_file_is_followed(tmp_path):
    task = load_task('dynamic', _write(tmp_path, OWN_TASK))
    assert task.duration == 1.5 and task.settle_duration == 1.25 and task.suffix == 'q'
    tg = full_targets(task, 100.0)
    q = tg.quintic_index
    assert q == 125 and tg.quintic_start == 1.25
    assert tg.left[q] == pytest.approx([0.02, 0.0, 1.0])
    assert tg.left[-1] == pytest.approx([0.02, 0.0, 1.1])  # its chain ended at 1 s: held
    assert tg.right[-1] == pytest.approx([0.498, -0.05, 1.1])
    assert tg.roll[-1] == pytest.approx(math.radians(-170))
    assert len(tg) == 276


def test_a_copy_of_the_shipped_file_gives_the_same_samples(tmp_path):
    copy = _write(tmp_path, task_file('dynamic').read_text(), 'fling.yaml')
    own = sample_quintic(load_task('dynamic', copy), 250.0)
    shipped = sample_quintic('dynamic', 250.0)
    assert to_csv(own) == to_csv(shipped)
    assert load_task('dynamic', copy).record()['task_sha256'] == load_task('dynamic').sha256


@pytest.mark.parametrize('field,value,words', [
    (('window',), 'sometimes', ['window', 'sometimes']),
    (('settle', 'move'), -1.0, ['settle.move', '-1']),
    (('motion', 'left', 'z', 0, 'duration'), 0.0, ['motion.left.z[0].duration']),
    (('motion', 'right', 'y', 1, 'end'), [0, 0], ['motion.right.y[1].end']),
    (('grasp', 'left'), 'here', ['grasp.left']),
    (('motion', 'pitch'), float('nan'), ['motion.pitch']),
])
def test_a_bad_field_is_one_line_naming_file_and_field(tmp_path, field, value, words):
    doc = yaml.safe_load(OWN_TASK)
    at = doc
    for key in field[:-1]:
        at = at[key]
    at[field[-1]] = value
    path = _write(tmp_path, yaml.safe_dump(doc))
    with pytest.raises(InputError) as err:
        load_task('dynamic', path)
    message = str(err.value)
    assert '\n' not in message and str(path) in message
    for word in words:
        assert word in message


def test_unknown_and_missing_keys_are_named(tmp_path):
    with pytest.raises(InputError, match='unknown key .speed.'):
        load_task('dynamic', _write(tmp_path, OWN_TASK + 'speed: 2\n'))
    with pytest.raises(InputError, match='missing key window'):
        load_task('dynamic', _write(tmp_path, OWN_TASK.replace('window: whole_motion', '')))


def test_cli_trajectory_takes_a_task_file_and_refuses_a_bad_one(tmp_path):
    good = cli('trajectory', '--task', str(_write(tmp_path, OWN_TASK)), '--rate', '10')
    assert good.returncode == 0, good.stderr
    rows = good.stdout.splitlines()
    assert len(rows) == 17 and float(rows[-1].split(',')[7]) == pytest.approx(1.1)
    bad = _write(tmp_path, OWN_TASK.replace('whole_motion', 'often'), 'bad.yaml')
    assert_one_line_error(cli('trajectory', '--task', str(bad)), 'bad.yaml', 'window')
    assert_one_line_error(cli('trajectory', '--task', str(tmp_path / 'none.yaml')), 'none.yaml')


def test_shipped_tasks_keep_the_papers_windows():
    assert load_task('dynamic').window == 'before_table_contact'
    assert load_task('quasi_static').window == 'whole_motion'
    assert np.isclose(load_task('quasi_static').duration, 14.0)


def test_a_recorded_motion_file_is_checked_as_a_task_file(tmp_path):
    doc = {
        'settle': {'hold_start': 1.0, 'move': 1.0, 'hold_end': 1.0},
        'recorded': {
            'source': 'tf frames l,r', 'frame': 'base', 'start_ns': 10**18,
            'to_scene': [1.0, 0, 0, 0, 0, 1.0, 0, 0, 0, 0, 1.0, 0, 0, 0, 0, 1.0],
            'table_z': None, 'table_source': 'none', 't': [0.0, 0.5, 1.0],
            'left': [[0, 0, 1], [0, 0.1, 1], [0, 0.2, 1]],
            'right': [[0.5, 0, 1], [0.5, 0.1, 1], [0.5, 0.2, 1]],
        },
        'window': 'before_table_contact',
    }
    task = load_task('dynamic', _write(tmp_path, yaml.safe_dump(doc)))
    tg = full_targets(task, 10.0)
    assert task.duration == 1.0 and tg.quintic_index == 30
    assert np.allclose(tg.left[:31], [0, 0, 1])  # settles where the grippers start
    assert tg.left[35] == pytest.approx([0, 0.1, 1])
    assert tg.right[-1] == pytest.approx([0.5, 0.2, 1])
    doc['recorded']['t'] = [0.0, 1.0, 0.5]
    with pytest.raises(InputError, match='recorded.t: the times must increase'):
        load_task('dynamic', _write(tmp_path, yaml.safe_dump(doc), 'bad.yaml'))
