"""
Conformance suite: every available cloth engine and model obeys the ClothEngine contract.

In the benchmark scene; real engines, coarse 6 x 8 grid, 100 Hz fling.

Tolerances:
- grasped corners within CORNER_TOLERANCE = 1 mm of the targets after every step;
- at the end of the settle phase the lowest vertex hangs HANG = 0.70 m +- 0.07 m below the
  grippers;
- no vertex above the table footprint more than TABLE_PENETRATION = 1 cm below the table top;
- the seeded initial perturbation has a standard deviation within 0.3-0.7 mm and no vertex
  is displaced more than 3 mm;
- the same seed gives bit-identical vertices; different seeds give different ones.
"""

from __future__ import annotations

from dataclasses import dataclass

from cloth_bench_ros.core import scene
from cloth_bench_ros.core.scene import ClothGrid
from cloth_bench_ros.core.trajectory import full_targets, PRIMITIVES
from cloth_bench_ros.engines import engine_class, known_engines, make_engine
from cloth_bench_ros.engines.base import ClothEngine, EngineError
from cloth_bench_ros.engines.presets import CLOTHS, load_preset
import numpy as np
import pytest

CORNER_TOLERANCE = 0.001  # m
HANG, HANG_TOLERANCE = 0.70, 0.07  # m
TABLE_PENETRATION = 0.01  # m
GRID = ClothGrid(6, 8)

ENGINES = sorted(info.name for info in known_engines() if info.available)

# Cloth models per engine, with the parameters each needs on the fling (others: defaults).
MODELS: dict[str, list[dict]] = {
    'mujoco': [{'model': 'shell'}, {'model': 'edges'}],
    'bullet': [{'model': 'mass_spring'}, {'model': 'neo_hookean', 'timestep': 0.001}],
    'newton': [{'model': 'xpbd'}, {'model': 'vbd'}],
}
# A case built to diverge per engine: 10 Hz, one internal step per target, very stiff cloth.
DIVERGING: dict[str, dict] = {
    'mujoco': {'model': 'edges', 'edge_stiffness': 1e6, 'timestep': 0.1},
    'bullet': {
        'model': 'mass_spring',
        'elastic': 1e6,
        'bending': 1e6,
        'damping': 0.0,
        'timestep': 0.1,
    },
    'newton': {'model': 'xpbd', 'spring_stiffness': 1e6, 'spring_damping': 0.0, 'timestep': 0.1},
}

# The models whose cases take long (PyBullet's FEM at 1 kHz internal steps, Newton's VBD): slow;
# the quick tier runs each engine on its other model.
SLOW_MODELS = {('bullet', 'neo_hookean'), ('newton', 'vbd')}
VARIANTS = [
    pytest.param(
        name,
        params,
        id=f'{name}-{params.get("model", "default")}',
        marks=pytest.mark.slow if (name, params.get('model')) in SLOW_MODELS else (),
    )
    for name in ENGINES
    for params in MODELS.get(name, [{}])
]


@dataclass
class Run:
    """Every step of one engine run: targets and vertices (steps, n, 3)."""

    engine: ClothEngine
    left: np.ndarray
    right: np.ndarray
    vertices: np.ndarray
    settle_end: int  # index of the last settle-phase sample


def run_engine(
    name: str,
    params: dict,
    rate_hz: float,
    primitive: str = 'dynamic',
    seed: int = 0,
    steps: int | None = None,
) -> Run:
    targets = full_targets(primitive, rate_hz)
    n = len(targets) if steps is None else min(steps, len(targets))
    engine = make_engine(name, rate_hz, params, GRID)
    frames = [engine.reset(seed, targets.left[0], targets.right[0])]
    for k in range(1, n):
        frames.append(engine.step(targets.left[k], targets.right[k]))
    engine.close()
    return Run(
        engine, targets.left[:n], targets.right[:n], np.stack(frames), targets.quintic_index - 1
    )


@pytest.fixture(
    scope='module', params=[pytest.param(v.values, id=v.id, marks=v.marks) for v in VARIANTS]
)
def fling(request) -> Run:
    """Return the full dynamic primitive at 100 Hz, settle phase included."""
    name, params = request.param
    return run_engine(name, params, 100.0)


