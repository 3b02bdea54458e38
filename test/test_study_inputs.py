"""
A task file and a cloth mesh in the studies: sweep, stress and hil run them and key on them.

Real engines on coarse meshes; the bags are written by the test's bag fixture, the mesh file by
the test itself.
"""

from __future__ import annotations

import shutil

from bag_fixtures import write_hanging_cloth_bag
from cloth_bench_ros.cli import main
from cloth_bench_ros.core.scene import ClothGrid
from cloth_bench_ros.core.task_data import task_file
from cloth_bench_ros.sweep import study as sw
import pytest


def write_grid_obj(path, nx=6, nz=8):
    """Write the benchmark's cloth as an nx x nz grid mesh (OBJ, exact floats); return its path."""
    grid = ClothGrid(nx, nz)
    lines = [f'v {x!r} {y!r} {z!r}' for x, y, z in grid.vertices().tolist()]
    lines += [f'f {a + 1} {b + 1} {c + 1}' for a, b, c in grid.faces().tolist()]
    path.write_text('\n'.join(lines) + '\n')
    return path


@pytest.fixture(scope='module')
def bags(tmp_path_factory):
    d = tmp_path_factory.mktemp('study_inputs')
    write_hanging_cloth_bag(d / 'bags' / 'towel_dynamic', frames=40, change_of_phase_frame=30)
    write_grid_obj(d / 'grid.obj')
    shutil.copy(task_file('dynamic'), d / 'my_task.yaml')
    return d


def _sweep(root, out, *extra):
    command = ['sweep', '--bag-dir', str(root / 'bags'), '--engine', 'mujoco', '--rate', '100',
               '--cloth', 'towel', '--primitive', 'dynamic', '--seeds', '1', '--workers', '1',
               '--no-progress', '--output', str(out), *extra]
    assert main(command) == 0
    return sw.load_rows(out)


def test_a_sweep_runs_a_task_file_and_a_mesh_and_records_them(bags, tmp_path):
    (grid,) = _sweep(bags, tmp_path / 'grid', '--grid', '6x8')
    task = str(bags / 'my_task.yaml')
    (both,) = _sweep(bags, tmp_path / 'both', '--cloth-mesh', str(bags / 'grid.obj'),
                     '--task', task)
    assert grid['task_file'] == '' and grid['cloth_mesh'] == '' and grid['task_sha256'] == ''
    assert both['task_file'] == task and len(both['task_sha256']) == 64
    assert both['cloth_mesh'] == str(bags / 'grid.obj') and len(both['mesh_sha256']) == 64
    # the shipped task as a file and the 6 x 8 grid as a mesh are that task and grid exactly
    assert both['CD'] == grid['CD'] and both['HD'] == grid['HD'] and grid['CD'] > 0


def test_a_changed_task_file_or_mesh_recomputes_a_kept_cell(bags, tmp_path, capsys):
    task, mesh = tmp_path / 'task.yaml', tmp_path / 'cloth.obj'
    shutil.copy(bags / 'my_task.yaml', task)
    shutil.copy(bags / 'grid.obj', mesh)
    out = tmp_path / 'out'
    args = ('--task', str(task), '--cloth-mesh', str(mesh))
    (first,) = _sweep(bags, out, *args)
    assert _sweep(bags, out, *args) == [first]
    assert '(1 already done)' in capsys.readouterr().out
    task.write_text(task.read_text() + '# kept as it was\n')  # another file, the same task
    (again,) = _sweep(bags, out, *args)  # replaced, not beside the old row
    assert '(0 already done)' in capsys.readouterr().out
    assert again['task_sha256'] != first['task_sha256'] and again['CD'] == first['CD']
    mesh.write_text(mesh.read_text().replace('v ', 'v  ', 1))  # one more space: another file
    (moved,) = _sweep(bags, out, *args)
    assert '(0 already done)' in capsys.readouterr().out
    assert moved['mesh_sha256'] != again['mesh_sha256'] and moved['CD'] == first['CD']


