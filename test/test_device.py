"""
Newton's device: `--device cpu|cuda[:N]|auto` on every command, refused when absent, named.

The expectations follow what Warp finds here (CUDA), so the same tests pass on a machine with a
GPU and still fail where `auto` resolves to anything but Warp's first CUDA device, else the CPU.
"""

from __future__ import annotations

import json

from cloth_bench_ros import validation
from cloth_bench_ros.cli import build_parser, main
from cloth_bench_ros.cli.studies_command import say_fitted_elsewhere
from cloth_bench_ros.core.scene import ClothGrid, GRIPPER_START_LEFT, GRIPPER_START_RIGHT
from cloth_bench_ros.engines import engine_device, make_engine
from cloth_bench_ros.engines.base import EngineError
from cloth_bench_ros.engines.newton_cloth import available_devices, NewtonCloth, resolve_device
from cloth_bench_ros.engines.presets import fitted_device, load_preset, preset_set
from cloth_bench_ros.identify.output import write_outputs
from cloth_bench_ros.identify.spec import IdentifySpec
from cloth_bench_ros.paths import bundled_bag
from cloth_bench_ros.studies.cells import Cell, paper_cells
from cloth_bench_ros.studies.direct import run_direct
from cloth_bench_ros.studies.results import row_key
from cloth_bench_ros.studies.run_config import RunConfig
from cloth_bench_ros.studies.run_pipeline import node_parameters
from cloth_bench_ros.sweep.study import error_row
import numpy as np
import pytest
import warp as wp

CUDA = wp.get_cuda_device_count()
ABSENT = f'cuda:{CUDA}'  # one past the last CUDA device: never on this machine
AUTO = 'cuda:0' if CUDA else 'cpu'  # where `auto` must run, from what Warp reports


def test_device_spelling_is_checked_in_the_validation_layer():
    for good in ('cpu', 'cuda', 'cuda:0', 'cuda:12', 'auto'):
        assert validation.device(good, '--device') == good
    for bad in ('gpu', 'cuda:', 'cuda:-1', 'CPU', 3, ''):
        with pytest.raises(validation.InputError, match='--device'):
            validation.device(bad, '--device')


def test_default_is_cuda_when_warp_finds_one_else_cpu():
    assert available_devices()[0] == 'cpu'
    assert resolve_device('auto') == AUTO
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


def test_auto_runs_on_warps_first_cuda_device_else_the_same_engine_as_cpu():
    """`auto` is cuda:0 where Warp finds CUDA; without it, the `cpu` engine bit for bit."""
    runs = []
    for params, device in (({'model': 'xpbd'}, AUTO), ({'model': 'xpbd', 'device': 'cpu'}, 'cpu')):
        engine = make_engine('newton', 100.0, params, ClothGrid(4, 5))
        assert engine.device == device
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
    row = error_row(cell, 'not run')  # a sweep's row names it, and resumes by it
    assert row['device'] == 'cpu' and row_key(row) == cell.key()
    assert Cell('newton', 100.0, 'towel', 'dynamic', 0, 'bag').device == AUTO
    assert Cell('mujoco', 100.0, 'towel', 'dynamic', 0, 'bag').device == 'cpu'


def test_engines_lists_the_devices_found(capsys):
    assert main(['engines']) == 0
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert last.startswith('devices: ')
    assert f'newton {", ".join(available_devices())}' in last and 'mujoco cpu' in last