def hang(run: Run, k: int) -> float:
    return float(run.left[k][2] - run.vertices[k][:, 2].min())


# -- the fling at 100 Hz ------------------------------------------------------------------------


def test_engines_are_discovered():
    assert {'mujoco', 'bullet'} <= set(ENGINES)
    for name in ENGINES:
        cls = engine_class(name)
        assert cls.name == name and cls.version()


def test_fling_runs_without_diverging(fling):
    assert not fling.engine.diverged, fling.engine.divergence
    assert fling.vertices.dtype == np.float64
    assert fling.vertices.shape[1:] == (GRID.nx * GRID.nz, 3)
    assert np.isfinite(fling.vertices).all()


def test_grasped_corners_follow_the_targets(fling):
    left_error = np.linalg.norm(fling.vertices[:, GRID.left_corner] - fling.left, axis=1)
    right_error = np.linalg.norm(fling.vertices[:, GRID.right_corner] - fling.right, axis=1)
    assert max(left_error.max(), right_error.max()) < CORNER_TOLERANCE


def test_cloth_hangs_about_0_7_m_after_settling(fling):
    assert abs(hang(fling, fling.settle_end) - HANG) < HANG_TOLERANCE


def test_cloth_follows_the_fling(fling):
    """The cloth moves with the grippers: its mean y swings both ways during the fling."""
    mean_y = fling.vertices[fling.settle_end:, :, 1].mean(axis=1)
    assert mean_y.min() < -0.1 and mean_y.max() > 0.1


def test_cloth_lands_on_the_table_without_passing_through(fling):
    x, y, z = (fling.vertices[..., i] for i in range(3))
    above_table = (
        (x > scene.TABLE_X[0])
        & (x < scene.TABLE_X[1])
        & (y > scene.TABLE_Y[0])
        & (y < scene.TABLE_Y[1])
    )
    assert z[above_table].min() > scene.TABLE_TOP_Z - TABLE_PENETRATION
    # It does reach the table, so the check above is not vacuous.
    assert z[-1].min() < scene.TABLE_TOP_Z + 0.02


# -- rates --------------------------------------------------------------------------------------


@pytest.mark.parametrize('rate_hz', [10.0, 1000.0])
@pytest.mark.parametrize('name,params', VARIANTS)
def test_settle_phase_at_other_rates(name, params, rate_hz):
    targets = full_targets('dynamic', rate_hz)
    run = run_engine(name, params, rate_hz, steps=targets.quintic_index)
    assert not run.engine.diverged, run.engine.divergence
    assert np.isfinite(run.vertices).all()
    assert np.abs(run.vertices[:, GRID.left_corner] - run.left).max() < CORNER_TOLERANCE
    assert abs(hang(run, run.settle_end) - HANG) < HANG_TOLERANCE


# -- seeds --------------------------------------------------------------------------------------


def _fling_from_pregrasp(name: str, params: dict, seed: int, steps: int = 60) -> np.ndarray:
    """Reset at the pre-grasp pose, then the first `steps` targets of the fling, at 100 Hz."""
    targets = full_targets('dynamic', 100.0)
    k0 = targets.quintic_index
    engine = make_engine(name, 100.0, params, GRID)
    frames = [engine.reset(seed, targets.left[k0], targets.right[k0])]
    frames += [engine.step(targets.left[k], targets.right[k]) for k in range(k0 + 1, k0 + steps)]
    engine.close()
    return np.stack(frames)


@pytest.mark.parametrize('name,params', VARIANTS)
def test_same_seed_gives_identical_output(name, params):
    first = _fling_from_pregrasp(name, params, seed=7)
    again = _fling_from_pregrasp(name, params, seed=7)
    other = _fling_from_pregrasp(name, params, seed=8)
    assert np.array_equal(first, again)
    assert not np.array_equal(first, other)


