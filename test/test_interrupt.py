"""
Ctrl-C during a study is ordinary use: one line, exit 130, workers gone, and a rerun resumes.

The CLI runs in its own session, as in a terminal; SIGINT goes to its whole process group (what
Ctrl-C does), after the first results are on disk.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
import signal
import subprocess
import sys
import time

import pytest

pytestmark = pytest.mark.timing  # wall-clock behaviour: run alone (conftest.py)

NOISE = ('Traceback', 'CancelledError', 'never awaited', 'Exception ignored')


def _cli(*args: str) -> list[str]:
    return [sys.executable, '-m', 'cloth_bench_ros.cli', *args]


def _lines(path: Path) -> int:
    return len(path.read_text().splitlines()) if path.exists() else 0


def interrupt_after_first_row(
    argv: list[str], rows: Path, timeout: float = 240.0
) -> tuple[int, str]:
    """Run argv in a new session, Ctrl-C its group once `rows` has a line; (status, stderr)."""
    proc = subprocess.Popen(
        argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True
    )
    deadline = time.monotonic() + timeout
    while _lines(rows) < 1 and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.2)
    assert proc.poll() is None, 'the study finished before it could be interrupted'
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    time.sleep(1.0)
    listed = subprocess.run(
        ['ps', '-o', 'stat=,pid=,args=', '-g', str(proc.pid)], capture_output=True, text=True
    ).stdout.splitlines()
    survivors = [
        line for line in listed if not line.strip().startswith('Z')
    ]  # zombies have exited
    assert not survivors, f'processes of the study left running: {survivors}'
    return proc.returncode, err


@pytest.mark.slow
def test_ctrl_c_during_a_sweep_keeps_finished_cells_and_resumes(tmp_path):
    out = tmp_path / 'sweep'
    args = [
        'sweep',
        '--engine',
        'mujoco',
        '--rate',
        '1000',
        '--cloth',
        'towel',
        '--primitive',
        'dynamic',
        '--seeds',
        '6',
        '--grid',
        '6x8',
        '--workers',
        '1',
        '--no-progress',
        '--output',
        str(out),
    ]
    code, err = interrupt_after_first_row(_cli(*args), out / 'results.jsonl')
    assert code == 130, err
    last = err.strip().splitlines()[-1]
    assert last.startswith('cloth-bench: sweep interrupted: ') and 'of 6 cells are in' in last
    assert 'run the same command again to resume' in last
    assert not any(word in err for word in NOISE), err
    kept = int(last.split('interrupted: ')[1].split(' of ')[0])
    assert 1 <= kept < 6 and _lines(out / 'results.jsonl') == kept
    done = subprocess.run(_cli(*args), capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    assert f'({kept} already done)' in done.stdout
    keys = [json.loads(line)['seed'] for line in (out / 'results.jsonl').read_text().splitlines()]
    assert sorted(keys) == list(range(6))  # every cell once


def _identify_args(out: Path, trials: int) -> list[str]:
    return [
        'identify',
        '--sampler',
        'tpe',
        '--trials',
        str(trials),
        '--grid',
        '6x8',
        '--max-frames',
        '10',
        '--validate-seeds',
        '0',
        '--workers',
        '1',
        '--batch',
        '1',
        '--no-progress',
        '--output',
        str(out),
    ]


@pytest.fixture(scope='module')
def interrupted_identification(tmp_path_factory) -> tuple[Path, int, str]:
    out = tmp_path_factory.mktemp('identify') / 'study'
    code, err = interrupt_after_first_row(_cli(*_identify_args(out, 60)), out / 'trials.jsonl')
    return out, code, err


@pytest.mark.slow
def test_ctrl_c_during_identify_is_one_line_and_exit_130(interrupted_identification):
    out, code, err = interrupted_identification
    assert code == 130, err
    last = err.strip().splitlines()[-1]
    assert (
        last.startswith('cloth-bench: identify interrupted: ')
        and 'run the same command again' in last
    )
    assert not any(word in err for word in NOISE), err


@pytest.mark.slow
def test_a_torn_journal_is_repaired_and_identify_resumes(interrupted_identification):
    out, _, _ = interrupted_identification
    journal = out / 'study.journal'
    kept = _lines(out / 'trials.jsonl')
    with journal.open('a') as f:
        f.write('garbage{')
    done = subprocess.run(
        _cli(*_identify_args(out, kept + 2)), capture_output=True, text=True, timeout=600
    )
    assert done.returncode == 0, done.stderr
    assert f'journal {journal} ended in a torn line' in done.stderr
    assert 'garbage' not in journal.read_text()
    assert (
        _lines(out / 'trials.jsonl') >= kept + 1
    )  # the complete trials were kept and more were run


def test_repair_journal_keeps_complete_lines_and_refuses_damage_in_the_middle(tmp_path):
    from cloth_bench_ros.identify.study import repair_journal

    journal = tmp_path / 'study.journal'
    journal.write_text('{"op_code": 0}\n{"op_code": 1}\n{"op_co')
    with pytest.warns(UserWarning, match='torn line'):
        assert repair_journal(journal) == len('{"op_co')
    assert journal.read_text() == '{"op_code": 0}\n{"op_code": 1}\n'
    assert repair_journal(journal) == 0  # intact: untouched
    journal.write_text('{"op_code": 0}\ngarbage{\n{"op_code": 1}\n')
    with pytest.raises(ValueError, match='damaged at line 2'):
        repair_journal(journal)


@pytest.mark.slow
def test_ctrl_c_during_rank_takes_its_one_cluster_down_and_keeps_the_trials(tmp_path):
    """Interrupted in its first fold's identification: one line, exit 130, no worker left."""
    from camera_recording import CAMERA_TOPIC, make_repeated_recording
    from cloth_bench_ros.paths import bundled_bag

    make_repeated_recording(bundled_bag('towel', 'dynamic'), tmp_path / 'rec' / 'two',
                            repetitions=2, rest_s=1.0, seed=4)
    out = tmp_path / 'rank'
    args = ['rank', str(tmp_path / 'rec'), '--topic', CAMERA_TOPIC, '--engine', 'mujoco',
            '--trials', '60', '--sampler', 'tpe', '--seeds', '1', '--grid', '6x8',
            '--recommend-rate', '100', '--max-frames', '6', '--workers', '1', '--no-progress',
            '--output', str(out)]
    trials = out / 'identify' / 'towel_dynamic' / 'mujoco' / 'fold1' / 'trials.jsonl'
    code, err = interrupt_after_first_row(_cli(*args), trials)
    assert code == 130, err
    last = err.strip().splitlines()[-1]
    assert last.startswith('cloth-bench: rank interrupted: ') and 'to resume' in last
    assert not any(word in err for word in NOISE), err
    assert _lines(trials) >= 1
