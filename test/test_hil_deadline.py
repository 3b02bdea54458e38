"""
The deadline said out loud: the one deadline rule, the warm-up check, the remedy, --find-rate.

Real engines on tiny meshes and short stretches of the trajectory, all nodes in one process; a
configuration made slow on purpose (MuJoCo with 50 internal steps per step) stands for one that
cannot keep up.
"""

from __future__ import annotations

import json
import math
import re

from cloth_bench_ros.cli import main
from cloth_bench_ros.core.deadline import (
    cd_tolerance,
    deadline_check,
    deadline_rule,
    holds_rate,
    within_tolerance,
)
from cloth_bench_ros.core.trajectory import full_targets
from cloth_bench_ros.hil.config import HilConfig
from cloth_bench_ros.hil.warmup import coarser_grids, warmup
from cloth_bench_ros.sweep.recommend import meets_deadline
import pytest

pytestmark = pytest.mark.timing  # wall-clock behaviour: run alone (conftest.py)

SLOW = ['--set', 'mujoco.substeps=50']  # 50 internal steps per step: milliseconds on 4 x 5


def test_the_deadline_rule_judges_the_step_p99_against_the_budgeted_period():
    at_1k = deadline_check(0.4e-3, 1000.0)  # budget 0.5: 0.5 ms allowed
    assert at_1k.meets and not at_1k.exceeds_period
    assert at_1k.rate_met_hz == pytest.approx(1250.0)
    late = deadline_check(0.7e-3, 1000.0)
    assert not late.meets and not late.exceeds_period and 'over 0.5 x' in late.verdict()
    over = deadline_check(1.09e-3, 1000.0)
    assert over.exceeds_period and 'exceeds the 1 ms period' in over.verdict()
    assert deadline_check(0.7e-3, 1000.0, budget=0.8).meets  # the budget is the rule's knob
    assert not deadline_check(math.nan, 100.0).meets  # not measured: not met
    # The recommendation's test is the same rule, its step times in ms.
    assert meets_deadline(0.4, 1000.0) and not meets_deadline(0.7, 1000.0)
    assert meets_deadline(0.7, 1000.0, 0.8) and not meets_deadline(math.nan, 1000.0)
    assert '0.5 x the period' in deadline_rule()


def test_a_rate_is_held_on_the_median_run_and_tolerance_is_one_test():
    assert holds_rate([0.0, 0.5, 0.001])  # one bad run of three does not decide
    assert not holds_rate([0.02, 0.0, 0.03])
    assert not holds_rate([0.01])  # at the threshold: not under it
    assert holds_rate([0.02], threshold=0.05)
    assert not holds_rate([]) and not holds_rate([math.nan])
    assert cd_tolerance(0.0272, 0.05, 0.002) == pytest.approx(0.002)  # 5 % is 1.4 mm
    assert cd_tolerance(0.1, 0.05, 0.002) == pytest.approx(0.005)
    assert within_tolerance(0.0284, 0.0272, 0.002) and not within_tolerance(0.0293, 0.0272, 0.002)
    assert not within_tolerance(math.nan, 0.0272, 0.002)


def test_warmup_times_the_engine_and_coarser_meshes_keep_the_aspect(hanging_bag):
    config = HilConfig('mujoco', 100.0, hanging_bag, grid=(4, 5), duration=0.3)
    timing = warmup(config)
    assert timing.grid == (4, 5) and timing.steps == 30  # 0.3 s at 100 Hz
    assert 0 < timing.p50_s <= timing.p99_s <= timing.max_s
    default = warmup(HilConfig('mujoco', 100.0, hanging_bag, duration=0.2))
    assert default.grid == (11, 15)  # the engine's own mesh when none is given
    assert coarser_grids((11, 15)) == [(9, 12), (7, 10), (6, 8), (4, 6)]
    assert coarser_grids((4, 5)) == [(4, 4)]


def _hil(hanging_bag, tmp_path, *extra: str) -> list[str]:
    return [
        'hil',
        '--bag',
        str(hanging_bag),
        '--in-process',
        '--no-lockstep',
        '--engine',
        'mujoco',
        '--grid',
        '4x5',
        '--output',
        str(tmp_path / 'o'),
        *extra,
    ]


def test_a_configuration_slower_than_the_period_is_said_before_the_run_with_a_remedy(
    hanging_bag, tmp_path, capsys
):
    code = main(_hil(hanging_bag, tmp_path, '--rate', '1000', '--duration', '0.1', *SLOW))
    out = capsys.readouterr().out
    assert code == 0, out
    lines = out.splitlines()
    assert any(line.startswith('deadline rule: ') for line in lines)
    warm = next(i for i, line in enumerate(lines) if 'warm-up on this machine' in line)
    run = next(i for i, line in enumerate(lines) if line.startswith('  simulator process:'))
    assert warm < run  # said before the real-time run
    assert 'exceeds the 1 ms period at 1000 Hz' in lines[warm]
    remedy = lines[-1]  # the output ends with what would meet the rate
    assert remedy.startswith('to meet 1000 Hz with mujoco (') and 'over 1 %' in remedy
    rows = [json.loads(line) for line in (tmp_path / 'o' / 'hil.jsonl').read_text().splitlines()]
    said = re.search(r'\((\d+) of (\d+) targets late or skipped, ([\d.]+) %', remedy)
    f = rows[-1]  # the count is the table's misses and skipped targets together
    assert said and int(said[1]) == f['deadline_misses'] + f['skipped'] + f['lost'], remedy
    assert int(said[2]) == f['targets'] and float(said[3]) == pytest.approx(
        100 * int(said[1]) / f['targets'], abs=0.006
    )
    assert 'a lower rate: this configuration meets the rule up to' in remedy
    assert '--find-rate --engine mujoco --grid 4x5' in remedy


