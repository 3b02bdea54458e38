"""The direct study path gives the node graph's metrics bit for bit, cell by cell."""

import csv
import math

from cloth_bench_ros.identify.objective import evaluate, Trial
from cloth_bench_ros.paths import share_dir
from cloth_bench_ros.studies.direct import run_direct
from cloth_bench_ros.studies.run_pipeline import run_pipeline, RunConfig
import pytest

GRID = (6, 8)
TIMING = {'step_time', 'latency', 'deadline_misses', 'real_time_factor'}


def _same(a, b, where: str) -> None:
    """Assert two summaries' values are equal, NaN equal to NaN, float for float."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and list(a) == list(b), where
        for key in a:
            _same(a[key], b[key], f'{where}.{key}')
    elif isinstance(a, float) and math.isnan(a):
        assert isinstance(b, float) and math.isnan(b), where
    else:
        assert type(a) is type(b) and a == b, f'{where}: {a!r} != {b!r}'


def _frames(path):
    with open(path) as f:
        return list(csv.reader(f))


CELLS = {
    'mujoco-100hz-hanging': {'engines': ['mujoco'], 'rate_hz': 100.0},
    'bullet-10hz-towel-drag': {
        'engines': ['bullet'],
        'rate_hz': 10.0,
        'primitive': 'quasi_static',
        'bag': 'towel_quasi_static',
    },
    # Newton's one cell (its 1 kHz run is the longest): beside another engine, on another seed
    'mujoco-newton-1khz-seed-3': {'engines': ['mujoco', 'newton'], 'rate_hz': 1000.0, 'seed': 3},
    'resized-cloth-two-engines': {  # --cloth-size and --cloth-mass reach every node
        'engines': ['mujoco', 'bullet'],
        'rate_hz': 100.0,
        'cloth_size': (0.4, 0.6),
        'cloth_mass': 0.2,
    },
    'two-engines-overrides': {
        'engines': ['mujoco', 'bullet'],
        'rate_hz': 100.0,
        'engine_params': {'mujoco': {'damping': 0.5}},
    },
}


@pytest.mark.parametrize('name', [  # the quick tier compares the first cell; the others are slow
    pytest.param(name, marks=() if k == 0 else pytest.mark.slow) for k, name in enumerate(CELLS)
])
def test_direct_cell_equals_the_node_graph(name, hanging_bag, tmp_path):
    if 'newton' in CELLS[name]['engines']:
        pytest.importorskip('newton')
    kw = dict(CELLS[name])
    bag = share_dir('bags') / kw.pop('bag') if 'bag' in kw else hanging_bag
    graph = run_pipeline(RunConfig(bag=bag, grid=GRID, output_dir=tmp_path / 'graph', **kw))
    direct = run_direct(RunConfig(bag=bag, grid=GRID, output_dir=tmp_path / 'direct', **kw))
    for engine, metrics in graph['engines'].items():
        assert metrics['frames_scored'] > 0
        assert metrics['step_time']['count'] == direct['engines'][engine]['step_time']['count']
        _same(
            {k: v for k, v in metrics.items() if k not in TIMING},
            {k: v for k, v in direct['engines'][engine].items() if k not in TIMING},
            f'engines.{engine}',
        )
    _same(graph['real'], direct['real'], 'real')
    _same(
        {k: v for k, v in graph['run'].items() if k != 'wall_time'},
        {k: v for k, v in direct['run'].items() if k != 'wall_time'},
        'run',
    )
    frames = _frames(tmp_path / 'graph' / 'frames.csv')
    assert frames == _frames(tmp_path / 'direct' / 'frames.csv')


def test_the_direct_path_refuses_what_needs_the_node_graph(hanging_bag):
    with pytest.raises(ValueError, match='realtime pacing'):
        run_direct(RunConfig(bag=hanging_bag, grid=GRID, pacing='realtime'))


def test_an_identification_trial_scores_as_a_run(hanging_bag):
    """Identification's objective starts, rounds and scores a trial as the run of its cell."""
    params = {'damping': 0.5}
    trial = Trial(
        engine='mujoco',
        cloth='towel',
        primitive='dynamic',
        bag=str(hanging_bag),
        params=tuple(sorted(params.items())),
        rate_hz=100.0,
        grid=GRID,
    )
    scored = evaluate(trial)
    run = run_direct(RunConfig(bag=hanging_bag, grid=GRID, engine_params={'mujoco': params}))
    metrics = run['engines']['mujoco']
    assert scored['status'] == 'ok' and scored['frames'] == metrics['frames_in_window'] > 0
    assert (scored['CD'], scored['HD']) == (metrics['CD_d'], metrics['HD_d'])
