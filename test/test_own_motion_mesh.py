"""
A cloth mesh with a recorded motion: the mesh is in the recording's frame and moves with it.

The recordings (test/own_motion_recording.py) hold a motion of the test's own, simulated with
MuJoCo's Python API directly and written with rosbags, in the world and in a robot-base frame
turned 35 degrees about z. The mesh file, written here, is the reference's own rest mesh in the
recording's frame.
"""

import json
import math

from cloth_bench_ros import cli
from cloth_bench_ros.errors import InputError
import numpy as np
from own_motion_recording import base_matrix, grippers, LENGTH, noise_floor, write_recording
import pytest
from test_cli import assert_one_line_error
from test_cli import cli as cli_process

GRIPPERS = ('--gripper-frames', 'left_gripper,right_gripper')


def write_obj(path, vertices, triangles):
    """Write a Wavefront OBJ (1-based indices) and return its path."""
    lines = [f'v {x:.9f} {y:.9f} {z:.9f}' for x, y, z in vertices]
    lines += [f'f {a + 1} {b + 1} {c + 1}' for a, b, c in triangles]
    path.write_text('\n'.join(lines) + '\n')
    return path


def hanging_mesh(left, right, nx=6, nz=8, length=LENGTH):
    """Return a grid hanging from `left` to `right` (vertices, triangles), index j * nx + i."""
    s = np.linspace(0.0, 1.0, nx)
    rows = [left + s[:, None] * (right - left) - [0, 0, length * j / (nz - 1)] for j in range(nz)]
    tris = []
    for j in range(nz - 1):
        for i in range(nx - 1):
            a = j * nx + i
            tris += [(a, a + nx, a + 1), (a + 1, a + nx, a + nx + 1)]
    return np.concatenate(rows), np.asarray(tris)


@pytest.fixture(scope='module')
def recordings(tmp_path_factory):
    """Write the world and base-frame recordings and the reference's mesh in each frame."""
    root = tmp_path_factory.mktemp('own_motion_mesh')
    world = write_recording(root / 'world')
    write_recording(root / 'base', frame='base_link')
    rest, tris = hanging_mesh(*grippers(0.0))
    to_base = np.linalg.inv(base_matrix())
    write_obj(root / 'world.obj', rest, tris)
    write_obj(root / 'base.obj', rest @ to_base[:3, :3].T + to_base[:3, 3], tris)
    return root, world


def _run(bag, mesh, out):
    assert cli.main(['run', '--bag', str(bag), '--topic', '/points', '--cloth-mesh', str(mesh),
                     *GRIPPERS, '--output', str(out)]) == 0
    return json.loads((out / 'summary.json').read_text())


def test_a_mesh_in_a_turned_base_frame_follows_its_recorded_motion(recordings, tmp_path, capsys):
    root, reference = recordings
    world = _run(root / 'world', root / 'world.obj', tmp_path / 'world')
    base = _run(root / 'base', root / 'base.obj', tmp_path / 'base')
    printed = capsys.readouterr().out
    assert 'cloth: mesh' in printed and 'grasped vertices 0 and 5' in printed
    cd_world, cd_base = (s['engines']['mujoco']['CD_d'] for s in (world, base))
    cop = world['real']['change_of_phase']
    floor = noise_floor(reference['floors'], cop['t_s'] if cop.get('frame') else math.inf)
    assert cd_world == pytest.approx(cd_base, abs=1e-4)  # CD does not change with the frame
    assert cd_world < floor + 0.02, (cd_world, floor)
    for summary, name in ((world, 'world.obj'), (base, 'base.obj')):
        assert summary['run']['cloth_mesh']['file'].endswith(name)
        assert summary['run']['motion']['source'] == 'tf frames left_gripper,right_gripper'


def test_a_mesh_in_the_scenes_frame_is_not_grasped_by_a_turned_recording(recordings, tmp_path):
    root, _ = recordings  # the world's mesh with the base frame's recording: 1 cm is missed
    result = cli_process('run', '--bag', str(root / 'base'), '--topic', '/points', '--cloth-mesh',
                         str(root / 'world.obj'), *GRIPPERS, '--output', str(tmp_path / 'out'))
    assert_one_line_error(result, 'world.obj', 'no vertex within 1 cm')


