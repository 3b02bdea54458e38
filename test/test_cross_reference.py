"""
The second synthetic reference (Newton VBD) and the cross-reference table.

Real engines scored against short real bags of both references (coarse grids, 0.2 s of the fling).
"""

from __future__ import annotations

from dataclasses import replace

from cloth_bench_ros.data import BagReader, CLOUD_TOPIC, synth, virtual_camera
from cloth_bench_ros.rank import cross_reference as rank_xr
from cloth_bench_ros.report import cross_reference as report_xr
from cloth_bench_ros.studies import cross_reference as xr
from cloth_bench_ros.sweep import study as sw
from cloth_bench_ros.sweep.aggregate import stat
from cloth_bench_ros.sweep.study import Cell
import numpy as np
import pytest

SMALL = virtual_camera.Camera(width=320, height=180)


def test_newton_reference_is_another_family_with_the_same_cloths():
    for cloth in ('towel', 'chequered', 'linen'):
        for primitive in ('dynamic', 'quasi_static'):
            mujoco = synth.reference_config(cloth, primitive)
            newton = synth.reference_config(cloth, primitive, reference='newton-vbd')
            assert (mujoco.engine, newton.engine) == ('mujoco', 'newton')
            assert newton.params['model'] == 'vbd' and newton.params['self_collision']
            assert newton.grid == mujoco.grid and newton.frame_count == mujoco.frame_count
            assert newton.steps_per_frame == 80 and newton.provenance  # 2400 Hz
            for key in ('mass', 'friction'):
                assert newton.params[key] == mujoco.params[key]
    with pytest.raises(synth.SynthError, match="unknown synthetic reference 'bullet'"):
        synth.reference_config('towel', 'dynamic', reference='bullet')


def test_reference_bags_are_named_after_their_reference():
    assert xr.reference_bag('towel', 'dynamic', 'mujoco').name == 'towel_dynamic'
    assert (
        xr.reference_bag('towel', 'quasi_static', 'newton-vbd').name
        == 'towel_quasi_static_newton_vbd'
    )
    with pytest.raises(ValueError, match='unknown synthetic reference'):
        xr.reference_bag('towel', 'dynamic', 'sofa')
    cells, _ = xr.cross_reference_cells(
        'towel', ['dynamic'], [0, 1], 100.0, xr.DEFAULT_ENTRANTS, kinds=['preset']
    )
    assert len(cells) == len(xr.DEFAULT_ENTRANTS) * 2 * 2
    assert {c.config.split(',')[0] for c in cells} == {'reference=mujoco', 'reference=newton-vbd'}
    assert len({c.key() for c in cells}) == len(cells)  # resumable: every cell has its own key


@pytest.fixture(scope='module')
def short_bags(tmp_path_factory) -> dict[str, str]:
    """Make 0.2 s of the towel's fling from each reference, on a 6 x 8 grid at 150 Hz."""
    out = tmp_path_factory.mktemp('xref')
    bags = {}
    for reference in xr.REFERENCES:
        cfg = synth.reference_config(
            'towel', 'dynamic', reference=reference, grid=(6, 8), rate_hz=150.0, duration=0.2
        )
        cfg = replace(cfg, sensor=replace(cfg.sensor, camera=SMALL))
        bags[reference] = str(synth.write_synthetic_bag(cfg, out / f'towel_dynamic_{reference}'))
    return bags


@pytest.mark.slow
def test_newton_reference_bag_names_its_model(short_bags):
    reader = BagReader(short_bags['newton-vbd'])
    assert reader.trial.source.startswith(
        'synthetic: reference newton vbd cloth 6x8, 150 Hz, self-collision on'
    )
    clouds = list(reader.clouds(CLOUD_TOPIC))
    assert len(clouds) == 6 and all(len(p) > 200 for _, p in clouds)