@pytest.mark.parametrize('name', ENGINES)
def test_seed_perturbs_the_initial_state_by_sub_millimetre_noise(name):
    left, right = scene.GRIPPER_START_LEFT, scene.GRIPPER_START_RIGHT
    engine = make_engine(name, 100.0, None, GRID)
    start = engine.reset(3, left, right)
    reset_again = engine.reset(3, left, right)
    engine.close()
    offset = start - GRID.vertices()
    assert np.array_equal(start, reset_again)
    assert 0.0003 < offset.std() < 0.0007
    assert np.abs(offset).max() < 0.003
    assert np.abs(offset[[GRID.left_corner, GRID.right_corner]]).max() < 1e-9


@pytest.mark.parametrize('name', ENGINES)
def test_two_instances_coexist_in_one_process(name):
    targets = full_targets('dynamic', 100.0)
    a, b = make_engine(name, 100.0, None, GRID), make_engine(name, 100.0, None, GRID)
    a.reset(1, targets.left[0], targets.right[0])
    b.reset(1, targets.left[0], targets.right[0])
    for k in range(1, 40):
        va, vb = (
            a.step(targets.left[k], targets.right[k]),
            b.step(targets.left[k], targets.right[k]),
        )
        assert np.array_equal(va, vb)
    a.close()
    vb = b.step(targets.left[40], targets.right[40])  # closing one leaves the other working
    assert np.isfinite(vb).all()
    b.close()


@pytest.mark.parametrize('name', ENGINES)
def test_step_returns_a_copy(name):
    engine = make_engine(name, 100.0, None, GRID)
    left, right = scene.GRIPPER_START_LEFT, scene.GRIPPER_START_RIGHT
    engine.reset(0, left, right)
    v = engine.step(left, right)
    v[:] = 99.0  # scribbling on the result must not reach the engine's state
    assert np.abs(engine.step(left, right) - GRID.vertices()).max() < 0.01
    engine.close()


# -- divergence ---------------------------------------------------------------------------------


@pytest.mark.parametrize('name', ENGINES)
def test_divergence_is_detected_and_reported(name):
    if name not in DIVERGING:
        pytest.skip(f'no case built to diverge for engine {name}')
    targets = full_targets('dynamic', 10.0)
    engine = make_engine(name, 10.0, DIVERGING[name], GRID)
    engine.reset(0, targets.left[0], targets.right[0])
    for k in range(1, len(targets)):
        v = engine.step(targets.left[k], targets.right[k])
        if engine.diverged:
            break
    assert engine.diverged
    assert engine.divergence.step == k and engine.divergence.reason
    # A diverged engine keeps answering (with its last state) instead of raising.
    assert np.array_equal(engine.step(targets.left[-1], targets.right[-1]), v)
    engine.close()


# -- bad parameters -----------------------------------------------------------------------------


def _rejects(name: str, params: dict, *words: str) -> None:
    with pytest.raises(EngineError) as caught:
        make_engine(name, 100.0, params, GRID)
    message = str(caught.value)
    assert '\n' not in message
    for word in words:
        assert word in message


@pytest.mark.parametrize('name', ENGINES)
def test_bad_parameters_raise_one_clear_line(name):
    _rejects(name, {'mass': -1.0}, 'mass', '-1.0')
    _rejects(name, {'mass': 1e9}, 'mass', 'outside')
    _rejects(name, {'mass': 'heavy'}, 'mass', 'not a number')
    _rejects(name, {'stiffnesss': 1.0}, 'unknown', 'stiffnesss')
    _rejects(name, {'model': 'cotton'}, 'model', 'cotton')
    _rejects(name, {'self_collision': 'yes'}, 'self_collision')
    with pytest.raises(EngineError, match='rate'):
        make_engine(name, 0.0, None, GRID)


def test_mujoco_rejects_edge_damping_with_the_discrete_integrator():
    if 'mujoco' not in ENGINES:
        pytest.skip('MuJoCo is not available')
    _rejects('mujoco', {'integrator': 'discrete', 'damping': 0.5}, 'damping', 'discrete')
    make_engine('mujoco', 100.0, {'integrator': 'discrete', 'damping': 0.0}, GRID).close()


