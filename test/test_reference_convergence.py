"""The reference convergence study (`cloth-bench converge`) on a coarse, short reference."""

from dataclasses import replace
from pathlib import Path

from cloth_bench_ros.data.synth import reference_config, simulate_reference
from cloth_bench_ros.engines.mujoco_cloth import TIMECONST_SLACK
from cloth_bench_ros.studies import reference_convergence as rc
import numpy as np
import pytest

COARSE = {'grid': (7, 9), 'rate_hz': 90.0}


def _serial(func, items, on_result, on_crash, args):
    for item in items:
        on_result(item, func(item, *args))


def test_each_axis_refines_one_setting():
    base = reference_config('towel', 'dynamic', reference='mujoco')
    iterations = rc.refined(base, 'iterations', 2)
    assert iterations.params['solver_iterations'] == 4 * base.params['solver_iterations']
    assert (iterations.rate_hz, iterations.grid) == (base.rate_hz, base.grid)
    rate = rc.refined(base, 'rate', 1)
    assert rate.rate_hz == 2 * base.rate_hz
    assert rate.params['timestep'] == base.params['timestep'] / 2  # the internal step halves
    grid = rc.refined(base, 'grid', 1)
    assert grid.grid == (46, 64)  # spacing 1.7 cm -> 1.1 cm
    assert grid.params['edge_timeconst'] == pytest.approx(base.params['edge_timeconst'] * 2 / 3)
    with pytest.raises(ValueError):
        rc.refined(base, 'colour', 1)
    labels = [v.label for v in rc.variants(base, rc.AXES, 2)]
    assert labels == [
        'shipped', 'iterations+1', 'iterations+2', 'rate+1', 'rate+2', 'grid+1', 'grid+2'
    ]


def test_the_surface_passes_through_the_vertices_and_between_them():
    grid = (4, 3)
    x, z = np.meshgrid(np.arange(4) * 0.1, np.arange(3) * 0.2)
    vertices = np.stack([x, np.zeros_like(x), z], axis=-1).reshape(-1, 3)
    between = np.stack([x[:-1, :-1] + 0.05, np.zeros((2, 3)), z[:-1, :-1] + 0.1], axis=-1)
    assert rc.surface_distance(vertices, vertices, grid) == 0.0
    assert rc.surface_distance(between.reshape(-1, 3), vertices, grid) == 0.0
    assert rc.surface_distance(vertices + [0, 0.02, 0], vertices, grid) == pytest.approx(0.02)
    # the same cloth on another grid is the same surface: nothing between them
    fine_x, fine_z = np.meshgrid(np.linspace(0, 0.3, 7), np.linspace(0, 0.4, 5))
    fine = np.stack([fine_x, np.zeros_like(fine_x), fine_z], axis=-1).reshape(-1, 3)
    change = rc.trajectory_change(vertices[None], grid, fine[None], (7, 5))
    assert change[0] < 1e-12
    moved = fine + [0, 0.01, 0]  # 1 cm off the plane
    change = rc.trajectory_change(vertices[None], grid, moved[None], (7, 5))
    assert change[0] == pytest.approx(0.01)


@pytest.mark.slow
def test_a_study_on_a_coarse_reference_compares_each_run_with_the_one_before(tmp_path: Path):
    study = rc.ConvergenceStudy(
        'mujoco', 'towel', 'dynamic', axes=('iterations', 'rate'), levels=1, duration=0.1,
        overrides=COARSE,
    )
    study.run(tmp_path, _serial)
    rows = {r['run']: r for r in study.rows()}
    assert set(rows) == {'shipped', 'iterations+1', 'rate+1'}
    assert all(r['hanging_length_m'] > 0.6 for r in rows.values())  # a 0.70 m cloth, hanging
    assert rows['rate+1']['compared_with'] == 'shipped'
    assert rows['rate+1']['change_mean_m'] > 0  # a finer internal step moves the cloth
    for r in rows.values():
        if 'converged' in r:
            assert r['converged'] == (
                r['change_mean_m'] < rc.TOLERANCE_M and r['hang_change_m'] < rc.HANG_TOLERANCE_M
            )
    # a rerun reuses the trajectories it kept
    again = rc.ConvergenceStudy(
        'mujoco', 'towel', 'dynamic', axes=('iterations', 'rate'), levels=1, duration=0.1,
        overrides=COARSE,
    )
    again.run(tmp_path, _serial)
    assert again.rows() == study.rows()
    rc.save(study.rows(), study, tmp_path / 'convergence.json')
    assert 'rate+1' in (tmp_path / 'convergence.json').read_text()
    assert 'shipped' in rc.format_rows(study.rows())


