"""A cloth of another size than the benchmark's 0.5 x 0.7 m, and its mass (--cloth-size/-mass)."""

from __future__ import annotations

import csv
import json

from cloth_bench_ros import cli
from cloth_bench_ros.core.cloth_size import BENCHMARK_AREA, cloth_grid
from cloth_bench_ros.core.scene import ClothGrid
from cloth_bench_ros.core.trajectory import full_targets
from cloth_bench_ros.engines import make_engine
from cloth_bench_ros.engines.presets import load_preset, sized_params
from cloth_bench_ros.errors import InputError
from cloth_bench_ros.identify.objective import evaluate, Trial
from cloth_bench_ros.studies.direct import run_direct
from cloth_bench_ros.studies.run_pipeline import RunConfig
from cloth_bench_ros.validation import parse_cloth_size
import numpy as np
import pytest

SIZE = (0.4, 0.6)


@pytest.mark.parametrize('text, message', [
    ('0.4', 'is not W,L in metres'),
    ('0.4,0.6,0.1', 'is not W,L in metres'),
    ('0.4,wide', "'wide' is not a number"),
    ('0.9,0.6', 'width: 0.9 m is outside [0.1, 0.8]'),
    ('0.4,0.8', 'length: 0.8 m is outside [0.1, 0.75]'),
    ('0.4,nan', 'not a finite number'),
])
def test_a_malformed_or_out_of_range_size_is_refused(text, message):
    with pytest.raises(InputError, match=message.replace('[', r'\[').replace(']', r'\]')):
        parse_cloth_size(text, '--cloth-size')
    assert parse_cloth_size('0.4, 0.6') == SIZE and parse_cloth_size('') is None