def test_mujoco_contact_dimension_and_solver_reach_the_model():
    if 'mujoco' not in ENGINES:
        pytest.skip('MuJoCo is not available')
    import mujoco

    _rejects('mujoco', {'condim': 2}, 'condim')
    _rejects('mujoco', {'solver': 'Jacobi'}, 'solver', 'Jacobi')
    targets = full_targets('dynamic', 1000.0)
    rows = {}
    for condim in (3, 1):
        engine = make_engine(
            'mujoco', 1000.0, {'condim': condim, 'solver': 'CG', 'solver_iterations': 5}, GRID
        )
        assert engine.model.opt.solver == mujoco.mjtSolver.mjSOL_CG
        assert engine.model.geom_condim[0] == condim and engine.model.flex_condim[0] == condim
        # Grippers lowered so that the hanging cloth's lower edge meets the table.
        left, right = targets.left[0].copy(), targets.right[0].copy()
        left[2] = right[2] = scene.TABLE_TOP_Z + 0.6
        engine.reset(0, left, right)
        for _ in range(20):
            engine.step(left, right)
        assert not engine.diverged and engine.data.ncon > 0
        # Constraint rows per contact: 1 frictionless, 4 with friction (a pyramidal cone).
        rows[condim] = (engine.data.nefc - engine.data.ne) / engine.data.ncon
        engine.close()
    assert rows == {3: 4.0, 1: 1.0}


# -- presets ------------------------------------------------------------------------------------


@pytest.mark.parametrize('name', ENGINES)
def test_every_preset_loads_and_steps(name):
    targets = full_targets('dynamic', 100.0)
    for cloth in CLOTHS:
        for primitive in PRIMITIVES:
            params = load_preset(name, cloth, primitive)
            engine = make_engine(name, 100.0, params, GRID)
            engine.reset(0, targets.left[0], targets.right[0])
            for k in range(1, 20):
                engine.step(targets.left[k], targets.right[k])
            assert not engine.diverged, (cloth, primitive, engine.divergence)
            engine.close()


def test_unknown_cloth_lists_the_valid_ones():
    with pytest.raises(EngineError, match='towel, chequered, linen'):
        load_preset('mujoco', 'silk', 'dynamic')
    with pytest.raises(EngineError, match='quasi_static'):
        load_preset('mujoco', 'towel', 'twirl')


GOOD_PRESET = """engine: mujoco
engine_version: "4.0.0"
provenance: test
presets:
  towel:
    dynamic: {mass: 0.3}
"""


@pytest.mark.parametrize(
    'text,words',
    [
        ('engine: [unclosed\n', ['not valid YAML']),
        ('- just\n- a list\n', ['expected a mapping']),
        (GOOD_PRESET.replace('provenance: test\n', ''), ['missing key', 'provenance']),
        (GOOD_PRESET.replace('engine: mujoco', 'engine: bullet'), ["engine is 'bullet'"]),
        (GOOD_PRESET.replace('towel:', 'silk:'), ['unknown cloth', 'silk']),
        (GOOD_PRESET.replace('dynamic:', 'twirl:'), ['unknown primitive', 'twirl']),
        (GOOD_PRESET.replace('{mass: 0.3}', '0.3'), ['must map parameter']),
        (GOOD_PRESET.replace('mass: 0.3', 'mas: 0.3'), ['unknown', 'mas']),
        (GOOD_PRESET.replace('mass: 0.3', 'mass: -2'), ['mass', 'outside']),
    ],
)
def test_malformed_preset_file_names_the_file(tmp_path, text, words):
    (tmp_path / 'presets').mkdir()
    path = tmp_path / 'presets' / 'mujoco.yaml'
    path.write_text(text)
    with pytest.raises(EngineError) as caught:
        load_preset('mujoco', 'towel', 'dynamic', config_dir=tmp_path)
    message = str(caught.value)
    assert '\n' not in message and str(path) in message
    for word in words:
        assert word in message


def test_good_preset_file_in_a_custom_directory(tmp_path):
    (tmp_path / 'mujoco.yaml').write_text(GOOD_PRESET)
    # an entry that names no model is for the model that runs (the shipped preset's: shell)
    assert load_preset('mujoco', 'towel', 'dynamic', config_dir=tmp_path) == {
        'mass': 0.3,
        'model': 'shell',
    }
    with pytest.raises(EngineError, match='no preset for towel quasi_static'):
        load_preset('mujoco', 'towel', 'quasi_static', config_dir=tmp_path)
