"""The stress suite: hard cases on the real engines; divergence is found, reported, never fatal."""

from __future__ import annotations

import json
import math

from cloth_bench_ros.cli import main
from cloth_bench_ros.core import scene
from cloth_bench_ros.core.trajectory import full_targets
from cloth_bench_ros.engines import engine_class
from cloth_bench_ros.engines.presets import load_preset
from cloth_bench_ros.studies.stress import load_stress, run_case, verdict
from cloth_bench_ros.studies.stress_cases import case_targets, default_cases, StressCase
import numpy as np
import pytest

ISSUE_CASES = {
    'fling_10hz',
    'stiff_cloth',
    'light_cloth',
    'fast_drag_into_table',
    'large_dt_high_damping',
}


def test_the_suite_has_the_issue_cases_for_every_engine_with_real_parameter_names():
    cases = default_cases(['mujoco', 'bullet', 'newton'])
    for engine in ('mujoco', 'bullet', 'newton'):
        names = {c.name for c in cases if c.engine == engine}
        assert ISSUE_CASES <= names and len(names) >= 8
    for c in cases:  # every override passes the engine's own schema on top of the preset
        engine_class(c.engine).validate_params(
            {**load_preset(c.engine, 'towel', c.primitive), **c.params}
        )


def test_case_trajectories_are_transformed_as_described():
    by = {c.name: c for c in default_cases(['mujoco'])}
    drag = by['fast_drag_into_table']
    left, right, q, dt = case_targets(drag)
    assert len(left) == len(
        full_targets('quasi_static', 100.0 / 5)
    )  # 5x faster: a fifth of the steps
    assert min(left[:, 2].min(), right[:, 2].min()) == pytest.approx(scene.TABLE_TOP_Z - 0.02)
    assert dt == pytest.approx(0.01)
    jump = by['gripper_jump']
    left, right, q, _ = case_targets(jump)
    gap = right[:, 0] - left[:, 0]
    assert gap[q] == pytest.approx(0.478) and gap[-1] == pytest.approx(0.778)
    assert np.count_nonzero(np.diff(gap) > 0.1) == 1  # in one step


def test_a_case_that_cannot_be_built_is_an_error_row_not_an_exception():
    row = run_case(StressCase('bad_mass', 'mujoco', 'negative mass', params={'mass': -1.0}))
    assert row['status'] == 'error' and 'mass' in row['error'] and not row['diverged']


def test_a_diverging_case_reports_its_step_speed_and_reason():
    case = next(c for c in default_cases(['mujoco']) if c.name == 'large_dt_high_damping')
    row = run_case(case)
    assert row['status'] == 'diverged' and row['diverged']
    assert row['diverged_at_step'] == row['steps'] >= 1
    assert row['diverged_reason'] and row['max_vertex_speed'] > 0
    assert row['step_time_mean'] > 0


@pytest.mark.slow
def test_cli_stress_finds_a_diverging_case_per_engine_and_exits_0(tmp_path, capsys):
    code = main(
        [
            'stress',
            '--case',
            'fling_10hz',
            '--case',
            'stiff_cloth',
            '--workers',
            '2',
            '--no-progress',
            '--output',
            str(tmp_path),
        ]
    )
    out = capsys.readouterr().out
    assert code == 0, out
    rows = load_stress(tmp_path)
    assert len(rows) == 6 and {r['status'] for r in rows} <= {
        'ok',
        'diverged',
    }  # mujoco, bullet, newton
    v = verdict(rows)
    assert v['mujoco'] and v['bullet']  # at least one diverging case per engine
    assert 'stiff_cloth' in v['mujoco'] and 'fling_10hz' in v['bullet']
    calm = next(r for r in rows if r['engine'] == 'mujoco' and r['case'] == 'fling_10hz')
    assert calm['status'] == 'ok' and calm['steps'] == 74
    assert math.isfinite(calm['L_s']) and calm['L_s'] > 0 and 0 < calm['max_vertex_speed'] < 100
    for r in rows:
        if r['diverged']:
            assert r['diverged_at_step'] >= 1 and r['diverged_reason']
    assert 'mujoco: 1 of 2 cases diverged (stiff_cloth)' in out
    assert (tmp_path / 'stress.md').read_text().count('\n') == 2 + 6
    json.loads((tmp_path / 'stress.jsonl').read_text().splitlines()[0])


def test_cli_stress_lists_cases_and_refuses_unknown_ones(capsys):
    assert main(['stress', '--list']) == 0
    assert 'fast_drag_into_table' in capsys.readouterr().out
    assert main(['stress', '--case', 'nope']) == 2
    assert 'unknown stress case nope' in capsys.readouterr().err


@pytest.mark.parametrize('value', ['-1', 'nan', '0', 'inf'])
def test_cli_stress_refuses_a_bad_wall_time_budget(capsys, value):
    with pytest.raises(SystemExit) as exit_:  # argparse's one-line usage error
        main(['stress', '--max-wall-s', value, '--list'])
    err = capsys.readouterr().err
    assert (
        exit_.value.code == 2
        and 'argument --max-wall-s' in err
        and len(err.strip().splitlines()) == 1
    )