def test_a_configuration_well_within_the_period_gets_neither_line(hanging_bag, tmp_path, capsys):
    code = main(_hil(hanging_bag, tmp_path, '--rate', '10', '--duration', '0.5'))
    out = capsys.readouterr().out
    assert code == 0, out
    warm = next(line for line in out.splitlines() if 'warm-up on this machine' in line)
    assert 'is under 0.5 x the 100 ms period at 10 Hz' in warm and 'exceeds' not in out
    assert 'to meet 10 Hz' not in out


@pytest.mark.slow
def test_find_rate_bisects_to_the_highest_rate_held_for_each_mesh(hanging_bag, tmp_path, capsys):
    code = main(
        _hil(
            hanging_bag,
            tmp_path,
            '--grid',
            '5x7',
            '--find-rate',
            '--rate-min',
            '5',
            '--rate-max',
            '500',
            '--rate-tolerance',
            '1.0',
            '--repeats',
            '1',
            '--duration',
            '0.4',
            *SLOW,
        )
    )
    out = capsys.readouterr().out
    assert code == 0, out
    assert 'bisection on a log scale to within 100 %' in out and 'deadline rule: ' in out
    data = json.loads((tmp_path / 'o' / 'find_rate.json').read_text())
    assert data['options']['repeats'] == 1 and data['options']['rate_max_hz'] == 500.0
    rows = data['results']
    assert [(r['engine'], r['grid']) for r in rows] == [('mujoco', '4x5'), ('mujoco', '5x7')]
    for r in rows:
        probes = {p['rate_hz']: p['held'] for p in r['probes']}
        assert probes[5.0] and not probes[500.0]  # 50 internal steps cannot hold 2 ms periods
        low, high = r['bracket_hz']
        assert r['rate_hz'] == low and 5.0 <= low < high <= 500.0 and high / low <= 2.0
        # Bisection: every rate tried at or under the one found was held, every one above not.
        assert all(held == (rate <= low) for rate, held in probes.items())
        assert len(probes) <= 2 + math.ceil(math.log2(math.log(100) / math.log(2)))
        assert r['miss_fraction'] < 0.01 and r['latency_p999'] > 0
        assert r['warmup_step_p99'] > 0 and r['rule_rate_hz'] > 0
        assert f'mujoco  {r["grid"]}' in out
    assert main(_hil(hanging_bag, tmp_path, '--find-rate', '--rate', '100')) == 2
    assert main(_hil(hanging_bag, tmp_path, '--grid', '5x7', '--rate', '100')) == 2
    assert main(_hil(hanging_bag, tmp_path, '--find-rate', '--rate-min', '100',
                     '--rate-max', '50')) == 2


@pytest.mark.slow
def test_the_remedy_names_the_recommended_configuration_when_it_meets_the_rule(
    hanging_bag, tmp_path, capsys
):
    # A fine mesh at 100 Hz misses; the shipped 100 Hz recommendation (9 x 12) steps far faster.
    # A generous budget keeps a loaded machine's preemptions from deciding the recommendation's
    # warm-up.
    args = _hil(hanging_bag, tmp_path, '--rate', '100', '--duration', '0.3')
    args[args.index('4x5')] = '25x35'
    code = main([*args, '--deadline-budget', '3'])
    out = capsys.readouterr().out
    assert code == 0, out
    assert 'step p99 is under 3 x the period' in out  # the rule as this run applies it
    remedy = out.splitlines()[-1]
    assert remedy.startswith('to meet 100 Hz with mujoco ('), out
    assert '`--config recommended` (grid=9x12' in remedy and 'warm-up step p99' in remedy


@pytest.mark.slow
def test_a_whole_run_ends_when_its_last_target_falls_before_the_motions_end(
    hanging_bag, tmp_path, capsys
):
    # At 15.3993 Hz the last target is 4.338 s into the motion, before the recording's last frame
    # (4.367 s): that frame is after the trajectory, not a frame the run waits for forever.
    rate = 15.3993
    targets = full_targets('dynamic', rate)
    last_s = targets.stamp_ns(len(targets) - 1) / 1e9 - targets.quintic_start
    assert last_s < 131 / 30
    code = main(_hil(hanging_bag, tmp_path, '--rate', str(rate)))
    out = capsys.readouterr().out
    assert code == 0, out
    (summary,) = (tmp_path / 'o').glob('*/summary.json')
    accounting = json.loads(summary.read_text())['real']['accounting']
    assert accounting['adds_up'] and accounting['not_received'] == 0, accounting
    assert accounting['after_trajectory'] == 1 and accounting['scored'] > 100, accounting


def test_a_run_that_does_not_finish_in_time_is_one_line_not_a_bug(tmp_path, capsys, monkeypatch):
    """A starved process (a loaded machine) is said as such, never as an internal error."""
    from cloth_bench_ros.hil import groups as hil_groups

    monkeypatch.setattr(hil_groups, '_time_budget', lambda config: 0.0)
    code = main(['hil', '--engine', 'mujoco', '--rate', '100', '--grid', '4x5', '--no-lockstep',
                 '--output', str(tmp_path / 'hil')])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1, err
    assert 'did not finish in time' in err and 'internal error' not in err
