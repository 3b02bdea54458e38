"""
Preset sets hold one entry per engine model; `--presets` gives the entry of the model that runs.

Real Newton runs on the coarse 6 x 8 mesh (XPBD from the shipped set, VBD from a set where a
Newton VBD identification, as the identification writes it, was merged beside the shipped XPBD
entry), and malformed layouts refused in one line.
"""

from __future__ import annotations

import json
from pathlib import Path

from cloth_bench_ros.cli import main
from cloth_bench_ros.engines import presets
from cloth_bench_ros.engines.base import EngineError
from cloth_bench_ros.engines.newton_cloth import resolve_device
from cloth_bench_ros.identify.output import write_outputs
from cloth_bench_ros.identify.spec import IdentifySpec
from cloth_bench_ros.paths import share_dir
from cloth_bench_ros.studies.run_pipeline import run_pipeline, RunConfig
import pytest
import yaml

GRID = (6, 8)
AUTO = resolve_device('auto')  # where Newton runs by default here
SHIPPED = presets.config_dir() / 'presets' / 'identified' / 'newton.yaml'


def _run(bag: Path, out: Path, *argv: str) -> list[str]:
    return ['run', '--engine', 'newton', '--grid', '6x8', '--bag', str(bag), '--output',
            str(out), *argv]


