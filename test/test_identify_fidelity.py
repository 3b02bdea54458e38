"""
Multi-fidelity identification: a trial pruned on the first part of the motion, and a pruned study.

Real MuJoCo on a target bag the engine made itself (short, coarse), real Optuna, a real Dask
LocalCluster.
"""

from __future__ import annotations

import json

from cloth_bench_ros import cli
from cloth_bench_ros.studies.identify import identify, IdentifySpec, TRIALS_FILE
from cloth_bench_ros.studies.identify_fidelity import STARTUP
from cloth_bench_ros.studies.objective import evaluate, Trial
from identify_target import write_engine_target_bag
import pytest

GRID = (5, 6)
TRUTH = {'damping': 3.0, 'timestep': 0.01}


@pytest.fixture(scope='module')
def target(tmp_path_factory):
    return write_engine_target_bag(
        tmp_path_factory.mktemp('fidelity') / 'target', 'mujoco', TRUTH, GRID, 40
    )


def _trial(target, **kw) -> Trial:
    params = tuple(sorted({'timestep': 0.01, 'damping': 0.5}.items()))
    return Trial('mujoco', 'towel', 'dynamic', str(target), params, grid=GRID, **kw)


def test_a_trial_reports_its_partial_value_and_stops_where_it_is_above_the_threshold(target):
    whole = evaluate(_trial(target, rung=0.25))
    assert whole['status'] == 'ok' and whole['frames'] == 40
    early = evaluate(_trial(target, max_frames=10))  # the first quarter, scored alone
    assert whole['partial'] == pytest.approx(early['value'], rel=1e-9)
    assert whole['partial'] != pytest.approx(whole['value'])
    kept = evaluate(_trial(target, rung=0.25, prune_above=whole['partial'] * 1.01))
    assert kept['status'] == 'ok' and kept['value'] == whole['value']
    pruned = evaluate(_trial(target, rung=0.25, prune_above=whole['partial'] * 0.99))
    assert pruned['status'] == 'pruned' and pruned['partial'] == whole['partial']
    assert pruned['cpu_s'] > 0 and pruned['frames'] == 0


def test_a_pruned_study_counts_pruned_trials_in_its_budget_and_tells_optuna(target, tmp_path):
    spec = IdentifySpec(
        'mujoco', 'towel', 'dynamic', target, tmp_path / 'out', 'tpe', STARTUP + 8, 'cd',
        ['damping'], grid=GRID, fixed={'timestep': 0.01}, batch=2, validate_seeds=0,
        fidelity='prune',
    )
    s = identify(spec, workers=2, progress=False).summary
    lines = (tmp_path / 'out' / TRIALS_FILE).read_text().splitlines()
    rows = sorted((json.loads(line) for line in lines), key=lambda r: r['number'])
    statuses = [r['status'] for r in rows]
    assert len(rows) == STARTUP + 8 == s['per_sampler']['tpe']['trials']
    assert 0 < statuses.count('pruned') == s['per_sampler']['tpe']['pruned'] <= 8
    assert all('partial' in r for r in rows)
    assert s['fidelity'] == 'prune' and s['value'] < rows[0]['value'] * 2
    curve = s['per_sampler']['tpe']['convergence']
    assert [row[1] is None for row in curve] == [st != 'ok' for st in statuses]
    assert cli.main(['report', str(tmp_path / 'out')]) == 0  # the report takes pruned trials
    assert (tmp_path / 'out' / 'report' / 'report.md').stat().st_size > 0
