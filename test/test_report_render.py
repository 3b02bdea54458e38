"""
Acceptance: a small sweep on the real engines runs in CI time and its report renders.

2 engines x 2 rates (10, 100 Hz) x 1 cloth x 2 tasks x 2 seeds = 16 cells on a coarse grid with
short fixture bags, 2 workers; then `cloth-bench report`: files exist, the tables hold the
expected rows, the plots are non-empty PNGs. Plus the report's pure parts (statistics, Pareto
front, recommendation) and a small settings sweep with its recommendation.
"""

from __future__ import annotations

import csv
import math
import re

from bag_fixtures import write_hanging_cloth_bag
from cloth_bench_ros.cli import main
from cloth_bench_ros.studies.stress import run_case
from cloth_bench_ros.studies.stress_cases import default_cases
from cloth_bench_ros.sweep import aggregate, recommend
from cloth_bench_ros.sweep import study as sw
import matplotlib.image as mpimg
import numpy as np
import pytest

ENGINES = ['mujoco', 'bullet']
RATES = [10.0, 100.0]


@pytest.fixture(scope='module')
def small_sweep(tmp_path_factory):
    bags = tmp_path_factory.mktemp('report_bags')
    write_hanging_cloth_bag(bags / 'towel_dynamic')
    write_hanging_cloth_bag(
        bags / 'towel_quasi_static',
        frames=420,
        primitive='quasi_static',
        change_of_phase_frame=None,
    )
    out = tmp_path_factory.mktemp('small_sweep')
    cells = sw.paper_cells(
        ENGINES, RATES, ['towel'], ['dynamic', 'quasi_static'], [0, 1], bags, grid=(6, 8)
    )
    outcome = sw.run_sweep(cells, out, workers=2, progress=False)
    return bags, out, outcome


@pytest.fixture(scope='module')
def rendered(small_sweep, tmp_path_factory):
    _, out, _ = small_sweep
    # One real stress case next to the results: the report includes it.
    stress = [
        run_case(next(c for c in default_cases(['mujoco']) if c.name == 'large_dt_high_damping'))
    ]
    sw.append_row(out / 'stress.jsonl', stress[0])
    report = tmp_path_factory.mktemp('report')
    assert main(['report', str(out), '--output', str(report)]) == 0
    return out, report


def _csv(path):
    with path.open() as f:
        return list(csv.reader(f))


@pytest.mark.slow
def test_the_small_sweep_runs_every_cell(small_sweep):
    _, out, outcome = small_sweep
    assert outcome.cells == outcome.ran == 16 and outcome.errors == 0
    rows = sw.load_rows(out)
    assert len(rows) == 16
    assert {(r['engine'], r['rate_hz'], r['primitive'], r['seed']) for r in rows} == {
        (e, r, p, s)
        for e in ENGINES
        for r in RATES
        for p in ('dynamic', 'quasi_static')
        for s in (0, 1)
    }
    for r in rows:
        assert r['status'] in ('ok', 'diverged')
        if r['status'] == 'ok':
            assert 0 < r['CD'] <= r['HD'] and r['step_time_mean'] > 0 and r['L_s'] > 0
    q = [r for r in rows if r['primitive'] == 'quasi_static']
    assert all(r['frames_scored'] == 420 for r in q)


def test_report_files_exist_and_the_plots_are_non_empty_pngs(rendered):
    _, report = rendered
    for name in (
        'report.md',
        'report.html',
        'table3.csv',
        'fig5.csv',
        'timing.csv',
        'stability.csv',
        'results.csv',
        'stress.csv',
        'pareto.csv',
    ):
        assert (report / name).is_file() and (report / name).stat().st_size > 0, name
    pngs = ['fig5.png', 'speed_error.png', 'frames_towel.png', 'latency.png']
    for name in pngs:
        path = report / name
        assert path.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n', name
        image = mpimg.imread(path)
        assert (
            image.shape[0] > 300 and image.shape[1] > 400 and float(image[..., :3].std()) > 0.02
        ), name
    md = (report / 'report.md').read_text()
    html = (report / 'report.html').read_text()
    for name in pngs:
        assert f']({name})' in md and f'src="{name}"' in html


