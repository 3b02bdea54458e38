"""A mesh changes only the resolution: the engines' one scaling rule (`params_for_grid`)."""

from __future__ import annotations

from cloth_bench_ros.core.scene import ClothGrid, GRIPPER_START_LEFT, GRIPPER_START_RIGHT
from cloth_bench_ros.data.synth import reference_config
from cloth_bench_ros.engines import engine_class, make_engine
from cloth_bench_ros.engines.base import params_for_grid, spacing_ratio
from cloth_bench_ros.engines.presets import load_preset
from cloth_bench_ros.studies.reference_convergence import refined
import numpy as np
import pytest

ENGINES = [('mujoco', {}), ('bullet', {}), ('newton', {'model': 'xpbd'})]


def _preset(name: str, overrides: dict) -> dict:
    return {**load_preset(name, 'towel', 'dynamic'), **overrides}


def _hold(engine, steps: int) -> np.ndarray:
    """Return the cloth after `steps` steps hanging from the grippers' start poses."""
    vertices = engine.start(0, GRIPPER_START_LEFT, GRIPPER_START_RIGHT)
    for _ in range(steps):
        vertices = engine.step(GRIPPER_START_LEFT, GRIPPER_START_RIGHT)
    engine.close()
    return vertices


@pytest.mark.parametrize('name,overrides', ENGINES)
def test_default_mesh_is_bit_identical_to_the_unscaled_path(name, overrides):
    """On 11 x 15 make_engine runs exactly what the engine built from the preset runs."""
    params = _preset(name, overrides)
    assert params_for_grid(engine_class(name), params, 100.0, ClothGrid()) == params
    assert params_for_grid(engine_class(name), params, 100.0, None) == params
    scaled = _hold(make_engine(name, 100.0, params, ClothGrid()), 20)
    unscaled = _hold(engine_class(name)(100.0, params, ClothGrid()), 20)
    assert np.array_equal(scaled, unscaled)


def test_parameters_set_for_their_own_grid_are_not_scaled():
    """A synthetic reference's parameters are set for its grid: simulate_reference keeps them."""
    config = reference_config('towel', 'dynamic')
    grid = ClothGrid(*config.grid)
    mujoco = engine_class('mujoco')
    assert params_for_grid(mujoco, config.params, 900.0, grid, grid) == config.params


def test_mujoco_scales_its_edge_time_constant_and_internal_step():
    cls = engine_class('mujoco')
    params = _preset('mujoco', {})
    fine = params_for_grid(cls, params, 100.0, ClothGrid(31, 43))
    ratio = spacing_ratio(ClothGrid(31, 43), ClothGrid())
    assert ratio == pytest.approx(1 / 3)
    assert fine['edge_timeconst'] == pytest.approx(params['edge_timeconst'] / 3)
    # 3.3 ms is under two of the preset's 2 ms steps: the step follows (at most half of it)
    assert fine['timestep'] == pytest.approx(fine['edge_timeconst'] / 2)
    coarse = params_for_grid(cls, params, 100.0, ClothGrid(6, 8))
    assert coarse['edge_timeconst'] == pytest.approx(2 * params['edge_timeconst'])
    assert coarse['timestep'] == params['timestep']
    # A time constant under two internal steps was floored at two: that is the cloth scaled.
    long_steps = {**params, 'timestep': 0.01}  # 10 ms steps: the 10 ms constant acts as 20 ms
    fine = params_for_grid(cls, long_steps, 100.0, ClothGrid(21, 29))
    assert fine['edge_timeconst'] == pytest.approx(0.01) and fine['timestep'] == 0.005
    springs = {**params, 'model': 'edges', 'integrator': 'Euler'}
    assert params_for_grid(cls, springs, 100.0, ClothGrid(31, 43)) == springs  # per edge: a sheet


def test_newton_scales_contact_with_vertex_area_and_xpbd_step():
    cls = engine_class('newton')
    xpbd = _preset('newton', {'model': 'xpbd', 'contact_stiffness': 1000.0})
    fine = params_for_grid(cls, xpbd, 100.0, ClothGrid(21, 29))
    assert fine['contact_stiffness'] == pytest.approx(250.0)
    assert fine['timestep'] == pytest.approx(xpbd['timestep'] / 2)
    vbd = _preset('newton', {'model': 'vbd'})
    assert params_for_grid(cls, vbd, 100.0, ClothGrid(21, 29))['timestep'] == vbd['timestep']


def test_mujoco_coarse_mesh_hangs_like_the_default_one():
    """
    With the scaling, MuJoCo's towel hangs within 8 mm on 6 x 8 and 11 x 15; without, it does not.

    MuJoCo's edge constraint stiffness goes with the vertex mass: the same time constant on a
    coarser mesh is a stiffer cloth (11.6 mm shorter at 6 x 8 after 1 s), the scaled one 4.7 mm.
    """
    params = _preset('mujoco', {})
    default = np.ptp(_hold(make_engine('mujoco', 100.0, params), 100)[:, 2])
    coarse = np.ptp(_hold(make_engine('mujoco', 100.0, params, ClothGrid(6, 8)), 100)[:, 2])
    unscaled = np.ptp(_hold(engine_class('mujoco')(100.0, params, ClothGrid(6, 8)), 100)[:, 2])
    assert abs(coarse - default) < 0.008
    assert abs(unscaled - default) > 0.008  # what the test would see if the scaling were dropped


def test_converge_grid_axis_uses_the_same_rule():
    """The convergence study's finer grid is scaled by params_for_grid, as --grid is."""
    config = reference_config('towel', 'dynamic')
    finer = refined(config, 'grid', 1)
    expected = params_for_grid(
        engine_class(config.engine), config.params, config.rate_hz, ClothGrid(*finer.grid),
        ClothGrid(*config.grid),
    )
    assert finer.params == expected
    assert finer.params['edge_timeconst'] == pytest.approx(config.params['edge_timeconst'] / 1.5)
