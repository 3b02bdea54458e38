"""The hardware-in-the-loop layout: the machine's measured best by default, in one line."""

from __future__ import annotations

import json

from cloth_bench_ros.cli import main
from cloth_bench_ros.hil.layout import (
    choose_layout,
    fifo_permitted,
    FIFO_PRIORITY,
    resolve_layout,
    usable_cpus,
)
import pytest


def test_two_cores_and_fifo_give_the_polling_step_loop_its_core():
    layout = choose_layout([0, 1], fifo_ok=True)
    assert (layout.cpu, layout.fifo, layout.busy_wait) == (1, FIFO_PRIORITY, True)
    assert (
        'polling on core 1 of its own' in layout.line()
        and f'SCHED_FIFO {FIFO_PRIORITY}' in layout.line()
    )


def test_without_fifo_the_layout_says_why_and_keeps_the_core():
    layout = choose_layout([2, 5, 7], fifo_ok=False)
    assert (layout.cpu, layout.fifo, layout.busy_wait) == (7, 0, True)
    assert 'SCHED_FIFO not permitted' in layout.line() and 'ulimit -r' in layout.line()


def test_one_core_falls_back_to_a_sleeping_step_loop():
    layout = choose_layout([0], fifo_ok=True)
    assert (layout.cpu, layout.busy_wait) == (-1, False)
    assert 'one usable core' in layout.line()


def test_flags_override_the_layout_and_none_is_none():
    none = resolve_layout('none', None, None, None)
    assert (none.cpu, none.fifo, none.busy_wait) == (-1, 0, False)
    given = resolve_layout('none', 0, 10, True)
    assert (given.cpu, given.fifo, given.busy_wait) == (
        0,
        10,
        True,
    ) and 'flags on top' in given.why
    with pytest.raises(ValueError, match='--busy-wait needs a core'):
        resolve_layout('none', None, None, True)
    auto = resolve_layout('auto', None, None, None)
    assert auto == choose_layout(usable_cpus(), fifo_permitted())


@pytest.mark.slow
def test_the_default_hil_command_prints_its_layout_and_the_observer_misses_no_state(
    tmp_path, capsys
):
    out = tmp_path / 'hil'
    code = main(
        [
            'hil',
            '--engine',
            'mujoco',
            '--rate',
            '100',
            '--grid',
            '6x8',
            '--no-lockstep',
            '--output',
            str(out),
        ]
    )
    printed = capsys.readouterr().out
    expected = choose_layout(usable_cpus(), fifo_permitted())
    assert expected.line() in printed
    row = json.loads((out / 'hil.jsonl').read_text().splitlines()[-1])
    assert row['observer_states'] == row['stepped'] - 1 and not row['problems'], row['problems']
    assert code == 0
