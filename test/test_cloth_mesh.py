"""The cloth from a mesh file (`--cloth-mesh`): reading, checks, engines, and a garment scored."""

from __future__ import annotations

import csv
import json
from pathlib import Path

from cloth_bench_ros import cli
from cloth_bench_ros.core.cloth_mesh import ClothMesh, read_cloth_mesh
from cloth_bench_ros.core.cloth_size import BENCHMARK_AREA
from cloth_bench_ros.core.scene import ClothGrid
from cloth_bench_ros.core.trajectory import full_targets
from cloth_bench_ros.engines import make_engine
from cloth_bench_ros.engines.mujoco_cloth import mesh_spring_edges
from cloth_bench_ros.engines.presets import load_preset, sized_params
from cloth_bench_ros.errors import ClothBenchError
from cloth_bench_ros.studies.direct import run_direct
from cloth_bench_ros.studies.run_pipeline import RunConfig
import numpy as np
import pytest
import trimesh

LEFT, RIGHT = np.array([0.0, 0.0, 1.0]), np.array([0.5, 0.0, 1.0])  # the task's gripper starts
MODELS = [('mujoco', 'shell'), ('mujoco', 'edges'), ('bullet', 'mass_spring'),
          ('bullet', 'neo_hookean'), ('newton', 'xpbd'), ('newton', 'vbd')]


