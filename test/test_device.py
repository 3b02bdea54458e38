"""Newton's device: `--device cpu|cuda[:N]|auto` on every command, refused when absent, named."""

from __future__ import annotations

from cloth_bench_ros import validation
from cloth_bench_ros.cli import build_parser, main
from cloth_bench_ros.core.scene import ClothGrid, GRIPPER_START_LEFT, GRIPPER_START_RIGHT
from cloth_bench_ros.engines import engine_device, make_engine
from cloth_bench_ros.engines.base import EngineError
from cloth_bench_ros.engines.newton_cloth import available_devices, resolve_device
from cloth_bench_ros.paths import bundled_bag
from cloth_bench_ros.studies.cells import Cell
from cloth_bench_ros.studies.direct import run_direct
from cloth_bench_ros.studies.run_config import RunConfig
from cloth_bench_ros.studies.run_pipeline import node_parameters
import numpy as np
import pytest
import warp as wp

CUDA = wp.get_cuda_device_count()
ABSENT = f'cuda:{CUDA}'  # one past the last CUDA device: never on this machine


def test_device_spelling_is_checked_in_the_validation_layer():
    for good in ('cpu', 'cuda', 'cuda:0', 'cuda:12', 'auto'):
        assert validation.device(good, '--device') == good
    for bad in ('gpu', 'cuda:', 'cuda:-1', 'CPU', 3, ''):
        with pytest.raises(validation.InputError, match='--device'):
            validation.device(bad, '--device')


def test_default_is_cuda_when_warp_finds_one_else_cpu():
    assert available_devices()[0] == 'cpu'
    assert resolve_device('auto') == ('cuda:0' if CUDA else 'cpu')
    assert engine_device('newton') == resolve_device('auto')
    assert engine_device('mujoco') == 'cpu'


def test_absent_device_is_refused_naming_what_was_found():
    with pytest.raises(EngineError, match=r'is not on this machine \(Warp found: cpu'):
        resolve_device(ABSENT)
    if not CUDA:
        with pytest.raises(EngineError, match='cuda is not on this machine'):
            make_engine('newton', 100.0, {'device': 'cuda'}, ClothGrid(3, 3))


@pytest.mark.parametrize('command', [
    ['run', '--engine', 'newton'],
    ['sweep'],
    ['identify', '--engine', 'newton'],
    ['hil', '--engine', 'newton'],
    ['converge', '--reference', 'newton-vbd'],
    ['stress', '--engine', 'newton'],
    ['cross-reference'],
    ['synth', '--reference', 'newton-vbd'],
])
def test_every_command_refuses_an_absent_device_in_one_line(command, capsys):
    with pytest.raises(SystemExit) as exit_:
        main([*command, '--device', ABSENT])
    assert exit_.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert f'{ABSENT} is not on this machine (Warp found: {", ".join(available_devices())})' in err


def test_device_option_becomes_newtons_engine_override():
    args = build_parser().parse_args(['run', '--set', 'newton.model=xpbd', '--device', 'cpu'])
    assert args.set == ['newton.model=xpbd', 'newton.device=cpu']
    assert main(['run', '--engine', 'mujoco', '--device', 'cpu']) == 2  # no Newton in the run


def test_cpu_device_runs_what_the_default_cpu_engine_runs():
    """On a machine without CUDA, `auto` and `cpu` are the same engine, bit for bit."""
    runs = []
    for params in ({'model': 'xpbd'}, {'model': 'xpbd', 'device': 'cpu'}):
        engine = make_engine('newton', 100.0, params, ClothGrid(4, 5))
        assert engine.device == 'cpu'
        vertices = engine.start(0, GRIPPER_START_LEFT, GRIPPER_START_RIGHT)
        for _ in range(5):
            vertices = engine.step(GRIPPER_START_LEFT, GRIPPER_START_RIGHT)
        runs.append(vertices)
        engine.close()
    if not CUDA:
        assert np.array_equal(runs[0], runs[1])


def test_runs_and_result_keys_name_the_device():
    config = RunConfig(
        bag=bundled_bag('towel', 'dynamic'),
        engines=['newton'],
        engine_params={'newton': {'model': 'xpbd', 'device': 'cpu'}},
        grid=(4, 5),
    )
    assert node_parameters(config)['evaluator']['devices'] == 'cpu'
    assert node_parameters(config)['simulator_newton']['engine_params'].count('device: cpu')
    summary = run_direct(config)
    assert summary['run']['devices'] == {'newton': 'cpu'}
    cell = Cell('newton', 100.0, 'towel', 'dynamic', 0, 'bag', overrides=(('device', 'cpu'),))
    assert cell.device == 'cpu' and 'cpu' in cell.key()
    assert Cell('mujoco', 100.0, 'towel', 'dynamic', 0, 'bag').device == 'cpu'


def test_engines_lists_the_devices_found(capsys):
    assert main(['engines']) == 0
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert last.startswith('devices: ')
    assert f'newton {", ".join(available_devices())}' in last and 'mujoco cpu' in last


def test_identified_provenance_names_the_device_and_the_preset_does_not(tmp_path):
    from types import SimpleNamespace

    from cloth_bench_ros.studies.identify_output import provenance_text

    spec = SimpleNamespace(
        engine='newton', bag=tmp_path / 'no_bag', cloth='towel', primitive='dynamic',
        objective='cd', seed=0, rate_hz=100.0, grid=None, max_frames=None,
        fixed={'model': 'xpbd', 'device': 'cpu'},
    )
    summary = {
        'params': {'mass': 0.2}, 'value': 0.03, 'preset_value': 0.04, 'best_sampler': 'tpe',
        'per_sampler': {'tpe': {'trials': 3}},
    }
    text = provenance_text(spec, summary, '1.8.0')
    assert 'on device cpu' in text and 'fixed model = xpbd;' in text
    assert 'trials: tpe 3; seed 0' in text  # a full-fidelity study says nothing of rungs
    spec.fidelity = 'coarse'
    summary['per_sampler']['tpe']['pruned'] = 2
    text = provenance_text(spec, summary, '1.8.0')
    assert 'trials: tpe 3; multi-fidelity coarse, 2 stopped at a rung; seed 0' in text
