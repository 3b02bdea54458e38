"""The settle phase, full (the paper's) or fast: its start state, cost, keys and records."""

import json

from cloth_bench_ros.cli import build_parser
from cloth_bench_ros.core.scene import ClothGrid
from cloth_bench_ros.core.trajectory import full_targets
from cloth_bench_ros.engines import make_engine
from cloth_bench_ros.engines.presets import load_preset
from cloth_bench_ros.engines.settle import final_hold, HOLD_LIMIT_S, Settler
from cloth_bench_ros.errors import InputError
from cloth_bench_ros.identify.problem import check_problem, PROBLEM_FILE, study_key
from cloth_bench_ros.studies.cells import Cell
from cloth_bench_ros.studies.direct import run_direct
from cloth_bench_ros.studies.results import row_key
from cloth_bench_ros.studies.run_config import RunConfig
from cloth_bench_ros.sweep.study import cells_to_run, SweepPlan
import numpy as np
import pytest

GRID = ClothGrid(6, 8)
RATE_HZ = 100.0
ENGINES = [('mujoco', None), ('bullet', None), ('newton', 'xpbd'), ('newton', 'vbd')]


def _settle(engine: str, model: str | None, settle: str, seed: int = 0):
    """Return the state at the start of the quintic part and the engine steps it took."""
    params = load_preset(engine, 'towel', 'dynamic')
    if model:
        params['model'] = model
    targets = full_targets('dynamic', RATE_HZ)
    sim = make_engine(engine, RATE_HZ, params, GRID)
    settler = Settler(sim, targets, settle)
    vertices = sim.start(seed, targets.left[0], targets.right[0])
    for k in range(1, targets.quintic_index + 1):
        vertices = settler.step(k, targets.left[k], targets.right[k])
    sim.close()
    return np.array(vertices), sim.steps, sim.divergence


@pytest.mark.parametrize('engine, model', ENGINES, ids=[f'{e}-{m or ""}' for e, m in ENGINES])
def test_the_fast_settle_starts_the_quintic_part_near_the_full_one_for_less(engine, model):
    """
    Each engine family: fewer steps, a sound state, as far from the full settle as seeds are.

    The full settle's state is still moving when the quintic part starts, and the seed's 0.5 mm
    noise alone moves it by millimetres to decimetres (benchmarks/bench_settle.py), so no cheaper
    settle lands within 1 mm of it: the fast one is held to the spread of two seeds of the full.
    """
    full, full_steps, full_div = _settle(engine, model, 'full')
    fast, fast_steps, fast_div = _settle(engine, model, 'fast')
    other, _, _ = _settle(engine, model, 'full', seed=1)
    targets = full_targets('dynamic', RATE_HZ)
    q = targets.quintic_index
    assert full_div is None and fast_div is None
    assert full_steps == q
    assert fast_steps == final_hold(targets) + round(HOLD_LIMIT_S * RATE_HZ)  # the hold cut short
    difference = np.linalg.norm(fast - full, axis=1).max()
    spread = np.linalg.norm(other - full, axis=1).max()
    assert difference <= max(3 * spread, 0.02)
    assert np.isfinite(fast).all() and fast[:, 2].min() > 0.19  # hanging, above the table


def test_the_full_settle_is_the_engine_stepped_through_every_target():
    targets = full_targets('dynamic', RATE_HZ)
    params = load_preset('mujoco', 'towel', 'dynamic')
    plain, settled = (make_engine('mujoco', RATE_HZ, params, GRID) for _ in range(2))
    settler = Settler(settled, targets, 'full')
    a = plain.start(0, targets.left[0], targets.right[0])
    b = settled.start(0, targets.left[0], targets.right[0])
    for k in range(1, targets.quintic_index + 5):
        a = plain.step(targets.left[k], targets.right[k])
        b = settler.step(k, targets.left[k], targets.right[k])
        assert settler.stepped
    assert np.array_equal(a, b)


def test_the_summary_records_the_settle_and_skipped_targets_are_no_steps(hanging_bag):
    summaries = {
        settle: run_direct(RunConfig(bag=hanging_bag, engines=['mujoco'], grid=(6, 8),
                                     settle=settle))
        for settle in ('full', 'fast')
    }
    for settle, summary in summaries.items():
        assert summary['run']['settle'] == settle
        json.dumps(summary)  # as summary.json keeps it
    steps = {s: summaries[s]['engines']['mujoco']['step_time']['count'] for s in summaries}
    assert steps['fast'] < steps['full']


def _cell(settle: str) -> Cell:
    return Cell('mujoco', 100.0, 'towel', 'dynamic', 0, 'bag', settle=settle)


def test_a_kept_cell_of_the_other_settle_is_run_again():
    full, fast = _cell('full'), _cell('fast')
    assert full.key() != fast.key() and full.ident() != fast.ident()
    old_row = {'mode': 'paper', 'config': 'preset', 'engine': 'mujoco', 'rate_hz': 100.0,
               'cloth': 'towel', 'primitive': 'dynamic', 'trial': 0, 'seed': 0,
               'pacing': 'lockstep', 'device': 'cpu', 'params': {},
               'engine_version': full.engine_version, 'all_metrics': full.all_metrics,
               'surface_revision': full.surface_revision}  # before the settle was kept
    assert row_key(old_row) == full.key()
    assert cells_to_run([full, fast], [old_row]) == [fast]
    assert cells_to_run([fast], [{**old_row, 'settle': 'fast'}]) == []


def test_a_sweep_gives_every_cell_its_settle_and_refuses_fast_on_the_node_graph():
    cells = SweepPlan(engines=['mujoco'], rates=[100.0], cloths=['towel'],
                      primitives=['dynamic'], n_seeds=1, settle='fast').cells()
    assert cells and {c.settle for c in cells} == {'fast'}
    with pytest.raises(InputError, match='--settle fast runs lockstep cells only'):
        SweepPlan(engines=['mujoco'], pacing='realtime', settle='fast').cells()


def test_an_identification_settled_in_full_is_not_resumed_with_the_fast_settle(tmp_path):
    class Spec:
        engine, cloth, primitive = 'mujoco', 'towel', 'dynamic'
        cloth_size = cloth_mass = None
        output = tmp_path

    journal = tmp_path / 'journal.log'
    journal.write_text('')
    problem = {'objective': 'cd', 'seed': 0}  # kept before the settle was
    (tmp_path / PROBLEM_FILE).write_text(json.dumps({study_key(Spec): problem}))
    check_problem(Spec, {**problem, 'settle': 'full'}, journal)
    with pytest.raises(InputError, match=r'\(settle changed\)'):
        check_problem(Spec, {**problem, 'settle': 'fast'}, journal)


@pytest.mark.parametrize('command', [['identify'], ['rank', 'bag'], ['sweep']])
def test_every_command_settles_in_full_unless_asked(command):
    assert build_parser().parse_args(command).settle == 'full'
    assert build_parser().parse_args([*command, '--settle', 'fast']).settle == 'fast'


@pytest.mark.parametrize('argv', [['rank', 'bag', '--settle', 'slow'], ['run', '--settle', 'fast'],
                                  ['identify', '--settle', '']])
def test_a_settle_that_is_not_one_or_a_command_without_it_is_exit_2(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(argv)
    assert exc.value.code == 2
    assert '--settle' in capsys.readouterr().err