@pytest.mark.parametrize('extra,words', [
    (('--cloth-mesh', 'missing.obj'), ['missing.obj']),
    (('--cloth-mesh', 'GRID', '--grid', '6x8'), ['grid.obj', 'own vertices']),
    (('--task', 'missing.yaml'), ['missing.yaml']),
])
def test_a_bad_task_file_or_mesh_is_one_line_before_any_cell(bags, tmp_path, extra, words):
    from test_cli import assert_one_line_error
    from test_cli import cli as cli_process

    extra = [str(bags / 'grid.obj') if e == 'GRID' else e for e in extra]
    result = cli_process('sweep', '--bag-dir', str(bags / 'bags'), '--engine', 'mujoco', '--rate',
                         '100', '--cloth', 'towel', '--primitive', 'dynamic', '--seeds', '1',
                         '--output', str(tmp_path / 'out'), *extra)
    assert_one_line_error(result, *words)
    assert not (tmp_path / 'out' / 'results.jsonl').exists()


def test_stress_runs_a_task_file_and_a_mesh_and_records_them(bags, tmp_path, capsys):
    import json

    mesh, task = str(bags / 'grid.obj'), str(bags / 'my_task.yaml')
    command = ['stress', '--engine', 'mujoco', '--case', 'fling_10hz', '--workers', '1',
               '--no-progress']
    assert main([*command, '--output', str(tmp_path / 'grid')]) == 0
    assert main([*command, '--case', 'fine_mesh_one_step', '--output', str(tmp_path / 'mesh'),
                 '--cloth-mesh', mesh, '--task', task]) == 0
    assert 'cases of their own grid are left out' in capsys.readouterr().out
    grid, meshed = ([json.loads(line) for line in (tmp_path / d / 'stress.jsonl').open()]
                    for d in ('grid', 'mesh'))
    assert grid[0]['cloth_mesh'] == '' and grid[0]['task_file'] == ''
    (row,) = meshed  # the fine mesh case is left out
    assert row['case'] == 'fling_10hz' and row['status'] == 'ok', row
    assert row['cloth_mesh'] == mesh and len(row['mesh_sha256']) == 64
    assert row['task_file'] == task and len(row['task_sha256']) == 64
    # the 6 x 8 mesh is a coarser cloth than the default 11 x 15 grid: its own steps
    assert row['steps'] == grid[0]['steps'] and row['L_s'] != grid[0]['L_s']


def test_hil_runs_a_task_file_and_a_mesh_and_records_them(bags, tmp_path, capsys):
    import json

    mesh, task = str(bags / 'grid.obj'), str(bags / 'my_task.yaml')
    command = ['hil', '--rate', '100', '--bag', str(bags / 'bags' / 'towel_dynamic'),
               '--in-process', '--duration', '0.3', '--no-lockstep', '--cloth-mesh', mesh,
               '--task', task, '--output', str(tmp_path / 'o')]
    assert main(command) == 0
    assert 'steps of the mesh ' + mesh in capsys.readouterr().out  # the engine ran the mesh
    (row,) = [json.loads(line) for line in (tmp_path / 'o' / 'hil.jsonl').open()]
    assert row['cloth_mesh'] == mesh and len(row['mesh_sha256']) == 64
    assert row['task_file'] == task and len(row['task_sha256']) == 64
    assert row['run_dir'].endswith('_task-my_task_mesh-grid')
    assert main([*command, '--grid', '6x8']) == 2  # a mesh has its own vertices
    assert 'own vertices' in capsys.readouterr().err


def test_the_sweep_report_names_the_task_files_and_meshes_its_cells_ran(bags, tmp_path):
    from cloth_bench_ros.report.document import overview_section

    out = tmp_path / 'out'
    _sweep(bags, out, '--grid', '6x8')
    (plain,) = [r for r in _sweep(bags, out, '--cloth-mesh', str(bags / 'grid.obj'))
                if r['cloth_mesh']]
    rows = sw.load_rows(out)
    assert len(rows) == 2  # a mesh is another cell than the grid
    text = overview_section(rows)[0][1]
    assert f'1 cells ran the cloth mesh `{bags / "grid.obj"}` (sha256 ' in text
    assert plain['mesh_sha256'][:12] in text and 'task file' not in text
    grid_only = [r for r in rows if not r['cloth_mesh']]
    assert 'ran the' not in overview_section(grid_only)[0][1]