def test_table3_has_the_papers_layout_with_our_and_the_papers_numbers(rendered):
    out, report = rendered
    table = _csv(report / 'table3.csv')
    header, rows = table[0], table[1:]
    assert header == [
        'cloth',
        'metric',
        'MuJoCo (ours)',
        'Bullet (ours)',
        'MuJoCo (paper)',
        'Bullet (paper)',
        'Flex (paper)',
        'SOFA (paper)',
    ]
    assert [(r[0], r[1]) for r in rows] == [('towel', m) for m in ('CD_d', 'HD_d', 'CD_q', 'HD_q')]
    paper = {r[1]: r[4] for r in rows}
    assert paper['CD_d'] == '0.079 ± 0.031' and paper['HD_q'] == '0.182 ± 0.040'
    assert rows[0][7] == '0.078 ± 0.029'  # SOFA's towel CD_d, bold in the paper
    # Our cells are mean ± std over the two seeds at 100 Hz, recomputed from the results.
    results = sw.load_rows(out)
    for r in rows:
        prim = 'dynamic' if r[1].endswith('_d') else 'quasi_static'
        for col, engine in ((2, 'mujoco'), (3, 'bullet')):
            vals = [
                x[r[1][:2]]
                for x in results
                if x['engine'] == engine
                and x['rate_hz'] == 100.0
                and x['primitive'] == prim
                and x['status'] == 'ok'
            ]
            m = re.match(r'([\d.]+) ± ([\d.]+)', r[col])
            assert m, r[col]
            assert float(m.group(1)) == pytest.approx(np.mean(vals), abs=6e-4)
            assert float(m.group(2)) == pytest.approx(np.std(vals), abs=6e-4)
    md = (report / 'report.md').read_text()
    assert '(paper)' in md and '**paper**' in md


def test_fig5_timing_and_stability_tables_hold_one_row_per_engine_and_rate(rendered):
    _, report = rendered
    fig5 = _csv(report / 'fig5.csv')[1:]
    assert [(r[0], r[1]) for r in fig5] == [
        ('MuJoCo', '10'),
        ('MuJoCo', '100'),
        ('Bullet', '10'),
        ('Bullet', '100'),
    ]
    assert all(float(r[3]) > 0 for r in fig5)  # step time
    timing = _csv(report / 'timing.csv')
    assert timing[0][:3] == ['engine', 'rate Hz', 'pacing'] and len(timing) == 1 + 4
    stability = _csv(report / 'stability.csv')
    assert len(stability) == 1 + 8  # engine x rate x task
    stress = _csv(report / 'stress.csv')
    assert stress[1][:4] == ['mujoco', 'large_dt_high_damping', '10', 'diverged']


def test_stat_pareto_and_recommendation():
    rows = [
        {'status': 'ok', 'CD': 1.0},
        {'status': 'ok', 'CD': 3.0},
        {'status': 'diverged', 'CD': math.nan},
        {'status': 'error', 'CD': math.nan},
    ]
    s = aggregate.stat(rows, 'CD')
    assert (s.n, s.used, s.diverged, s.errors, s.mean, s.std) == (4, 2, 1, 1, 2.0, 1.0)
    assert '1 diverged' in s.text()
    assert aggregate.pareto_front([(1, 5), (2, 4), (3, 6), (0.5, 9), (2, 1), (math.nan, 0)]) == [
        3,
        0,
        4,
    ]

    def cr(config, cd, ms, stable=True):
        st = aggregate.Stat(2, 2, 0, 0, cd, 0.0)
        return recommend.ConfigResult(
            'mujoco', 'towel', 'dynamic', 100.0, config, st, st, ms, ms / 10, stable
        )

    configs = [
        cr('fine', 0.100, 10.0),
        cr('medium', 0.1045, 3.0),
        cr('coarse', 0.110, 1.0),
        cr('broken', 0.050, 0.5, stable=False),
    ]
    best, cheap, tol = recommend.recommend(configs, 0.05, 0.002)
    assert best.config == 'fine' and cheap.config == 'medium' and tol == pytest.approx(0.005)
    best, cheap, tol = recommend.recommend(
        configs, 0.05, 0.02
    )  # 2 cm absolute tolerance: coarse is enough
    assert cheap.config == 'coarse' and tol == pytest.approx(0.02)


def test_a_settings_sweep_renders_its_recommendation(small_sweep, tmp_path, capsys):
    bags, _, _ = small_sweep
    axes = {'grid': [(6, 8)], 'timestep': [None, 0.005], 'solver_iterations': [None, 5]}
    cells = sw.settings_cells(['mujoco'], 100.0, ['towel'], ['dynamic'], [0], bags, axes)
    assert len(cells) == 4
    sw.run_sweep(cells, tmp_path, workers=2, progress=False)
    assert (
        main(['report', str(tmp_path), '--tolerance-rel', '0.05', '--tolerance-abs', '0.002']) == 0
    )
    out = capsys.readouterr().out
    assert 'recommended mujoco towel dynamic 100 Hz:' in out
    report = tmp_path / 'report'
    table = _csv(report / 'settings_mujoco_towel_dynamic_100hz.csv')
    assert len(table) == 1 + 4
    assert sum('recommended' in r[-1] for r in table[1:]) == 1
    assert sum('most accurate' in r[-1] for r in table[1:]) == 1
    png = report / 'settings_mujoco.png'
    assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n' and png.stat().st_size > 10_000
    md = (report / 'report.md').read_text()
    assert 'cheapest within tolerance' in md and 'Table contact cannot be switched off' in md


def test_report_of_missing_results_is_a_one_line_error(tmp_path, capsys):
    assert main(['report', str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert 'no results.jsonl' in err and len(err.strip().splitlines()) == 1