def t_shirt(cell: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """
    Return a T-shirt outline hanging in the x-z plane from its sleeve ends at LEFT and RIGHT.

    Sleeves: the full 0.5 m width, 0.15 m down; body: x in [0.1, 0.4] down to 0.6 m. Grid cells of
    `cell`, two triangles each, unused grid points dropped.
    """
    nx, nz = round(0.5 / cell) + 1, round(0.6 / cell) + 1
    xs, zs = np.linspace(0.0, 0.5, nx), 1.0 - np.linspace(0.0, 0.6, nz)
    points = np.array([[x, 0.0, z] for z in zs for x in xs])
    tris = []
    for j in range(nz - 1):
        for i in range(nx - 1):
            x0, z0 = xs[i], zs[j]
            if z0 > 0.85 + 1e-9 or 0.1 - 1e-9 <= x0 < 0.4 - 1e-9:
                a = j * nx + i
                b, c, d = a + 1, a + nx, a + nx + 1
                tris += [(a, c, b), (b, c, d)]
    faces = np.asarray(tris)
    used = np.unique(faces)
    index = np.full(len(points), -1)
    index[used] = np.arange(len(used))
    return points[used], index[faces]


def write_mesh(path: Path, vertices: np.ndarray, faces: np.ndarray) -> Path:
    """Write a mesh with trimesh's exporter (OBJ with every digit, so a grid stays exact)."""
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    if path.suffix == '.obj':
        mesh.export(path, digits=17)
    else:
        mesh.export(path)
    return path


def _engine_run(engine: str, model: str, cloth, steps: int) -> np.ndarray:
    """Return the vertices after `steps` targets of the fling, from the task's start."""
    targets = full_targets('dynamic', 100.0)
    area = cloth.area if isinstance(cloth, ClothMesh) else None
    preset = load_preset(engine, 'towel', 'dynamic', None, model)
    params = sized_params(engine, {**preset, 'model': model}, None, None, area)
    sim = make_engine(engine, 100.0, params, cloth)
    try:
        vertices = sim.start(0, targets.left[0], targets.right[0])
        for k in range(1, steps):
            vertices = sim.step(targets.left[k], targets.right[k])
        assert not sim.diverged, sim.divergence
        return np.array(vertices)
    finally:
        sim.close()


def _skip_absent(engine: str) -> None:
    if engine == 'newton':
        pytest.importorskip('newton')


# ------------------------------------------------------------------------------ reading, checks

@pytest.mark.parametrize('suffix', ['.obj', '.ply', '.stl'])
def test_each_format_reads_as_the_garment_grasped_at_its_sleeve_ends(suffix, tmp_path):
    vertices, faces = t_shirt()
    mesh = read_cloth_mesh(write_mesh(tmp_path / f'shirt{suffix}', vertices, faces), LEFT, RIGHT)
    assert len(mesh.rest) == len(vertices) and len(mesh.triangles) == len(faces)  # STL merged
    assert mesh.area == pytest.approx(0.5 * 0.15 + 0.3 * 0.45, rel=1e-6)
    assert np.allclose(mesh.rest[[mesh.left_corner, mesh.right_corner]], [LEFT, RIGHT], atol=1e-6)
    assert mesh.spacing_ratio() == 1.0  # 5 cm cells: the benchmark grid's material
    assert mesh.grid is None  # not a grid: the engines build its own springs and slab
    assert mesh.record()['sha256'] == __import__('hashlib').sha256(
        (tmp_path / f'shirt{suffix}').read_bytes()).hexdigest()


def test_a_finer_mesh_of_the_garment_is_given_the_grid_rule_for_its_spacing(tmp_path):
    """Half the cell: spacing ratio 0.5, so the parameters of a 21 x 29 grid's (ratio 0.5)."""
    fine = read_cloth_mesh(write_mesh(tmp_path / 'fine.obj', *t_shirt(0.025)), LEFT, RIGHT)
    assert fine.spacing_ratio() == 0.5 and fine.area == pytest.approx(0.21)
    for engine in ('mujoco', 'newton'):
        _skip_absent(engine)
        preset = load_preset(engine, 'towel', 'dynamic')
        on_mesh = make_engine(engine, 100.0, preset, fine)
        on_grid = make_engine(engine, 100.0, preset, ClothGrid(21, 29))
        assert on_mesh.config == on_grid.config and on_mesh.config != make_engine(
            engine, 100.0, preset, ClothGrid()).config
        for sim in (on_mesh, on_grid):
            sim.close()


def test_the_mass_is_the_presets_per_area_times_the_meshs_area_unless_given(tmp_path):
    mesh = read_cloth_mesh(write_mesh(tmp_path / 'shirt.ply', *t_shirt()), LEFT, RIGHT)
    preset = load_preset('mujoco', 'towel', 'dynamic')
    per_area = sized_params('mujoco', preset, None, None, mesh.area)['mass']
    assert per_area == pytest.approx(preset['mass'] / BENCHMARK_AREA * 0.21)
    assert sized_params('mujoco', preset, None, 0.3, mesh.area)['mass'] == 0.3
    assert sized_params('mujoco', preset, None, None, BENCHMARK_AREA) == preset
    sim = make_engine('mujoco', 100.0, {**preset, 'mass': per_area}, mesh)
    import mujoco

    model = mujoco.MjModel.from_xml_string(sim._mjcf())
    assert model.body_mass[model.flex_vertbodyid].sum() == pytest.approx(per_area)


def test_mesh_springs_are_the_triangle_edges_then_one_across_each_pair():
    quad = np.array([[0, 2, 1], [1, 2, 3]])
    springs = mesh_spring_edges(quad)
    assert springs.tolist() == [[0, 2], [1, 2], [0, 1], [2, 3], [1, 3], [0, 3]]


def _bad_meshes(tmp_path: Path) -> dict[str, tuple[Path, str]]:
    v, f = t_shirt()
    shifted = v + [0.0, 0.0, 0.02]
    second = np.concatenate([v, v + [0.0, 0.5, 0.0]]), np.concatenate([f, f + len(v)])
    flap = np.concatenate([v, [[0.02, 0.05, 0.98]]])
    flaps = np.concatenate([f, [[1, 11, len(v)]]])  # a third triangle on the diagonal 1-11
    line = np.concatenate([v, [[0.25, 0.0, 1.0]]])  # on the edge between vertices 0 and 10
    big = t_shirt(0.003)
    cases = {
        'degenerate': (line, np.concatenate([f, [[0, len(v), 10]]]),
                       '1 degenerate triangles (no area)'),
        'duplicate': (v, np.concatenate([f, f[:1]]), '1 triangles given more than once'),
        'parts': (*second, '2 separate parts'),
        'non-manifold': (flap, flaps, '1 non-manifold edges'),
        'too many': (*big, f'{len(big[0])} vertices, more than the 20000 allowed'),
        'grasp': (shifted, f, "no vertex within 1 cm of the left gripper's start"),
    }
    out = {name: (write_mesh(tmp_path / f'{name.replace(" ", "_")}.obj', a, b), text)
           for name, (a, b, text) in cases.items()}
    garbage = tmp_path / 'garbage.ply'
    garbage.write_bytes(b'ply\nformat binary_little_endian 1.0\nelement vertex 3\n\x00\x01')
    out['unreadable'] = (garbage, 'not readable as PLY')
    out['no such file'] = (tmp_path / 'missing.stl', 'missing.stl')
    notes = tmp_path / 'shirt.txt'
    notes.write_text('v 0 0 0\n')
    out['extension'] = (notes, 'not an OBJ, PLY or STL file')
    return out


def test_each_bad_mesh_is_one_line_and_exit_2(tmp_path, capsys):
    for name, (path, text) in _bad_meshes(tmp_path).items():
        with pytest.raises(ClothBenchError, match=text.replace('(', r'\(').replace(')', r'\)')):
            read_cloth_mesh(path, LEFT, RIGHT)
        code = cli.main(['run', '--cloth-mesh', str(path), '--output', str(tmp_path / 'out')])
        err = capsys.readouterr().err
        assert code == 2 and text in err and len(err.strip().splitlines()) == 1, (name, err)
        assert f'cloth mesh {path}' in err or name == 'no such file', err
    good = write_mesh(tmp_path / 'shirt.obj', *t_shirt())
    for other in (['--grid', '6x8'], ['--cloth-size', '0.5,0.6']):
        code = cli.main(['run', '--cloth-mesh', str(good), *other,
                         '--output', str(tmp_path / 'o')])
        err = capsys.readouterr().err
        assert code == 2 and f'--cloth-mesh and {other[0]}' in err, err


# ------------------------------------------------------------------------------ every engine

@pytest.mark.parametrize('engine, model', MODELS)
def test_the_benchmark_rectangle_as_a_mesh_is_the_grids_cloth_bit_for_bit(engine, model,
                                                                          tmp_path):
    _skip_absent(engine)
    grid = ClothGrid()
    mesh = read_cloth_mesh(write_mesh(tmp_path / 'rect.obj', grid.vertices(), grid.faces()),
                           LEFT, RIGHT)
    assert mesh.grid == grid and mesh.area == BENCHMARK_AREA and mesh.spacing == grid.spacing
    steps = 8 if engine == 'newton' or model == 'neo_hookean' else 40
    assert np.array_equal(_engine_run(engine, model, mesh, steps),
                          _engine_run(engine, model, grid, steps))


@pytest.mark.parametrize('engine, model', MODELS)
def test_the_garment_runs_on_every_engine_and_model(engine, model, tmp_path):
    _skip_absent(engine)
    mesh = read_cloth_mesh(write_mesh(tmp_path / 'shirt.stl', *t_shirt()), LEFT, RIGHT)
    steps = 8 if engine == 'newton' or model == 'neo_hookean' else 40
    vertices = _engine_run(engine, model, mesh, steps)
    targets = full_targets('dynamic', 100.0)
    grasped = vertices[[mesh.left_corner, mesh.right_corner]]
    assert np.allclose(grasped, [targets.left[steps - 1], targets.right[steps - 1]], atol=2e-3)
    assert vertices.shape == mesh.rest.shape
    assert 0.57 < np.ptp(vertices[:, 2]) < 0.72  # hangs its length (the presets' stretch)
    rows = {z: vertices[np.isclose(mesh.rest[:, 2], z)] for z in np.unique(mesh.rest[:, 2])}
    sleeves = [np.ptp(row[:, 0]) for z, row in rows.items() if z > 0.86]
    body = [np.ptp(row[:, 0]) for z, row in rows.items() if z < 0.84]
    assert min(sleeves) > 0.42 and max(body) < 0.34, (sleeves, body)  # still a T (it sways)


def test_the_rectangle_mesh_scores_as_the_grid_and_the_summary_records_the_mesh(
        hanging_bag, tmp_path):
    """The direct path's frames.csv, bit for bit; the file and its hash in summary.json."""
    grid = ClothGrid()
    rect = write_mesh(tmp_path / 'rect.obj', grid.vertices(), grid.faces())
    rows = {}
    for name, mesh in (('grid', None), ('mesh', str(rect))):
        run_direct(RunConfig(bag=hanging_bag, cloth_mesh=mesh, output_dir=tmp_path / name))
        with open(tmp_path / name / 'frames.csv') as f:
            timing = ('step_time', 'latency')
            rows[name] = [{k: v for k, v in r.items() if not k.startswith(timing)}
                          for r in csv.DictReader(f)]
    assert rows['grid'] == rows['mesh'] and rows['grid']
    run = json.loads((tmp_path / 'mesh' / 'summary.json').read_text())['run']
    assert run['cloth_mesh'] == {'file': str(rect), 'sha256': read_cloth_mesh(
        rect, LEFT, RIGHT).sha256, 'vertices': 165, 'triangles': 280, 'area_m2': 0.35}
    assert run['cloth_size'] is None  # a mesh has no W x L
    assert 'cloth_mesh' not in json.loads((tmp_path / 'grid' / 'summary.json').read_text())['run']


def test_the_launch_argument_gives_the_mesh_to_the_simulators_recorder_and_evaluator(
        monkeypatch, tmp_path):
    """`ros2 launch ... cloth_mesh:=FILE`: each node's parameter, the simulator's engine on it."""
    from test_launch_config import _launched_nodes, _start

    mesh = write_mesh(tmp_path / 'shirt.ply', *t_shirt())
    args = {'engines': 'mujoco', 'output_dir': str(tmp_path / 'out'), 'cloth_mesh': str(mesh)}
    started = {}
    try:
        for node in _launched_nodes(monkeypatch, args):
            instance, context = _start(node, tmp_path)
            started[instance.get_name()] = (instance, context)
        for name in ('recorder', 'evaluator', 'simulator_mujoco'):
            assert started[name][0].get_parameter('cloth_mesh').value == str(mesh), name
        engine = started['simulator_mujoco'][0].engine
        assert isinstance(engine.grid, ClothMesh) and len(engine.grid.rest) == len(t_shirt()[0])
        assert started['evaluator'][0].run_info['cloth_mesh']['file'] == str(mesh)
    finally:
        for instance, context in started.values():
            getattr(instance, 'close', lambda: None)()
            context.shutdown()