def _recorded_task(tmp_path, apart):
    """Return a recorded task (a task file) of still grippers `apart` metres apart along x."""
    from cloth_bench_ros.core.task_data import load_task
    import yaml

    left, right = [0.0, 0.0, 1.0], [apart, 0.0, 1.0]
    doc = {'settle': {'hold_start': 0.1, 'move': 0.1, 'hold_end': 0.1},
           'recorded': {'source': 'test', 'frame': 'world', 'start_ns': 0,
                        'to_scene': np.eye(4).ravel().tolist(), 'table_z': None,
                        'table_source': 'none', 't': [0.0, 0.5], 'left': [left, left],
                        'right': [right, right]},
           'window': 'whole_motion'}
    path = tmp_path / f'motion_{apart}.yaml'
    path.write_text(yaml.safe_dump(doc))
    return load_task('dynamic', path)


def test_the_grippers_distance_is_checked_against_the_meshs_grasped_vertices(tmp_path):
    from cloth_bench_ros.core.cloth_mesh import ClothMesh, run_cloth

    wide = _recorded_task(tmp_path, 0.6)  # wider than the benchmark's 0.5 m grasped edge
    with pytest.raises(InputError, match='0.600 m apart.*grasped edge, 0.500 m'):
        run_cloth(None, None, None, wide, 100.0)
    rest, tris = hanging_mesh(np.array([0.0, 0.0, 1.0]), np.array([0.6, 0.0, 1.0]), 4, 4, 0.4)
    mesh = run_cloth(None, None, str(write_obj(tmp_path / 'wide.obj', rest, tris)), wide, 100.0)
    assert isinstance(mesh, ClothMesh) and (mesh.left_corner, mesh.right_corner) == (0, 3)
    # grasped vertices 8 mm inside each gripper: within reach, but 1.6 cm narrower than the grip
    rest, tris = hanging_mesh(np.array([0.008, 0.0, 1.0]), np.array([0.592, 0.0, 1.0]), 4, 4, 0.4)
    narrow = str(write_obj(tmp_path / 'narrow.obj', rest, tris))
    with pytest.raises(InputError, match='0.600 m apart.*grasped vertices, 0.584 m apart'):
        run_cloth(None, None, narrow, wide, 100.0)


def test_a_recorded_motions_turn_moves_the_mesh_as_it_moves_the_grippers(tmp_path):
    from cloth_bench_ros.core.cloth_mesh import read_cloth_mesh

    turn = np.eye(4)
    c, s = math.cos(0.7), math.sin(0.7)
    turn[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    turn[:3, 3] = [0.2, -0.1, 0.3]
    rest, tris = hanging_mesh(np.array([1.0, 2.0, 0.9]), np.array([1.3, 2.4, 0.9]), 3, 3, 0.3)
    path = write_obj(tmp_path / 'm.obj', rest, tris)
    moved = rest @ turn[:3, :3].T + turn[:3, 3]
    mesh = read_cloth_mesh(path, moved[0], moved[2], turn)
    assert mesh.rest == pytest.approx(moved, abs=1e-9)
    assert mesh.area == pytest.approx(0.5 * 0.3, abs=1e-9)  # rigid: the area is kept


def test_the_comparison_bag_draws_the_meshs_own_triangles(tmp_path, capsys):
    from cloth_bench_ros.core.scene import ClothGrid
    from rosbags.highlevel import AnyReader

    grid = ClothGrid(6, 8)
    faces = grid.faces()[::-1, ::-1]  # its own order and winding: not the grid's triangles
    mesh = write_obj(tmp_path / 'sheet.obj', grid.vertices(), faces)
    bag = tmp_path / 'comparison'
    assert cli.main(['run', '--cloth-mesh', str(mesh), '--output', str(tmp_path / 'out'),
                     '--record-comparison', str(bag)]) == 0
    assert f'run of: cloth mesh {mesh} (48 vertices, 70 triangles' in capsys.readouterr().out
    markers = 0
    with AnyReader([bag]) as reader:
        by_stamp: dict = {}
        wanted = [c for c in reader.connections
                  if c.topic in ('/cloth_bench/mujoco/mesh', '/cloth_bench/mujoco/error_cloud')]
        for conn, stamp, raw in reader.messages(connections=wanted):
            by_stamp.setdefault(stamp, {})[conn.topic] = reader.deserialize(raw, conn.msgtype)
    for pair in by_stamp.values():
        marker, cloud = pair['/cloth_bench/mujoco/mesh'], pair['/cloth_bench/mujoco/error_cloud']
        n, step = cloud.width * cloud.height, cloud.point_step
        raw = np.frombuffer(bytes(cloud.data), dtype=np.uint8).reshape(n, step)
        xyz = np.column_stack([raw[:, 4 * i:4 * i + 4].copy().view('<f4').ravel()
                               for i in range(3)])
        points = np.array([[p.x, p.y, p.z] for p in marker.points])
        assert points == pytest.approx(xyz[faces.ravel()], abs=1e-6)
        markers += 1
    assert markers > 10
