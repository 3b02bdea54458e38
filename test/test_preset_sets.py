"""
Named preset sets (`--presets default|identified|identified-newton-vbd|DIR`) in every command.

Real preset files, written by the identification's own writer and merged as the shipped sets are.
"""

from __future__ import annotations

from pathlib import Path

from cloth_bench_ros.cli import main
from cloth_bench_ros.engines import presets
from cloth_bench_ros.engines.base import EngineError
from cloth_bench_ros.studies.cells import paper_cells, settings_cells
from cloth_bench_ros.studies.stress_cases import select_cases
import pytest
import yaml


def _identified_file(folder: Path, engine: str, primitive: str, values: dict) -> Path:
    """Write what identify --output writes: the shipped preset with fitted values."""
    folder.mkdir(parents=True)
    doc = {
        'engine': engine,
        'engine_version': '1',
        'provenance': f'fitted {primitive}',
        'presets': {
            'towel': {primitive: {**presets.load_preset(engine, 'towel', primitive), **values}}
        },
    }
    path = folder / f'{engine}.yaml'
    path.write_text(yaml.safe_dump(doc))
    return path


@pytest.fixture
def identified(tmp_path) -> Path:
    """Return a set directory merged from two identifications (fling, lower-and-drag)."""
    files = [
        _identified_file(tmp_path / 'a', 'mujoco', 'dynamic', {'mass': 0.2}),
        _identified_file(tmp_path / 'b', 'mujoco', 'quasi_static', {'mass': 0.3}),
    ]
    out = tmp_path / 'set'
    assert presets.merge_identified(files, out) == [out / 'mujoco.yaml']
    return out


def test_a_set_is_a_name_or_a_directory_and_anything_else_is_one_line(tmp_path):
    assert presets.preset_set(None).is_default and presets.preset_set('default').is_default
    named = presets.preset_set('identified')
    assert named.directory == presets.config_dir() / 'presets' / 'identified'
    assert presets.preset_set(str(tmp_path)).directory == tmp_path
    with pytest.raises(EngineError, match='neither a preset set .*identified-newton-vbd'):
        presets.preset_set(str(tmp_path / 'nowhere'))
    assert presets.identified_set_of('newton-vbd') == 'identified-newton-vbd'


def test_merged_identifications_keep_each_task_and_its_provenance(identified):
    assert presets.load_preset('mujoco', 'towel', 'dynamic', identified)['mass'] == 0.2
    assert presets.load_preset('mujoco', 'towel', 'quasi_static', identified)['mass'] == 0.3
    text = (identified / 'mujoco.yaml').read_text()
    assert 'towel dynamic (shell): fitted dynamic' in text
    assert 'towel quasi_static (shell): fitted' in text
    with pytest.raises(EngineError, match='no preset for linen dynamic'):
        presets.load_preset('mujoco', 'linen', 'dynamic', identified)


def test_a_new_identification_extends_a_merged_set_and_replaces_its_entry(identified, tmp_path):
    again = _identified_file(tmp_path / 'c', 'mujoco', 'dynamic', {'mass': 0.25})
    before = (identified / 'mujoco.yaml').read_text()
    assert presets.merge_identified([again], identified) == [identified / 'mujoco.yaml']
    assert presets.load_preset('mujoco', 'towel', 'dynamic', identified)['mass'] == 0.25
    assert presets.load_preset('mujoco', 'towel', 'quasi_static', identified)['mass'] == 0.3
    doc = presets.read_preset_file(identified / 'mujoco.yaml')
    assert doc['provenance'].splitlines() == [
        'towel dynamic (shell): fitted dynamic', 'towel quasi_static (shell): fitted quasi_static']
    presets.merge_identified([again], identified)  # the same again: the same file
    first = _identified_file(tmp_path / 'd', 'mujoco', 'dynamic', {'mass': 0.2})
    presets.merge_identified([first], identified)
    assert (identified / 'mujoco.yaml').read_text() == before
    (tmp_path / 'plain').mkdir()
    (tmp_path / 'plain' / 'mujoco.yaml').write_text(
        (presets.config_dir() / 'presets' / 'mujoco.yaml').read_text())
    with pytest.raises(EngineError, match='names no entry .*not a merged set'):
        presets.merge_identified([again], tmp_path / 'plain')  # the shipped presets: refused


def test_the_shipped_identified_sets_are_merged_sets():
    for name in presets.IDENTIFIED_SETS:
        folder = presets.config_dir() / 'presets' / name
        for path in sorted(folder.glob('*.yaml')):
            doc = presets.read_preset_file(path)
            entries = [f'{c} {p} ({m})' for c, tasks in doc['presets'].items()
                       for p, models in tasks.items() for m in models]
            keys = [line.split(': ')[0] for line in doc['provenance'].splitlines()]
            assert keys == entries, path


def test_sweep_settings_and_stress_cells_carry_the_set_as_overrides(identified):
    chosen = presets.preset_set(str(identified))
    cells = paper_cells(['mujoco'], [100.0], ['towel'], ['dynamic'], [0], presets=chosen,
                        overrides={'mujoco': {'damping': 0.5}})
    (cell,) = cells
    assert cell.params['mass'] == 0.2 and cell.params['damping'] == 0.5  # --set on top
    assert cell.config == f'presets={identified},damping=0.5'
    assert cell.preset_set == str(identified)
    (plain,) = paper_cells(['mujoco'], [100.0], ['towel'], ['dynamic'], [0])
    assert plain.config == 'preset' and plain.key() != cell.key()  # resumable side by side
    settings = settings_cells(['mujoco'], 100.0, ['towel'], ['quasi_static'], [0],
                              axes={'solver_iterations': [5]}, presets=chosen)
    assert {c.params['mass'] for c in settings} == {0.3}
    assert all(c.config.startswith(f'presets={identified},') for c in settings)
    cases = select_cases(['mujoco'], ['fling_10hz'], presets=chosen)
    assert cases and all(c.params['mass'] == 0.2 and c.params['timestep'] == 0.1 for c in cases)


@pytest.mark.parametrize('command', [['run'], ['sweep', '--dry-run'], ['hil'], ['stress']])
def test_every_command_takes_presets_and_refuses_an_unknown_set_in_one_line(command, capsys):
    assert main([*command, '--presets', 'fitted-somewhere']) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and 'neither a preset set' in err


def test_a_sweep_over_the_default_cloths_keeps_what_the_set_covers(tmp_path, capsys):
    """A set of the towel fling for MuJoCo only: the default sweep runs that, and says so."""
    folder = tmp_path / 'set'
    presets.merge_identified(
        [_identified_file(tmp_path / 'a', 'mujoco', 'dynamic', {'mass': 0.2})], folder
    )
    assert main(['sweep', '--dry-run', '--engine', 'mujoco', '--presets', str(folder),
                 '--seeds', '1', '--rate', '100', '--output', str(tmp_path / 'out')]) == 0
    out = capsys.readouterr().out
    assert 'cloth-bench sweep: 1 cells' in out
    assert 'no values for mujoco chequered dynamic' in out and 'mujoco towel quasi_static' in out
    # named cloth and task: the user insists, so a missing entry is an error
    assert main(['sweep', '--dry-run', '--engine', 'mujoco', '--presets', str(folder),
                 '--cloth', 'towel', '--primitive', 'quasi_static']) == 2
    assert 'no preset for towel quasi_static' in capsys.readouterr().err
    assert main(['sweep', '--dry-run', '--engine', 'mujoco', '--presets', str(folder),
                 '--cloth', 'linen']) == 2
    assert 'has no values for linen' in capsys.readouterr().err
