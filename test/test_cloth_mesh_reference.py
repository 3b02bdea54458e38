"""
A garment simulated by MuJoCo called directly, written by rosbags, scored with `--cloth-mesh`.

The reference is this test's own MJCF (a flexcomp of the T-shirt, kinematic grasps) along the
paper's fling, its vertices and triangle centres with 1 mm noise at 30 Hz on /points: a bag no
project code wrote. `cloth-bench run --cloth-mesh` scores it near the noise floor; the bounding
rectangle (`--cloth-size 0.5,0.6`) on the same recording far above.
"""

from __future__ import annotations

import json
from pathlib import Path

from cloth_bench_ros import cli
from cloth_bench_ros.core.trajectory import full_targets
from cloth_bench_ros.engines.presets import load_preset
import mujoco
import numpy as np
import pytest
from rosbags.rosbag2 import Writer
from rosbags.typesys import get_typestore, Stores
from scipy.spatial import cKDTree
from test_cloth_mesh import t_shirt, write_mesh

RATE_HZ, FPS, SETTLE_S, NOISE_M = 100.0, 30.0, 3.0, 0.001
TOPIC = '/points'


def reference_states(vertices: np.ndarray, faces: np.ndarray, start_seed: int | None = None
                     ) -> np.ndarray:
    """
    Return the garment's vertices at every target of the fling, (targets, n, 3).

    `start_seed`: its free vertices start displaced by 0.5 mm normal noise of that seed.
    """
    p = load_preset('mujoco', 'towel', 'dynamic')
    area = 0.5 * np.linalg.norm(np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]],
                                         vertices[faces[:, 2]] - vertices[faces[:, 0]]),
                                axis=1).sum()
    mass = p['mass'] / 0.35 * area  # the preset's mass per area of the 0.5 x 0.7 m towel
    h = 0.002
    xml = f"""
<mujoco>
  <option timestep="{h}" gravity="0 0 -9.81" integrator="Euler" solver="Newton" iterations="50"/>
  <worldbody>
    <geom type="box" size="0.55 0.9 0.025" pos="0.25 0 0.17"
          friction="{p['friction']} 0.005 0.0001"/>
    <flexcomp name="shirt" type="direct" dim="2" radius="0.004" mass="{mass}"
              point="{' '.join(map(repr, vertices.ravel().tolist()))}"
              element="{' '.join(map(str, faces.ravel().tolist()))}">
      <contact selfcollide="none" friction="{p['friction']} 0.005 0.0001" condim="3"
               solref="0.005 1" solimp="0.95 0.99 0.001"/>
      <edge equality="true" solref="{p['edge_timeconst']} 1" damping="{p['damping']}"/>
      <elasticity young="{p['young']}" poisson="{p['poisson']}" thickness="{p['thickness']}"
                  elastic2d="bend"/>
    </flexcomp>
  </worldbody>
</mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    bodies = model.flex_vertbodyid[:len(vertices)]
    joints = model.body_jntadr[bodies][:, None] + np.arange(3)
    qpos, dof = model.jnt_qposadr[joints], model.jnt_dofadr[joints]
    held = [0, int(np.argmin(np.linalg.norm(vertices - [0.5, 0.0, 1.0], axis=1)))]
    for body in bodies[held]:  # a grasp: a point too heavy for the cloth to move, moved by us
        model.body_mass[body], model.body_inertia[body] = 1000.0, 0.1
    mujoco.mj_setConst(model, data)
    data.qfrc_applied[dof[held, 2]] = 1000.0 * 9.81
    targets = full_targets('dynamic', RATE_HZ)
    grips = np.stack([targets.left, targets.right], axis=1)
    if start_seed is not None:
        start = np.random.default_rng(start_seed).normal(0.0, 0.0005, vertices.shape)
        start[held] = 0.0
        data.qpos[qpos] = start
    states = [vertices + data.qpos[qpos]]
    substeps = round(1 / RATE_HZ / h)
    for k in range(1, len(grips)):
        velocity = (grips[k] - grips[k - 1]) * RATE_HZ
        for s in range(substeps):
            data.qpos[qpos[held]] = grips[k - 1] + s * h * velocity - vertices[held]
            data.qvel[dof[held]] = velocity
            mujoco.mj_step(model, data)
        states.append(vertices + data.qpos[qpos])
    return np.array(states)


def at_frame(states: np.ndarray, k: int) -> np.ndarray:
    """Return the vertices at real frame k (linear between the targets, as the evaluator pairs)."""
    t = (SETTLE_S + k / FPS) * RATE_HZ
    i = int(t)
    return states[i] + (t - i) * (states[i + 1] - states[i])


def write_reference_bag(path: Path, states: np.ndarray, faces: np.ndarray, other: np.ndarray,
                        seed: int = 0) -> tuple[Path, np.ndarray]:
    """
    Write the motion's frames at 30 Hz on /points; return the bag and its noise floor per frame.

    The floor: the one-sided L1 CD of `other` (the reference from another start within its
    0.5 mm) to each noisy frame, the sensor's noise and the motion's spread from its start.
    """
    rng = np.random.default_rng(seed)
    store = get_typestore(Stores.ROS2_JAZZY)
    pc2 = store.types['sensor_msgs/msg/PointCloud2']
    field = store.types['sensor_msgs/msg/PointField']
    header = store.types['std_msgs/msg/Header']
    stamp_t = store.types['builtin_interfaces/msg/Time']
    floors = []
    frames = int((len(states) - 2) / RATE_HZ * FPS - SETTLE_S * FPS)
    t0 = 1_700_000_000 * 10**9
    with Writer(path, version=9) as writer:
        conn = writer.add_connection(TOPIC, pc2.__msgtype__, typestore=store)
        for k in range(frames):
            now = at_frame(states, k)
            surface = np.concatenate([now, now[faces].mean(axis=1)])
            points = (surface + rng.normal(0.0, NOISE_M, surface.shape)).astype(np.float32)
            floors.append(np.mean(cKDTree(points).query(at_frame(other, k), p=1)[0]))
            ns = t0 + round(k * 1e9 / FPS)
            msg = pc2(
                header=header(stamp=stamp_t(sec=ns // 10**9, nanosec=ns % 10**9),
                              frame_id='world'),
                height=1, width=len(points),
                fields=[field(name=n, offset=4 * j, datatype=7, count=1)
                        for j, n in enumerate('xyz')],
                is_bigendian=False, point_step=12, row_step=12 * len(points),
                data=np.frombuffer(points.tobytes(), dtype=np.uint8), is_dense=True,
            )
            writer.write(conn, ns, store.serialize_cdr(msg, pc2.__msgtype__))
    return path, np.array(floors)


@pytest.fixture(scope='module')
def garment(tmp_path_factory) -> tuple[Path, Path, np.ndarray]:
    """Return the T-shirt's mesh file, its reference bag and the bag's noise floor per frame."""
    folder = tmp_path_factory.mktemp('garment')
    vertices, faces = t_shirt()
    mesh = write_mesh(folder / 'shirt.obj', vertices, faces)
    reference, other = (reference_states(vertices, faces, seed) for seed in (1, 2))
    bag, floors = write_reference_bag(folder / 'bag', reference, faces, other)
    return mesh, bag, floors


def score(bag: Path, out: Path, *cloth: str, engine: str = 'mujoco', model: str = '') -> dict:
    """Return the engine's scores of `cloth-bench run` on the reference bag."""
    args = ['run', '--bag', str(bag), '--topic', TOPIC, '--start-time', '0', '--clean', 'off',
            '--engine', engine, '--output', str(out), *cloth]
    if model:
        args += ['--set', f'{engine}.model={model}']
    assert cli.main(args) == 0
    return json.loads((out / 'summary.json').read_text())['engines'][engine]