@pytest.mark.slow
def test_cross_reference_table_scores_every_engine_on_every_reference(short_bags, tmp_path):
    entrants = [('mujoco', {}), ('newton', {'model': 'vbd'})]
    cells = [
        Cell(
            engine,
            100.0,
            'towel',
            'dynamic',
            0,
            bag,
            0,
            xr.MODE,
            f'reference={reference},' + ('model=vbd' if overrides else 'preset'),
            (6, 8),
            tuple(sorted(overrides.items())),
        )
        for reference, bag in short_bags.items()
        for engine, overrides in entrants
    ]
    outcome = sw.run_sweep(
        cells, tmp_path, workers=2, progress=False
    )  # the executor, as any sweep
    rows = sw.load_rows(tmp_path / sw.RESULTS_FILE)
    assert outcome.ran == len(cells) == len(rows)
    assert all(r['status'] == 'ok' for r in rows), [r.get('error') for r in rows]
    assert sorted((r['engine'], r['reference']) for r in rows) == sorted(
        (c.engine, c.reference) for c in cells
    )
    assert (
        sw.run_sweep(cells, tmp_path, workers=2, progress=False).ran == 0
    )  # resumed: nothing runs twice

    table = report_xr.cross_reference_table(rows)
    assert table.headers == ['engine', 'MuJoCo shell ref. CD_d', 'Newton VBD ref. CD_d']
    assert [line[0] for line in table.rows] == ['MuJoCo', 'Newton (vbd)']
    for line, (engine, _) in zip(table.rows, entrants):
        for text, reference in zip(line[1:], xr.REFERENCES):
            mine = [r for r in rows if r['engine'] == engine and r['reference'] == reference]
            assert float(text.strip('*').split(' ')[0]) == pytest.approx(
                stat(mine, 'CD').mean, abs=6e-4
            )
    for column in (1, 2):  # one winner per column, in bold
        assert sum(line[column].startswith('**') for line in table.rows) == 1
    cds = np.array([r['CD'] for r in rows])
    assert np.isfinite(cds).all() and (cds > 0).all() and (cds < 0.2).all()

    heading, note, section_table = report_xr.cross_reference_section(rows)
    assert 'towel' in heading and '100 Hz' in note and section_table.rows == table.rows
    assert report_xr.cross_reference_table([{**r, 'mode': 'paper'} for r in rows]) is None


@pytest.mark.parametrize(
    'argv,words',
    [
        (['--cloth', 'silk'], ['--cloth', "invalid choice: 'silk'"]),
        (['--seeds', '0'], ['--seeds', '0 is outside [1, inf]']),
        (['--rate', '-5'], ['--rate', '-5.0 Hz is outside']),
    ],
)
def test_cross_reference_command_refuses_bad_input_in_one_line(argv, words, capsys, tmp_path):
    from cloth_bench_ros.cli import main

    with pytest.raises(SystemExit) as exit_:  # argparse's one-line usage error
        main(['cross-reference', '--output', str(tmp_path / 'x'), *argv])
    assert exit_.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and all(w in err for w in words)


def _identified_sets(tmp_path, monkeypatch) -> None:
    """config/ with the shipped presets and an identified set per reference, towel fling only."""
    import shutil

    from cloth_bench_ros.engines import presets

    shipped = presets.config_dir()
    config = tmp_path / 'config'
    shutil.copytree(
        shipped / 'presets', config / 'presets', ignore=shutil.ignore_patterns('identified*')
    )
    for name, mass in (('identified', 0.2), ('identified-newton-vbd', 0.3)):
        (config / 'presets' / name).mkdir()
        for engine, extra in (('mujoco', ''), ('newton', ', model: xpbd')):
            (config / 'presets' / name / f'{engine}.yaml').write_text(
                f'engine: {engine}\nengine_version: "x"\nprovenance: test\n'
                f'presets: {{towel: {{dynamic: {{mass: {mass}{extra}}}}}}}\n'
            )
    monkeypatch.setattr(presets, 'config_dir', lambda: config)


def test_identified_entrants_run_with_the_set_fitted_to_their_own_reference(tmp_path, monkeypatch):
    _identified_sets(tmp_path, monkeypatch)
    entrants = [
        ('mujoco', {}),
        ('bullet', {}),
        ('newton', {'model': 'vbd'}),
        ('newton', {'model': 'xpbd'}),
    ]
    cells, missing = xr.cross_reference_cells('towel', ['dynamic'], [1, 2], 100.0, entrants)
    identified = [c for c in cells if c.preset_set != 'default']
    # MuJoCo and Newton XPBD have identified values, PyBullet none; XPBD values never mean VBD.
    # MuJoCo's entry names no model: it stands for the model that runs, the preset's shell.
    assert sorted({(c.engine, c.params.get('model'), c.reference) for c in identified}) == [
        ('mujoco', 'shell', 'mujoco'),
        ('mujoco', 'shell', 'newton-vbd'),
        ('newton', 'xpbd', 'mujoco'),
        ('newton', 'xpbd', 'newton-vbd'),
    ]
    for c in identified:  # each scored against the reference it was identified against
        assert c.params['mass'] == (0.2 if c.reference == 'mujoco' else 0.3)
        name = 'identified' if c.reference == 'mujoco' else 'identified-newton-vbd'
        assert c.preset_set == name
    assert len(missing) == 4 and all('no identified' in m for m in missing)
    assert len({c.key() for c in cells}) == len(cells) == (4 + 2) * 2 * 2
    row = sw.run_cell.__globals__['_cell_fields'](identified[0])
    first = identified[0]
    assert (row['presets'], row['reference']) == (first.preset_set, first.reference)