def test_identified_provenance_names_the_device_and_the_preset_does_not(tmp_path):
    from types import SimpleNamespace

    from cloth_bench_ros.identify.output import provenance_text

    spec = SimpleNamespace(
        engine='newton', bag=tmp_path / 'no_bag', cloth='towel', primitive='dynamic',
        objective='cd', seed=0, rate_hz=100.0, grid=None, max_frames=None, settle='full',
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


def test_engines_warm_compiles_newton_on_every_device_warp_finds(monkeypatch):
    warmed = []
    reset = NewtonCloth.reset

    def noted(self, *args):
        warmed.append((self.device, self.config['model'], self.config['self_collision']))
        return reset(self, *args)

    monkeypatch.setattr(NewtonCloth, 'reset', noted)
    NewtonCloth.warm()
    assert sorted(warmed) == sorted(
        (device, model, collide) for device in available_devices()
        for model in ('xpbd', 'vbd') for collide in (False, True))


def test_a_preset_fitted_on_another_device_says_so_in_one_line(hanging_bag, tmp_path, capsys):
    """The identification's provenance names its device; a run elsewhere says so, once."""
    spec = IdentifySpec('newton', 'towel', 'dynamic', hanging_bag, tmp_path / 'ident', 'tpe', 8,
                        'cd', ['mass'], grid=(6, 8), validate_seeds=0, fixed={'device': 'cpu'})
    summary = {'params': {'mass': 0.2}, 'value': 0.031, 'preset_value': 0.036,
               'best_sampler': 'tpe', 'per_sampler': {'tpe': {'trials': 8}}}
    spec.output.mkdir()
    preset = write_outputs(spec, load_preset('newton', 'towel', 'dynamic'), summary)
    assert fitted_device('newton', 'towel', 'dynamic', preset.parent, 'vbd') == 'cpu'
    assert json.loads((spec.output / 'identification.json').read_text())['device'] == 'cpu'
    # As if it had been fitted on a GPU: the recorded device changed in the file.
    preset.write_text(preset.read_text().replace('on device cpu;', 'on device cuda:0;'))
    assert fitted_device('newton', 'towel', 'dynamic', preset.parent, 'vbd') == 'cuda:0'
    assert fitted_device('newton', 'towel', 'dynamic') is None  # hand-set: no device named
    assert main(['run', '--engine', 'newton', '--grid', '6x8', '--bag', str(hanging_bag),
                 '--output', str(tmp_path / 'run'), '--presets', str(preset.parent),
                 '--device', 'cpu']) == 0
    said = [line for line in capsys.readouterr().out.splitlines() if 'fitted on' in line]
    assert said == ['newton: its preset was fitted on cuda:0, it runs on cpu here: the device'
                    ' changes the numbers (docs/engines.md, "Device")']
    # A sweep's cells with that set: the same line, once for the engine (two seeds, one line).
    cells = paper_cells(['newton'], [100.0], ['towel'], ['dynamic'], [0, 1],
                        overrides={'newton': {'device': 'cpu'}},
                        presets=preset_set(str(preset.parent)))
    say_fitted_elsewhere(cells, preset.parent)
    assert capsys.readouterr().out.splitlines() == said


@pytest.mark.slow
def test_the_deterministic_option_runs_and_changes_nothing_on_the_cpu():
    """Warp orders no atomics on the CPU: the same numbers; on CUDA it is unmeasured here."""
    for model in ('xpbd', 'vbd'):
        runs = []
        for mode in ('off', 'run_to_run'):
            engine = make_engine('newton', 100.0, {'model': model, 'device': 'cpu',
                                                   'deterministic': mode}, ClothGrid(4, 5))
            vertices = engine.start(0, GRIPPER_START_LEFT, GRIPPER_START_RIGHT)
            for _ in range(5):
                vertices = engine.step(GRIPPER_START_LEFT + 0.01, GRIPPER_START_RIGHT + 0.01)
            runs.append(vertices)
            engine.close()
        assert np.isfinite(runs[0]).all() and np.array_equal(runs[0], runs[1]), model
    with pytest.raises(EngineError, match='parameter deterministic'):
        make_engine('newton', 100.0, {'deterministic': 'always'}, ClothGrid(3, 3))
    cell = Cell('newton', 100.0, 'towel', 'dynamic', 0, 'bag', config='deterministic=run_to_run',
                overrides=(('deterministic', 'run_to_run'),))
    assert cell.key() != Cell('newton', 100.0, 'towel', 'dynamic', 0, 'bag').key()