@pytest.mark.parametrize('args, message', [
    (['--cloth-size', '0.4'], "--cloth-size '0.4' is not W,L in metres"),
    (['--cloth-size', '0.3,0.9'], '--cloth-size length: 0.9 m is outside'),
    (['--cloth-mass', '0.2', '--set', 'mujoco.mass=1'], '--cloth-mass and --set mujoco.mass'),
])
def test_the_cli_says_a_bad_cloth_in_one_line_and_exits_2(args, message, tmp_path, capsys):
    assert cli.main(['run', '--output', str(tmp_path / 'out'), *args]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1, err
    with pytest.raises(SystemExit) as refused:  # argparse: the declared range, exit 2
        cli.main(['run', '--cloth-mass', '-1'])
    assert refused.value.code == 2
    assert 'outside [0.0001, 100]' in capsys.readouterr().err


def test_the_mesh_keeps_the_spacing_or_spans_the_given_grid():
    assert cloth_grid(None, None) is None and cloth_grid((6, 8), (0.5, 0.7)) == ClothGrid(6, 8)
    kept = cloth_grid(None, SIZE)
    assert (kept.nx, kept.nz) == (9, 13) and kept.spacing == pytest.approx(ClothGrid().spacing)
    given = cloth_grid((5, 7), SIZE)
    rest = given.vertices()
    assert (given.nx, given.nz) == (5, 7)
    assert rest.min(axis=0) == pytest.approx([0.0, 0.0, 1.0 - 0.6])
    assert rest.max(axis=0) == pytest.approx([0.4, 0.0, 1.0])


def test_the_right_gripper_holds_the_corner_of_the_cloths_width():
    bench, narrow = full_targets('dynamic', 100.0), full_targets('dynamic', 100.0, 0.4)
    assert narrow.right[0] == pytest.approx([0.4, 0.0, 1.0])
    assert np.array_equal(narrow.left, bench.left)
    assert np.allclose(narrow.right[:, 0] - bench.right[:, 0], -0.1)
    assert np.array_equal(narrow.right[:, 1:], bench.right[:, 1:])  # heights: the task's own
    assert np.array_equal(full_targets('dynamic', 100.0, 0.5).right, bench.right)


@pytest.mark.parametrize('engine', ['mujoco', 'newton', 'bullet'])
def test_a_resized_cloth_has_that_extent_and_that_mass(engine):
    """The mesh spans 0.4 x 0.6 m; the engine's model carries the given total mass."""
    if engine == 'newton':
        pytest.importorskip('newton')
    preset = load_preset(engine, 'towel', 'dynamic')
    params = sized_params(engine, preset, SIZE, 0.2)
    assert params['mass'] == 0.2
    per_area = sized_params(engine, preset, SIZE, None)['mass']
    assert per_area == pytest.approx(preset['mass'] / BENCHMARK_AREA * 0.24)
    cloth = make_engine(engine, 100.0, params, cloth_grid((5, 7), SIZE))
    try:
        start = cloth.start(0, np.array([0.02, 0.0, 1.0]), np.array([0.398, 0.0, 1.0]))
        assert start.shape == (35, 3)
        assert np.ptp(start[:, 0]) == pytest.approx(0.378, abs=0.003)  # between the grippers
        assert np.ptp(start[:, 2]) == pytest.approx(0.6, abs=0.003)  # hangs its length
        if engine == 'mujoco':  # the flex as compiled, before its corners become grippers
            import mujoco

            model = mujoco.MjModel.from_xml_string(cloth._mjcf())
            assert model.body_mass[model.flex_vertbodyid].sum() == pytest.approx(0.2)
        if engine == 'newton':  # the free particles carry the whole mass
            assert float(cloth.model.particle_mass.numpy().sum()) == pytest.approx(0.2, rel=1e-6)
    finally:
        cloth.close()


def test_a_resized_trial_runs_and_is_recorded(hanging_bag, tmp_path):
    """The identification's trial and a run both run the 0.4 x 0.6 m cloth and record it."""
    trial = Trial('mujoco', 'towel', 'dynamic', str(hanging_bag), (), grid=(5, 7),
                  max_frames=6, cloth_size=SIZE, cloth_mass=0.2)
    scored = evaluate(trial)
    assert scored['status'] == 'ok' and scored['frames'] == 6, scored
    same = evaluate(Trial('mujoco', 'towel', 'dynamic', str(hanging_bag), (('mass', 0.2),),
                          grid=(5, 7), max_frames=6, cloth_size=SIZE))
    assert same['CD'] == scored['CD']  # the given mass is the engine's mass
    bench = evaluate(Trial('mujoco', 'towel', 'dynamic', str(hanging_bag), (), grid=(5, 7),
                           max_frames=6))
    assert bench['CD'] != scored['CD']
    summary = run_direct(RunConfig(bag=hanging_bag, grid=(5, 7), cloth_size=SIZE,
                                   cloth_mass=0.2, output_dir=tmp_path / 'run'))
    assert summary['engines']['mujoco']['frames_scored'] > 0
    written = json.loads((tmp_path / 'run' / 'summary.json').read_text())
    assert written['run']['cloth_size'] == [0.4, 0.6] and written['run']['cloth_mass'] == 0.2


def test_the_benchmark_size_and_its_preset_mass_give_the_default_run_bit_for_bit(
    hanging_bag, tmp_path
):
    """Unset, or set to the benchmark's cloth: the same run, frame for frame."""
    mass = load_preset('bullet', 'towel', 'dynamic')['mass']
    runs = {}
    for name, size, given in (('unset', None, None), ('benchmark', (0.5, 0.7), mass)):
        run_direct(RunConfig(bag=hanging_bag, engines=['bullet'], grid=(6, 8), cloth_size=size,
                             cloth_mass=given, output_dir=tmp_path / name))
        with open(tmp_path / name / 'frames.csv') as f:
            runs[name] = list(csv.DictReader(f))
    drop = ('step_time', 'latency')
    strip = [[{k: v for k, v in r.items() if not k.startswith(drop)} for r in rows]
             for rows in runs.values()]
    assert strip[0] == strip[1] and len(strip[0]) > 0


@pytest.mark.slow
def test_a_recordings_gripper_targets_are_checked_against_the_cloths_width(tmp_path, capsys):
    """Targets recorded 0.478 m apart (the benchmark's pre-grasp): a 0.4 m cloth differs."""
    from camera_recording import CAMERA_TOPIC, make_repeated_recording, TARGETS_TOPIC
    from cloth_bench_ros.paths import bundled_bag

    bag = tmp_path / 'rec'
    make_repeated_recording(bundled_bag('towel', 'dynamic'), bag, repetitions=1, rest_s=1.0,
                            seed=5, targets_rate=30.0)
    # --motion task: the targets topic sets the start, the engines follow the task's quintic
    base = ['run', '--bag', str(bag), '--topic', CAMERA_TOPIC, '--targets-topic', TARGETS_TOPIC,
            '--motion', 'task', '--grid', '5x7']
    assert cli.main([*base, '--output', str(tmp_path / 'a'), '--cloth-size', '0.4,0.6']) == 0
    printed = capsys.readouterr().out
    assert "grasp: the recording's gripper targets are 0.478 m apart, the simulated corners " \
        '0.400 m (0.40 x 0.60 m cloth)' in printed, printed
    summary = json.loads((tmp_path / 'a' / 'summary.json').read_text())
    assert summary['real']['targets_grasp_m'] == pytest.approx(0.478)
    assert cli.main([*base, '--output', str(tmp_path / 'b'), '--cloth-size', '0.5,0.7']) == 0
    assert 'gripper targets are' not in capsys.readouterr().out  # they agree: nothing to say