def _row(engine, reference, cd, seed, presets='identified', model=None):
    return {
        'mode': xr.MODE,
        'engine': engine,
        'reference': reference,
        'primitive': 'dynamic',
        'cloth': 'towel',
        'seed': seed,
        'rate_hz': 100.0,
        'status': 'ok',
        'CD': cd,
        'presets': presets,
        'params': {'model': model} if model else {},
    }


def test_ranking_has_paired_intervals_and_says_whether_it_holds_across_references():
    from cloth_bench_ros.rank.ranking import HeldOutRun, rank_runs

    def ranked(samples):  # one reference bag: seeds 1, 2, ...
        return rank_runs({n: [HeldOutRun('bag', s, v) for s, v in enumerate(vs, 1)]
                          for n, vs in samples.items()}).ranked

    apart = ranked({'a': [0.030, 0.031, 0.029], 'b': [0.050, 0.052, 0.049]})
    assert [(r.name, r.rank, r.p_rank) for r in apart] == [('a', 1, 1.0), ('b', 2, 1.0)]
    for r, values in zip(apart, ([0.030, 0.031, 0.029], [0.050, 0.052, 0.049])):
        assert min(values) <= r.low <= r.mean <= r.high <= max(values)
        assert r.mean == pytest.approx(np.mean(values)) and r.n == 3
    close = ranked({'a': [0.030, 0.040, 0.035], 'b': [0.036, 0.033, 0.038]})
    assert 0.2 < close[0].p_rank < 0.9  # overlapping seeds: the order is not settled
    (kept,) = ranked({'a': [0.03, float('nan')], 'b': [None]})  # no value: not ranked
    assert (kept.name, kept.n) == ('a', 1)

    rows = [_row('mujoco', 'mujoco', 0.020 + 0.001 * s, s) for s in range(3)]
    rows += [_row('bullet', 'mujoco', 0.040 + 0.001 * s, s) for s in range(3)]
    rows += [_row('mujoco', 'newton-vbd', 0.050 + 0.001 * s, s) for s in range(3)]
    rows += [_row('bullet', 'newton-vbd', 0.030 + 0.001 * s, s) for s in range(3)]
    rows += [_row('bullet', 'mujoco', 0.01, s, presets='default') for s in range(3)]  # not ranked
    rows.append({**_row('bullet', 'mujoco', None, 3), 'status': 'diverged'})
    rankings = rank_xr.identified_rankings(rows)
    assert [r.name for r in rankings[('mujoco', 'dynamic')].ranked] == ['MuJoCo', 'Bullet']
    assert [r.name for r in rankings[('newton-vbd', 'dynamic')].ranked] == ['Bullet', 'MuJoCo']
    bullet = rankings[('mujoco', 'dynamic')].ranked[1]
    assert (bullet.diverged, bullet.runs, bullet.n) == (1, 4, 3)  # seed 3 diverged
    *told, line = report_xr.ranking_statements(rankings)
    assert told[1] == ('Newton VBD ref. dynamic: significant (the 95 % paired interval excludes'
                       ' 0): Bullet < MuJoCo (+0.0200 [+0.0200, +0.0200])')
    assert line.startswith('dynamic: the ranking changes between references')
    same = [r for r in rows if not (r['reference'] == 'newton-vbd')] + [
        {**r, 'reference': 'newton-vbd'} for r in rows if r['reference'] == 'mujoco'
    ]
    *_, line = report_xr.ranking_statements(rank_xr.identified_rankings(same))
    assert 'holds across references: MuJoCo < Bullet' in line
    md = report_xr.cross_reference_markdown(rows, rankings)
    assert 'Bullet, identified' in md and '95 % CI' in md and 'changes between' in md
    assert '| mujoco | dynamic | 2 | Bullet | 0.0410 | 1/4 |' in md