def test_the_grid_axis_runs_at_the_rate_its_finest_edges_need():
    base = reference_config('towel', 'dynamic', reference='mujoco')  # 900 Hz, edges 2.5 ms
    runs = {v.label: v for v in rc.variants(base, ('grid',), 2)}
    assert list(runs) == ['shipped', 'rate+1', 'grid+1', 'grid+2']
    assert runs['grid+1'].previous == 'rate+1'  # the same rate, the coarser grid
    assert runs['grid+2'].previous == 'grid+1'
    for name in ('grid+1', 'grid+2'):
        config = runs[name].config
        assert config.rate_hz == 1800.0
        # MuJoCo's floor: 2 steps (within the slack of a mesh whose x and z spacings round apart)
        slack = 1 + TIMECONST_SLACK
        assert config.params['edge_timeconst'] * slack >= 2 / config.rate_hz
    vbd = reference_config('towel', 'dynamic', reference='newton-vbd')
    assert rc.grid_rate_level(vbd, 2) == 0  # no edge constraints: no faster rate needed


@pytest.mark.slow
def test_a_finer_grid_with_scaled_edges_is_the_same_cloth():
    """The hanging length of the shell: the same time constant stretches the finer cloth more."""
    base = reference_config('towel', 'dynamic', grid=(7, 9), rate_hz=300.0, duration=0.05)
    base = replace(base, params={**base.params, 'edge_timeconst': 0.02, 'timestep': 1 / 300})
    finer = rc.refined(base, 'grid', 1)
    same_timeconst = replace(finer, params={**finer.params, 'edge_timeconst': 0.02})

    def hang(config):
        return rc.hanging_length(next(iter(simulate_reference(config)))[1][None])

    coarse = hang(base)
    assert abs(hang(finer) - coarse) < rc.HANG_TOLERANCE_M
    assert hang(same_timeconst) - coarse > 3 * rc.HANG_TOLERANCE_M


def test_engine_scores_are_the_cd_of_its_vertices_to_the_runs_surface():
    x, z = np.meshgrid(np.arange(4) * 0.1, np.arange(3) * 0.2)
    flat = np.stack([x, np.zeros_like(x), z], axis=-1).reshape(-1, 3)
    run = np.stack([flat, flat + [0, 0.01, 0]])  # two frames, the second 1 cm off the plane
    scores = rc.engine_scores({'same': run, 'off': run + [0, 0.005, 0]}, run, (4, 3))
    assert scores['same'] < 1e-12
    assert scores['off'] == pytest.approx(0.005)


@pytest.mark.slow
def test_a_study_scores_engines_against_every_run(tmp_path: Path, capsys):
    study = rc.ConvergenceStudy(
        'mujoco', 'towel', 'dynamic', axes=('iterations',), levels=1, duration=0.1,
        overrides=COARSE, scored=('mujoco', 'bullet'),
    )
    study.run(tmp_path, _serial)
    rows = study.rows()
    for row in rows:
        assert set(row['scores_m']) == {'mujoco', 'bullet'}
        assert all(0 < cd < 0.2 for cd in row['scores_m'].values())  # m: a cloth near the other
    assert rows[0]['scores_m']['mujoco'] != rows[0]['scores_m']['bullet']
    assert 'CD bullet' in rc.format_rows(rows).splitlines()[0]
    from cloth_bench_ros import cli
    assert cli.main(['converge', '--score', 'pybullet', '--output', str(tmp_path / 'x')]) == 2
    assert "--score: 'pybullet' is not an available engine" in capsys.readouterr().err