ENGINES = [
    ('mujoco', 'shell'),
    pytest.param('mujoco', 'edges', marks=pytest.mark.slow),
    pytest.param('bullet', 'mass_spring', marks=pytest.mark.slow),
    pytest.param('newton', 'xpbd', marks=pytest.mark.slow),
    pytest.param('newton', 'vbd', marks=pytest.mark.slow),
]


@pytest.mark.parametrize('engine, model', ENGINES)
def test_the_garment_scores_at_the_noise_floor_and_its_bounding_rectangle_far_above(
        garment, engine, model, tmp_path, capsys):
    if engine == 'newton':
        pytest.importorskip('newton')
    mesh, bag, floors = garment
    shirt = score(bag, tmp_path / 'shirt', '--cloth-mesh', str(mesh), engine=engine, model=model)
    printed = capsys.readouterr().out
    assert f'cloth: mesh {mesh}, ' in printed and 'grasped vertices 0 and 10' in printed
    rect = score(bag, tmp_path / 'rect', '--cloth-size', '0.5,0.6', engine=engine, model=model)
    window = shirt['frames_in_window']
    assert shirt['frames_scored'] == 131 and 60 < window == rect['frames_in_window']
    floor = float(floors[:window].mean())  # the frames CD_d averages over
    print(f'{engine} ({model}): garment CD_d {shirt["CD_d"]:.4f} m, bounding rectangle CD_d '
          f'{rect["CD_d"]:.4f} m; noise floor {floor:.4f} m over {window} frames')
    if (engine, model) == ('mujoco', 'shell'):  # the reference's own model
        assert shirt['CD_d'] < 2 * floor, (shirt['CD_d'], floor)
        assert rect['CD_d'] > 4 * shirt['CD_d'], (rect['CD_d'], shirt['CD_d'])
    else:  # another model of the same garment: closer than the wrong cloth
        assert shirt['CD_d'] < rect['CD_d'], (shirt['CD_d'], rect['CD_d'])
