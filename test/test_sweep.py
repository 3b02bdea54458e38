"""Sweeps: cells, workers, resume, diverged and failed cells, settings mode; real engines."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
import shutil

from bag_fixtures import write_hanging_cloth_bag
from cloth_bench_ros.cli import main
from cloth_bench_ros.core.surface_metrics import SURFACE_REVISION
from cloth_bench_ros.sweep import study as sw
import pytest

GRID = (6, 8)


@pytest.fixture(scope='module')
def bag_dir(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp('sweep_bags')
    write_hanging_cloth_bag(d / 'towel_dynamic')
    write_hanging_cloth_bag(
        d / 'towel_quasi_static', frames=420, primitive='quasi_static', change_of_phase_frame=None
    )
    return d


# ------------------------------------------------------------------------------ cells


def test_paper_cells_are_the_product_with_unique_keys_and_frames_for_the_first_seed(bag_dir):
    cells = sw.paper_cells(
        ['mujoco', 'bullet'],
        [10, 100, 1000],
        ['towel'],
        ['dynamic', 'quasi_static'],
        range(3),
        bag_dir,
        GRID,
    )
    assert len(cells) == 2 * 3 * 2 * 3
    assert len({c.key() for c in cells}) == len(cells)
    assert len({c.ident() for c in cells}) == len(cells)
    assert {c.seed for c in cells if c.keep_frames} == {0}
    assert {c.config for c in cells} == {'grid=6x8'}
    assert all(Path(c.bag).parent == bag_dir for c in cells)


def test_step_per_target_sets_the_internal_step_to_the_rate(bag_dir):
    cells = sw.paper_cells(
        ['mujoco'], [10, 1000], ['towel'], ['dynamic'], [0], bag_dir, step_per_target=True
    )
    assert {c.rate_hz: c.params['timestep'] for c in cells} == {10.0: 0.1, 1000.0: 0.001}
    assert all(c.params['substeps'] == 1 and c.config == 'step=1/rate' for c in cells)


def test_find_bags_knows_bundled_and_importer_names_and_says_what_is_missing(tmp_path, bag_dir):
    for trial in (0, 2):
        (tmp_path / f'linen_{trial}_dynamic').mkdir()
    (tmp_path / 'linen_quasi_static_extra').mkdir()
    assert [t for t, _ in sw.find_bags(tmp_path, 'linen', 'dynamic')] == [0, 2]
    assert sw.find_bags(bag_dir, 'towel', 'quasi_static')[0][1].name == 'towel_quasi_static'
    with pytest.raises(ValueError, match='no bag named linen_quasi_static'):
        sw.find_bags(tmp_path, 'linen', 'quasi_static')


def test_settings_cells_are_a_factorial_over_the_axes_the_engine_has(bag_dir):
    axes = {
        'grid': [(6, 8), (11, 15)],
        'self_collision': [False, True],
        'timestep': [None, 0.005],
        'no_such_param': [1, 2],
    }
    cells = sw.settings_cells(['mujoco'], 100.0, ['towel'], ['dynamic'], [0, 1], bag_dir, axes)
    assert len(cells) == 2 * 2 * 2 * 2
    configs = {c.config for c in cells}
    assert 'grid=6x8,self_collision=off,timestep=preset' in configs
    assert 'grid=11x15,self_collision=on,timestep=0.005' in configs
    cell = next(c for c in cells if c.config == 'grid=11x15,self_collision=on,timestep=0.005')
    assert cell.grid == (11, 15) and cell.params == {'self_collision': True, 'timestep': 0.005}
    assert all(c.mode == 'settings' for c in cells)
    # Newton has every time-costing axis (mesh, substep, iterations, contacts) in its schema.
    axes = {
        'grid': [(6, 8), (11, 15)],
        'self_collision': [False, True],
        'timestep': [None, 0.005],
        'solver_iterations': [None, 5],
    }
    newton = sw.settings_cells(['newton'], 100.0, ['towel'], ['dynamic'], [0], bag_dir, axes)
    assert len(newton) == 2 * 2 * 2 * 2
    assert 'grid=6x8,self_collision=on,timestep=0.005,solver_iterations=5' in {
        c.config for c in newton
    }
    # Choice-valued settings (MuJoCo's solver) are named as they are.
    solvers = sw.settings_cells(
        ['mujoco'],
        1000.0,
        ['towel'],
        ['dynamic'],
        [0],
        bag_dir,
        {'solver': ['Newton', 'CG'], 'condim': [3, 1]},
    )
    assert {c.config for c in solvers} == {
        f'grid=default,solver={s},condim={d}' for s in ('Newton', 'CG') for d in (3, 1)
    }


def test_bad_overrides_and_grids_are_refused_before_any_work(bag_dir):
    with pytest.raises(ValueError, match='unknown mujoco parameter'):
        sw.paper_cells(
            ['mujoco'],
            [100],
            ['towel'],
            ['dynamic'],
            [0],
            bag_dir,
            overrides={'mujoco': {'nope': 1}},
        )
    with pytest.raises(ValueError, match='outside'):
        sw.paper_cells(
            ['mujoco'],
            [100],
            ['towel'],
            ['dynamic'],
            [0],
            bag_dir,
            overrides={'mujoco': {'mass': -1}},
        )
    with pytest.raises(ValueError):
        sw.parse_grid('1x5')
    assert sw.parse_grid('16X22') == (16, 22)
    assert sw.parse_overrides(
        ['mujoco.self_collision=on', 'bullet.mass=0.5', 'mujoco.model=edges']
    ) == {'mujoco': {'self_collision': True, 'model': 'edges'}, 'bullet': {'mass': 0.5}}
    with pytest.raises(ValueError, match='engine.param=value'):
        sw.parse_overrides(['mass=1'])


# --------------------------------------------------------------------- running, resume


def test_sweep_appends_rows_and_resumes_without_recomputing(bag_dir, tmp_path):
    cells = sw.paper_cells(['mujoco'], [100], ['towel'], ['dynamic'], [0, 1], bag_dir, GRID)
    first = sw.run_sweep(cells, tmp_path, workers=2, progress=False)
    assert (first.ran, first.skipped, first.errors) == (2, 0, 0)
    rows = sw.load_rows(tmp_path)
    assert sorted(r['seed'] for r in rows) == [0, 1]
    r0 = next(r for r in rows if r['seed'] == 0)
    assert r0['status'] == 'ok' and 0 < r0['CD'] <= r0['HD'] < 1 and r0['step_count'] == 740
    assert (
        r0['frames_csv'] and (tmp_path / r0['frames_csv']).is_file()
    )  # first seed keeps its frames
    assert next(r for r in rows if r['seed'] == 1)['frames_csv'] is None
    assert r0['substeps'] == 5 and r0['engine_version']

    again = sw.run_sweep(cells, tmp_path, workers=2, progress=False)
    assert (again.ran, again.skipped) == (0, 2)

    # A line torn by an interrupted sweep is skipped; growing the sweep runs only the new cells.
    with (tmp_path / sw.RESULTS_FILE).open('a') as f:
        f.write('{"engine": "mujoco", "rate_hz": 100')
    more = sw.paper_cells(['mujoco'], [100], ['towel'], ['dynamic'], [0, 1, 2], bag_dir, GRID)
    grown = sw.run_sweep(more, tmp_path, workers=2, progress=False)
    assert (grown.ran, grown.skipped) == (1, 2)
    assert sorted(r['seed'] for r in sw.load_rows(tmp_path)) == [0, 1, 2]


def test_a_cell_scores_the_papers_metrics_unless_asked_and_a_row_lacking_one_runs_again(
    tmp_path, capsys
):
    """CD/HD only by default; --metric emd or --all-metrics: every metric, replacing the row."""
    bags, out = tmp_path / 'bags', tmp_path / 'out'
    write_hanging_cloth_bag(bags / 'towel_dynamic', frames=40, change_of_phase_frame=30)
    command = ['sweep', '--bag-dir', str(bags), '--engine', 'mujoco', '--rate', '100', '--cloth',
               'towel', '--primitive', 'dynamic', '--seeds', '1', '--grid', '6x8', '--workers',
               '1', '--no-progress', '--output', str(out)]
    assert main(command) == 0
    (paper,) = sw.load_rows(out)
    assert paper['all_metrics'] is False and paper['surface_revision'] == 0
    assert 0 < paper['CD'] <= paper['HD'] and 'EMD' not in paper and 'F' not in paper
    assert main([*command, '--metric', 'emd']) == 0  # ranked on EMD: that row lacks it
    assert '(0 already done)' in capsys.readouterr().out
    (every,) = sw.load_rows(out)  # replaced, not beside the old one
    assert every['all_metrics'] is True and every['surface_revision'] == SURFACE_REVISION
    assert every['EMD'] > 0 and 0 <= every['F'] <= 1 and every['CD'] == paper['CD']
    assert main([*command, '--all-metrics']) == 0  # the same scoring: kept
    assert '(1 already done)' in capsys.readouterr().out and len(sw.load_rows(out)) == 1
    assert main(command) == 0  # a row with every metric serves a cell that asks for CD/HD
    assert '(1 already done)' in capsys.readouterr().out
    assert [(r['all_metrics'], r['EMD']) for r in sw.load_rows(out)] == [(True, every['EMD'])]


def test_a_cells_key_holds_its_engine_version_device_metrics_and_their_revision(
    bag_dir, monkeypatch
):
    from dataclasses import replace

    from cloth_bench_ros.core import surface_metrics
    from cloth_bench_ros.engines.mujoco_cloth import MujocoCloth
    from cloth_bench_ros.studies import cells as cells_module
    from cloth_bench_ros.studies.results import KEY_FIELDS, superseded_rows

    assert {'engine_version', 'device', 'all_metrics', 'surface_revision'} <= set(KEY_FIELDS)
    (paper,) = sw.paper_cells(['mujoco'], [100], ['towel'], ['dynamic'], [0], bag_dir, GRID)
    every = replace(paper, all_metrics=True)
    keys = paper.key(), every.key()
    assert keys[0] != keys[1]
    row = sw.error_row(paper, 'x')
    assert sw.row_key(row) == paper.key()
    old = {k: v for k, v in row.items() if k not in ('engine_version', 'all_metrics')}
    assert sw.row_key(old) not in keys  # a row from before these fields: computed again
    assert superseded_rows([paper], [old, row]) == [old]
    monkeypatch.setattr(surface_metrics, 'SURFACE_REVISION', surface_metrics.SURFACE_REVISION + 1)
    assert paper.key() == keys[0] and every.key() != keys[1]  # CD/HD read no surface metric
    monkeypatch.undo()
    monkeypatch.setattr(MujocoCloth, 'version', classmethod(lambda cls: '99.0'))
    cells_module._engine_version.cache_clear()
    try:
        assert paper.key() != keys[0] and paper.engine_version == '99.0'
        assert superseded_rows([paper], [row]) == [row]
    finally:
        monkeypatch.undo()
        cells_module._engine_version.cache_clear()
    monkeypatch.setattr(sw.Cell, 'device', property(lambda cell: 'cuda:0'))
    assert paper.key() != keys[0]


def test_a_row_made_with_other_parameters_or_another_bag_is_never_resumed(tmp_path, capsys):
    """A preset set or a bag changed since: one line, nothing run, nothing appended."""
    from dataclasses import replace

    bags, out = tmp_path / 'bags', tmp_path / 'out'
    write_hanging_cloth_bag(bags / 'towel_dynamic', frames=40, change_of_phase_frame=30)
    cells = sw.paper_cells(['mujoco'], [100], ['towel'], ['dynamic'], [0], bags, GRID)
    assert sw.run_sweep(cells, out, workers=1, progress=False).ran == 1
    (row,) = sw.load_rows(out)
    assert row['bag_fingerprint'] and row['params'] == {}
    assert sw.run_sweep(cells, out, workers=1, progress=False).skipped == 1

    other_values = [replace(c, overrides=(('damping', 0.5),)) for c in cells]  # same key
    with pytest.raises(sw.ResultsError, match=r'1 cells .*other parameters.*another --output'):
        sw.run_sweep(other_values, out, workers=1, progress=False)
    shutil.rmtree(bags / 'towel_dynamic')  # the same bag made again, with other noise
    write_hanging_cloth_bag(bags / 'towel_dynamic', frames=40, change_of_phase_frame=30, seed=1)
    with pytest.raises(sw.ResultsError, match=r'another bag at .*towel_dynamic'):
        sw.run_sweep(cells, out, workers=1, progress=False)
    assert main(['sweep', '--bag-dir', str(bags), '--engine', 'mujoco', '--rate', '100',
                 '--cloth', 'towel', '--primitive', 'dynamic', '--seeds', '1', '--grid', '6x8',
                 '--output', str(out)]) == 2
    assert 'another bag' in capsys.readouterr().err
    assert len(sw.load_rows(out)) == 1

    # Rows written before rows had a fingerprint resume on their parameters alone.
    (out / sw.RESULTS_FILE).write_text(
        json.dumps({k: v for k, v in row.items() if k != 'bag_fingerprint'}) + '\n')
    assert sw.run_sweep(cells, out, workers=1, progress=False).skipped == 1


def test_a_diverged_cell_is_a_result_and_a_failing_cell_an_error_row(bag_dir, tmp_path):
    # Bullet at 10 Hz with one 0.1 s step per target explodes during the fling (11 x 15 grid).
    diverging = sw.paper_cells(
        ['bullet'], [10], ['towel'], ['dynamic'], [0], bag_dir, step_per_target=True
    )
    broken = sw.Cell(
        'mujoco', 100.0, 'towel', 'dynamic', 0, str(tmp_path / 'no_such_bag'), config='broken'
    )
    outcome = sw.run_sweep(diverging + [broken], tmp_path, workers=2, progress=False)
    assert (outcome.ran, outcome.diverged, outcome.errors) == (2, 1, 1)
    rows = {r['config']: r for r in sw.load_rows(tmp_path)}
    d = rows['step=1/rate']
    assert d['status'] == 'diverged' and d['diverged'] and d['diverged_at_step'] > 0
    assert math.isnan(d['CD']) and d['diverged_reason']
    e = rows['broken']
    assert e['status'] == 'error' and 'no_such_bag' in e['error']
    # Errors are finished cells; --retry-errors runs them again.
    assert sw.run_sweep(diverging + [broken], tmp_path, workers=1, progress=False).ran == 0
    assert (
        sw.run_sweep(
            diverging + [broken], tmp_path, workers=1, progress=False, retry_errors=True
        ).ran
        == 1
    )


def _square_or_die(x: int) -> int:
    if x == 3:
        os._exit(13)  # a worker dying as an engine's segfault would
    return x * x


@pytest.mark.slow
@pytest.mark.own_dask_cluster
def test_a_task_that_kills_its_workers_is_retried_then_recorded_and_the_rest_finish():
    from cloth_bench_ros.studies.dask_executor import open_client, run_tasks
    import dask

    results, crashes = {}, {}
    with (
        dask.config.set({'distributed.scheduler.allowed-failures': 1}),
        open_client(workers=2) as client,
    ):
        run_tasks(
            client,
            _square_or_die,
            list(range(6)),
            on_result=results.__setitem__,
            on_crash=crashes.__setitem__,
        )
    assert results == {0: 0, 1: 1, 2: 4, 4: 16, 5: 25}
    assert list(crashes) == [3] and 'died' in crashes[3]


# ------------------------------------------------------------------------------- CLI


def test_cli_sweep_dry_run_counts_cells(bag_dir, tmp_path, capsys):
    assert (
        main(
            [
                'sweep',
                '--bag-dir',
                str(bag_dir),
                '--cloth',
                'towel',
                '--seeds',
                '3',
                '--dry-run',
                '--output',
                str(tmp_path),
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert (
        '54 cells' in out and '0 already' in out
    )  # mujoco, bullet, newton x 3 rates x 2 tasks x 3 seeds


@pytest.mark.parametrize(
    'argv, message',
    [
        (['--set', 'mujoco.nope=1'], 'unknown mujoco parameter nope'),
        (['--grid', '1x5'], 'grid'),
        (['--cloth', 'silk'], "invalid choice: 'silk'"),
        (['--engine', 'sofa'], 'engine sofa is not available'),
        (['--mode', 'settings', '--rate', '10', '--rate', '100'], 'one rate'),
        (['--seed-start', '-3'], '--seed-start: -3 is outside [0,'),
        (['--scheduler', 'localhost'], 'is not tcp://HOST:PORT'),
    ],
)
def test_cli_sweep_user_errors_are_one_line(bag_dir, tmp_path, capsys, argv, message):
    try:
        code = main(
            ['sweep', '--bag-dir', str(bag_dir), '--output', str(tmp_path), '--dry-run', *argv]
        )
    except SystemExit as exc:  # argparse's own usage errors
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1


def test_cli_sweep_runs_and_reports(bag_dir, tmp_path, capsys):
    code = main(
        [
            'sweep',
            '--engine',
            'mujoco',
            '--rate',
            '100',
            '--cloth',
            'towel',
            '--primitive',
            'dynamic',
            '--seeds',
            '1',
            '--grid',
            '6x8',
            '--workers',
            '1',
            '--bag-dir',
            str(bag_dir),
            '--output',
            str(tmp_path),
            '--no-progress',
            '--set',
            'mujoco.self_collision=true',
            '--report',
        ]
    )
    out = capsys.readouterr().out
    assert code == 0, out
    row = sw.load_rows(tmp_path)[0]
    assert (
        row['params'] == {'self_collision': True} and row['config'] == 'grid=6x8,self_collision=on'
    )
    assert (tmp_path / 'report' / 'report.md').is_file() and '| towel | CD_d |' in out


def test_cli_run_accepts_grid_and_set(hanging_bag, tmp_path, capsys):
    code = main(
        [
            'run',
            '--bag',
            str(hanging_bag),
            '--grid',
            '6x8',
            '--set',
            'mujoco.solver_iterations=5',
            '--output',
            str(tmp_path),
        ]
    )
    assert code == 0
    summary = json.loads((tmp_path / 'summary.json').read_text())
    assert summary['engines']['mujoco']['frames_scored'] == 132
    assert main(['run', '--bag', str(hanging_bag), '--set', 'bullet.mass=1']) == 2
    assert 'not part of this run' in capsys.readouterr().err


@pytest.mark.parametrize(
    'line, message',
    [
        ('[1, 2, 3]', 'must be a JSON object'),
        ('{"engine": "mujoco", "cloth": "towel"}', 'lacks rate_hz'),
        (
            (
                '{"engine": "../../etc", "rate_hz": 100, "cloth": "towel", "primitive": "dynamic",'
                ' "seed": 0}'
            ),
            'not a safe file name part',
        ),
        (
            (
                '{"engine": "mujoco", "rate_hz": 100, "cloth": "towel", "primitive": "dynamic",'
                ' "seed": 0, "frames_csv": "../../outside.csv"}'
            ),
            'points outside',
        ),
        (
            (
                '{"engine": "mujoco", "rate_hz": -5, "cloth": "towel", "primitive": "dynamic",'
                ' "seed": 0}'
            ),
            'not a positive number',
        ),
    ],
)
def test_report_refuses_untrusted_rows_in_one_line(tmp_path, capsys, line, message):
    (tmp_path / sw.RESULTS_FILE).write_text(line + '\n')
    assert main(['report', str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert message in err and f'{sw.RESULTS_FILE}:1' in err and len(err.strip().splitlines()) == 1


def test_a_locked_results_directory_refuses_a_second_study(tmp_path):
    with sw.ResultsLock(tmp_path, 'sweep'):
        with pytest.raises(ValueError, match='is in use by sweep'):
            with sw.ResultsLock(tmp_path, 'identify'):
                pass
    with sw.ResultsLock(tmp_path, 'identify'):  # released on exit
        pass
