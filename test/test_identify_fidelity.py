"""
Multi-fidelity identification: trials pruned early or screened on a coarser mesh, told in order.

Real MuJoCo on a target bag the engine made itself (short, coarse), real Optuna, a real Dask
LocalCluster.
"""

from __future__ import annotations

from dataclasses import replace
import json

from cloth_bench_ros import cli
from cloth_bench_ros.errors import InputError
from cloth_bench_ros.identify.fidelity import coarse_grids, Pruner, STARTUP
from cloth_bench_ros.identify.objective import evaluate, Trial
from cloth_bench_ros.identify.spec import IdentifySpec
from cloth_bench_ros.identify.study import identify, TRIALS_FILE
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


@pytest.mark.slow
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


@pytest.mark.slow
def test_pybullet_is_screened_on_one_halving_of_its_mesh_the_others_on_two():
    import optuna

    study = optuna.create_study()
    assert Pruner('coarse', study, None, None, 'mujoco').grids == ((3, 4), (6, 8))
    assert Pruner('coarse', study, None, None, 'newton').grids == ((3, 4), (6, 8))
    assert Pruner('coarse', study, None, None, 'bullet').grids == ((6, 8),)
    assert Pruner('coarse', study, (6, 8), None, 'bullet').grids == ((3, 4),)
    assert Pruner('full', study, None, None, 'bullet').grids == ()


def test_coarse_rungs_score_the_whole_window_on_coarser_meshes_and_keep_the_full_value(
    target,
):
    assert coarse_grids(GRID) == ((3, 3),) and coarse_grids((6, 8)) == ((3, 4),)
    assert coarse_grids(None) == ((3, 4), (6, 8))  # the default 11 x 15 mesh: two rungs
    assert coarse_grids((41, 57)) == ((11, 15), (21, 29))  # at most two
    for mesh in ((3, 4), (3, 3)):  # 3 x 3 has more than half of 3 x 4's vertices
        with pytest.raises(InputError, match=f'{mesh[0]} x {mesh[1]} mesh has no coarser one'):
            coarse_grids(mesh)
    whole = evaluate(_trial(target))
    low = evaluate(replace(_trial(target), grid=(3, 3)))
    kept = evaluate(_trial(target, ladder=(((3, 3), low['value'] * 1.01),)))
    assert kept['status'] == 'ok' and kept['frames'] == 40
    assert kept['value'] == whole['value'] and kept['partial'] == low['value'] != whole['value']
    assert kept['partials'] == [low['value']]
    assert kept['cpu_s'] > low['cpu_s'] and kept['step_p50_ms'] > 0
    pruned = evaluate(_trial(target, ladder=(((3, 3), low['value'] * 0.99),)))
    assert pruned['status'] == 'pruned' and pruned['partial'] == low['value']
    assert pruned['frames'] == 0 and pruned['cpu_s'] > 0 and 'step_p50_ms' not in pruned
    assert '3 x 3 mesh' in pruned['reason']
    two = evaluate(_trial(target, ladder=(((3, 3), None), ((4, 5), 0.0))))  # pruned at the 2nd
    assert two['status'] == 'pruned' and two['partials'][0] == low['value']
    assert len(two['partials']) == 2 and '4 x 5 mesh' in two['reason']


def _rows(out):
    lines = (out / TRIALS_FILE).read_text().splitlines()
    return [json.loads(line) for line in lines]


@pytest.mark.slow
def test_a_coarse_study_is_told_in_trial_order_and_gives_the_same_trials_again(target, tmp_path):
    def run(out):
        spec = IdentifySpec(
            'mujoco', 'towel', 'dynamic', target, out, 'tpe', STARTUP + 6, 'cd',
            ['damping', 'young'], grid=GRID, fixed={'timestep': 0.01}, batch=3,
            validate_seeds=0, fidelity='coarse',
        )
        return identify(spec, workers=2, progress=False).summary

    first, again = run(tmp_path / 'a'), run(tmp_path / 'b')
    rows, rows_again = _rows(tmp_path / 'a'), _rows(tmp_path / 'b')
    assert [r['number'] for r in rows] == list(range(STARTUP + 6))  # told in order
    key = [(r['params'], r['status'], r['value'], r['partial']) for r in rows]
    assert key == [(r['params'], r['status'], r['value'], r['partial']) for r in rows_again]
    statuses = [r['status'] for r in rows]
    assert statuses[:STARTUP] == ['ok'] * STARTUP and 'pruned' in statuses
    assert first['fidelity'] == 'coarse' and first['params'] == again['params']
    assert first['per_sampler']['tpe']['pruned'] == statuses.count('pruned')


def test_cli_refuses_coarse_fidelity_on_the_coarsest_mesh_in_one_line(target, tmp_path, capsys):
    code = cli.main([
        'identify', '--bag', str(target), '--output', str(tmp_path), '--no-progress',
        '--grid', '3x3', '--fidelity', 'coarse', '--trials', '2',
    ])
    err = capsys.readouterr().err
    assert code == 2 and 'has no coarser one' in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / TRIALS_FILE).exists()
