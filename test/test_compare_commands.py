"""benchmarks/compare_outputs.py on tiny hand-made records: a timing passes, a number fails."""

from __future__ import annotations

import json
from pathlib import Path
import sys

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'benchmarks'))

from compare_outputs import compare_records  # noqa: E402
import pytest  # noqa: E402

STDOUT = """cloth-bench run: towel dynamic at 100 Hz, bag {root}/repo/bags/towel_dynamic
engine         CD_d     HD_d        L_s  step mean      p50      p99      max  status
-------------------------------------------------------------------------------------
mujoco       0.0446   0.1645  0.0000745      {step}    0.512    1.363    1.572  ok
sweep: 4 cells run in {wall} s (0 already done), 0 diverged
| engine | case | diverged at step | step mean (ms) | steps |
| --- | --- | ---: | ---: | ---: |
| bullet | fling_10hz | 24 | {step} | 24 |
report: {root}/rec/run/work/out/summary.json
"""


def write_record(root: Path, cd: float = 0.0446, step: str = '0.623', wall: str = '3.9',
                 stderr: str = '') -> Path:
    """Write a record of one command `run` as compare_commands.py does, under root/rec."""
    record = root / 'rec'
    command = record / 'run'
    (command / 'work' / 'out').mkdir(parents=True)
    (record / 'record.json').write_text(json.dumps({
        'record': str(record), 'repo': str(root / 'repo'), 'python': str(root / 'py/bin/python'),
        'commands': ['run'], 'date': f'2026-11-28 14:{wall[0]}0:00'}))
    (command / 'command.json').write_text(json.dumps({
        'name': 'run', 'argv': ['run', '--output', str(command / 'work' / 'out')],
        'exit_code': 0, 'wall_s': float(wall)}))
    (command / 'stdout.txt').write_text(STDOUT.format(root=root, step=step, wall=wall))
    (command / 'stderr.txt').write_text(stderr)
    summary = {'engines': {'mujoco': {'CD_d': cd, 'step_time': {'mean': float(step) / 1e3},
                                      'frames_scored': 132}}}
    (command / 'work' / 'out' / 'summary.json').write_text(json.dumps(summary))
    (command / 'work' / 'out' / 'frames.csv').write_text(
        f'engine,frame,cd,wall_s\nmujoco,0,{cd},{wall}\n')
    (command / 'work' / 'out' / 'report.html').write_text(
        '<table><thead><tr><th>engine</th><th>step p99 ms</th><th>CD_d (m)</th></tr></thead>\n'
        f'<tr><td>MuJoCo</td><td class="num">{step}</td><td class="num">{cd}</td></tr></table>\n')
    return record


def test_the_same_outputs_are_the_same(tmp_path, capsys):
    old = write_record(tmp_path / 'a')
    new = write_record(tmp_path / 'b')
    assert compare_records(old, new) == 0
    assert 'run                          same' in capsys.readouterr().out


def test_only_timings_and_dates_changed_is_the_same(tmp_path, capsys):
    old = write_record(tmp_path / 'a')
    new = write_record(tmp_path / 'b', step='12.871', wall='5.2')  # another column width
    assert compare_records(old, new) == 0
    assert 'run                          same' in capsys.readouterr().out


def test_a_changed_number_differs_and_is_named(tmp_path, capsys):
    old = write_record(tmp_path / 'a')
    new = write_record(tmp_path / 'b', cd=0.0446000001)
    assert compare_records(old, new) == 1
    out = capsys.readouterr().out
    assert 'run                          DIFFERENT' in out
    assert '.engines.mujoco.CD_d: 0.0446 -> 0.0446000001' in out
    assert '-mujoco,0,0.0446,<t>' in out and '+mujoco,0,0.0446000001,<t>' in out  # the CSV
    assert 'report.html: -| MuJoCo | <t> | 0.0446 |' in out


@pytest.mark.parametrize('where', ['stdout', 'exit'])
def test_a_changed_table_value_or_exit_code_differs(tmp_path, capsys, where):
    old = write_record(tmp_path / 'a')
    new = write_record(tmp_path / 'b')
    command = new / 'run'
    if where == 'stdout':
        text = (command / 'stdout.txt').read_text()
        (command / 'stdout.txt').write_text(text.replace('| 24 | ', '| 25 | '))
    else:
        meta = json.loads((command / 'command.json').read_text())
        (command / 'command.json').write_text(json.dumps({**meta, 'exit_code': 2}))
    assert compare_records(old, new) == 1
    assert ('| 25 |' if where == 'stdout' else 'exit code 0 -> 2') in capsys.readouterr().out


def test_a_deprecation_note_is_listed_apart(tmp_path, capsys):
    old = write_record(tmp_path / 'a')
    note = 'cloth-bench: --out is deprecated, use --output'
    new = write_record(tmp_path / 'b', stderr=note + '\n')
    assert compare_records(old, new) == 0
    assert f'deprecated (expected after a rename): run: {note}' in capsys.readouterr().out