def _one_line_error(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    return err


@pytest.mark.slow
def test_the_identified_set_gives_the_xpbd_entry_when_xpbd_runs(hanging_bag, tmp_path, capsys):
    entry = presets.load_preset('newton', 'towel', 'dynamic', SHIPPED.parent, 'xpbd')
    shipped = presets.read_preset_file(SHIPPED)['presets']['towel']['dynamic']['xpbd']
    assert entry == shipped and entry['model'] == 'xpbd'
    assert main(_run(hanging_bag, tmp_path / 'ident', '--presets', 'identified',
                     '--set', 'newton.model=xpbd')) == 0
    header = capsys.readouterr().out.splitlines()[0]
    assert header.endswith(f'newton (xpbd) on {AUTO}'), header
    summary = json.loads((tmp_path / 'ident' / 'summary.json').read_text())
    assert summary['run']['models'] == {'newton': 'xpbd'}
    # The set's values reached the engine: the shipped preset's XPBD scores otherwise.
    plain = run_pipeline(RunConfig(bag=hanging_bag, engines=['newton'], grid=GRID,
                                   engine_params={'newton': {'model': 'xpbd'}}))
    assert plain is not None and plain['run']['models'] == {'newton': 'xpbd'}
    cd = summary['engines']['newton']['CD_d']
    assert 0 < cd < 1 and cd != plain['engines']['newton']['CD_d']


def test_the_shipped_sets_give_newton_vbd_its_identified_entry_where_one_was_fitted():
    """The default model (VBD) runs with the set's VBD entry; its provenance says how."""
    for name in presets.IDENTIFIED_SETS:
        folder = presets.config_dir() / 'presets' / name
        data = presets.read_preset_file(folder / 'newton.yaml')
        shipped = data['presets']['towel']['dynamic']
        assert set(shipped) == {'xpbd', 'vbd'} and shipped['vbd']['model'] == 'vbd'
        assert presets.load_preset('newton', 'towel', 'dynamic', folder) == shipped['vbd']
        assert presets.load_preset('newton', 'towel', 'dynamic', folder, 'xpbd') == shipped['xpbd']
        paragraph = next(p for p in data['provenance'].splitlines()
                         if p.startswith('towel dynamic (vbd): '))
        assert 'multi-fidelity coarse' in paragraph and 'Held-out seeds (CD)' in paragraph
        assert 'on device cpu' in paragraph


def _xpbd_only_set(folder: Path) -> Path:
    """Write the shipped identified set with its Newton VBD entries left out; return the folder."""
    folder.mkdir()
    for source in SHIPPED.parent.glob('*.yaml'):
        data = presets.read_preset_file(source)
        if source.name == 'newton.yaml':
            for tasks in data['presets'].values():
                for entries in tasks.values():
                    entries.pop('vbd', None)
            data['provenance'] = '\n'.join(
                p for p in data['provenance'].splitlines() if '(vbd): ' not in p)
        (folder / source.name).write_text(yaml.safe_dump(data, sort_keys=False))
    return folder


def test_vbd_without_a_vbd_entry_is_refused_in_one_line_before_anything_runs(
    hanging_bag, tmp_path, capsys
):
    """The shipped preset's model (VBD) runs: the set has only XPBD, so no values stand for it."""
    assert presets.default_model('newton', 'towel', 'dynamic') == 'vbd'
    xpbd_only = _xpbd_only_set(tmp_path / 'xpbd_only')
    assert main(_run(hanging_bag, tmp_path / 'vbd', '--presets', str(xpbd_only))) == 2
    err = _one_line_error(capsys)
    assert 'no newton vbd entry for towel dynamic (it has: xpbd)' in err
    assert str(xpbd_only / 'newton.yaml') in err and '--set newton.model=xpbd' in err
    assert not (tmp_path / 'vbd').exists()
    # the same in a sweep that names the cloth and task; the default sweep leaves it out, saying so
    assert main(['sweep', '--dry-run', '--engine', 'newton', '--presets', str(xpbd_only),
                 '--cloth', 'towel', '--primitive', 'dynamic']) == 2
    assert 'no newton vbd entry' in _one_line_error(capsys)
    assert main(['sweep', '--dry-run', '--engine', 'newton', '--engine', 'mujoco', '--presets',
                 str(xpbd_only), '--seeds', '1', '--rate', '100', '--output',
                 str(tmp_path / 'sweep')]) == 0
    assert 'no values for mujoco chequered dynamic' in capsys.readouterr().out
    # and with the model named, the sweep's cells carry the XPBD entry and name the model
    from cloth_bench_ros.studies.cells import paper_cells

    (cell,) = paper_cells(['newton'], [100.0], ['towel'], ['dynamic'], [0],
                          overrides={'newton': {'model': 'xpbd'}},
                          presets=presets.preset_set('identified'))
    assert cell.params['mass'] == pytest.approx(0.1212612700311451) and cell.model == 'xpbd'


def _vbd_identification(out: Path) -> Path:
    """Return the preset file a Newton VBD identification writes (its own writer, mass fitted)."""
    bag = share_dir('bags') / 'towel_dynamic_newton_vbd'
    spec = IdentifySpec('newton', 'towel', 'dynamic', bag, out, 'tpe', 8, 'cd', ['mass'],
                        grid=GRID, validate_seeds=0)
    summary = {'params': {'mass': 0.2}, 'value': 0.031, 'preset_value': 0.036,
               'best_sampler': 'tpe', 'per_sampler': {'tpe': {'trials': 8}}}
    out.mkdir()
    return write_outputs(spec, presets.load_preset('newton', 'towel', 'dynamic'), summary)


@pytest.mark.slow
def test_a_vbd_identification_merges_beside_the_xpbd_entry(hanging_bag, tmp_path, capsys):
    identified = _vbd_identification(tmp_path / 'ident')
    fitted = presets.read_preset_file(identified)['presets']['towel']['dynamic']
    assert fitted['model'] == 'vbd'
    folder = _xpbd_only_set(tmp_path / 'set')
    before = presets.read_preset_file(folder / 'newton.yaml')
    assert presets.merge_identified([identified], folder) == [folder / 'newton.yaml']
    after = presets.read_preset_file(folder / 'newton.yaml')
    dynamic = after['presets']['towel']['dynamic']
    assert list(dynamic) == ['xpbd', 'vbd'] and dynamic['vbd'] == fitted
    assert dynamic['xpbd'] == before['presets']['towel']['dynamic']['xpbd']
    assert after['presets']['towel']['quasi_static'] == before['presets']['towel']['quasi_static']
    paragraphs = after['provenance'].splitlines()
    assert [p.partition(': ')[0] for p in paragraphs] == [  # in the entries' order
        'towel dynamic (xpbd)', 'towel dynamic (vbd)', 'towel quasi_static (xpbd)']
    assert [paragraphs[0], paragraphs[2]] == before['provenance'].splitlines()
    # the model that runs picks its entry: VBD by default, XPBD when named
    assert presets.load_preset('newton', 'towel', 'dynamic', folder)['mass'] == fitted['mass']
    assert presets.load_preset('newton', 'towel', 'dynamic', folder, 'xpbd') == dynamic['xpbd']
    with pytest.raises(EngineError, match='no newton vbd entry for towel quasi_static'):
        presets.load_preset('newton', 'towel', 'quasi_static', folder)
    # merged again: the same file
    text = (folder / 'newton.yaml').read_text()
    presets.merge_identified([identified], folder)
    assert (folder / 'newton.yaml').read_text() == text
    # a run of the default model with that set: VBD, with its identified entry
    assert main(_run(hanging_bag, tmp_path / 'run', '--presets', str(folder))) == 0
    printed = capsys.readouterr().out.splitlines()
    assert printed[0].endswith(f'newton (vbd) on {AUTO}')
    assert not any('fitted on' in line for line in printed)  # here, where it was fitted
    summary = json.loads((tmp_path / 'run' / 'summary.json').read_text())
    assert summary['run']['models'] == {'newton': 'vbd'}
    assert 0 < summary['engines']['newton']['CD_d'] < 1


@pytest.mark.parametrize('entry, message', [
    ({'xpbd': {'mass': 0.2}, 'mass': 0.3}, 'must map parameter -> value, or model -> parameters'
                                           ', not both'),
    ({'xpbd': {'model': 'vbd', 'mass': 0.2}}, "presets.towel.dynamic.xpbd has model 'vbd'"),
    ({'xpbd': {}}, 'presets.towel.dynamic.xpbd must map parameter -> value'),
    ({'xpbd': {'mass': {'a': 1}}}, 'must map parameter -> value, or model -> parameters'),
    ({'spring': {'mass': 0.2}}, 'no newton xpbd entry for towel dynamic (it has: spring)'),
])
def test_a_malformed_layout_is_one_line_and_exit_2(hanging_bag, tmp_path, capsys, entry, message):
    folder = tmp_path / 'set'
    folder.mkdir()
    (folder / 'newton.yaml').write_text(yaml.safe_dump({
        'engine': 'newton', 'engine_version': '1', 'provenance': 'test',
        'presets': {'towel': {'dynamic': entry}}}))
    assert main(_run(hanging_bag, tmp_path / 'out', '--presets', str(folder),
                     '--set', 'newton.model=xpbd')) == 2
    err = _one_line_error(capsys)
    assert f'preset file {folder / "newton.yaml"}: ' in err and message in err, err
