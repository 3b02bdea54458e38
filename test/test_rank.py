"""`cloth-bench rank` on recordings written by rosbags (the project's writer never makes them)."""

from __future__ import annotations

from dataclasses import replace
import json
import math
from pathlib import Path
import shutil
import time

from camera_recording import (
    CAMERA_TOPIC,
    make_camera_recording,
    make_rank_recordings,
    make_repeated_recording,
)
from cloth_bench_ros import cli
from cloth_bench_ros.engines.mujoco_cloth import MujocoCloth
from cloth_bench_ros.identify import objective, problem as identify_problem
from cloth_bench_ros.identify.objective import evaluate, Trial
from cloth_bench_ros.identify.shared_simulations import SharedSimulations
from cloth_bench_ros.metric_choice import metric
from cloth_bench_ros.paths import bundled_bag
from cloth_bench_ros.rank.answer import deadline_ms, rank_answer, within_reference_error
from cloth_bench_ros.rank.ranking import Ranked
from cloth_bench_ros.rank.study import folds, SHARED_FILE
from cloth_bench_ros.rank.trials import RankTrial, reference_error
from cloth_bench_ros.report.rank import rank_lines, rank_table
from cloth_bench_ros.report.rank_report import plot_ranking
import pytest

TINY = ['--topic', CAMERA_TOPIC, '--engine', 'mujoco', '--trials', '2', '--sampler', 'tpe',
        '--seeds', '1', '--grid', '6x8', '--recommend-rate', '100', '--max-frames', '6',
        '--workers', '2', '--no-progress']


@pytest.fixture
def mujoco_upgraded(monkeypatch):
    """Report another version of MuJoCo, as a pip upgrade would."""
    monkeypatch.setattr(MujocoCloth, 'version', classmethod(lambda cls: '99.0'))
    identify_problem._simulated_model.cache_clear()
    yield
    monkeypatch.undo()
    identify_problem._simulated_model.cache_clear()


@pytest.fixture
def mujoco_on_cuda(monkeypatch):
    """Resolve MuJoCo's device as cuda:0, as on a machine of another device (it runs alike)."""
    monkeypatch.setattr(MujocoCloth, 'device_for', classmethod(lambda cls, params: 'cuda:0'))
    identify_problem._device.cache_clear()
    yield
    monkeypatch.undo()
    identify_problem._device.cache_clear()


@pytest.fixture(scope='module')
def recordings(tmp_path_factory) -> Path:
    """One MCAP and one sqlite3 bag of one fling, one MCAP bag of three: five trials."""
    return make_rank_recordings(bundled_bag('towel', 'dynamic'),
                                tmp_path_factory.mktemp('recordings'))


def test_folds_leave_one_trial_out_up_to_five_then_five_folds():
    assert folds(3) == [[0], [1], [2]]
    assert folds(7) == [[0, 5], [1, 6], [2], [3], [4]]


def test_deadline_is_half_the_period():
    assert deadline_ms(1000.0) == pytest.approx(0.5)


def test_a_diverged_held_out_run_ranks_its_engine_behind_one_that_did_not(tmp_path):
    """Fragile is better on the runs it finished, but diverged on one: ranked behind, printed."""
    def cell(entrant: str, trial: str, seed: int, value: float | None) -> dict:
        return {'kind': 'held_out', 'group': 'towel_dynamic', 'entrant': entrant,
                'config': 'identified', 'trial': trial, 'seed': seed, 'value': value,
                'status': 'ok' if value is not None else 'diverged'}

    cells = []
    for trial in ('a', 'b', 'c'):
        for seed in (1, 2):
            cells.append(cell('steady', trial, seed, 0.040 + 0.001 * seed))
            cells.append(cell('fragile', trial, seed,
                              None if (trial, seed) == ('a', 2) else 0.020 + 0.001 * seed))
            cells.append(cell('gone', trial, seed, None))
    raw = {'spec': {'metric': 'cd', 'entrants': ['fragile', 'gone', 'steady'], 'rates': [100.0],
                    'rate_hz': 100.0},
           'groups': {'towel_dynamic': {'floor': {'mean': None}, 'reference_error': None}},
           'cells': cells}
    result = json.loads(json.dumps(rank_answer(raw), allow_nan=False))
    answer = result['answer']['towel_dynamic']
    assert [r['name'] for r in answer['ranking']] == ['steady', 'fragile', 'gone']
    assert answer['bootstrap']['trials'] == 3 and answer['bootstrap']['seeds_per_trial'] == 2
    table = rank_table(result).markdown()
    assert '| towel_dynamic | 2 | fragile | 0.0214 | 1/6 |' in table
    assert '| towel_dynamic | 3 | gone | - | 6/6 | [-, -] |' in table
    lines = rank_lines(result)
    assert 'towel_dynamic: 95 % intervals from 4000 paired bootstrap replicates (seed 0) over 3' \
           ' held-out trials x 2 seeds each' in lines[0]
    assert 'steady < fragile (fragile diverged in 1/6 runs, steady in 0/6' in lines[1]
    assert plot_ranking(result, 'towel_dynamic', tmp_path / 'rank.png').stat().st_size > 1000


@pytest.mark.slow
def test_rank_splits_identifies_ranks_and_resumes(recordings, tmp_path, capsys, request):
    out = tmp_path / 'rank'
    assert cli.main(['rank', str(recordings), '--output', str(out), *TINY]) == 0
    printed = capsys.readouterr().out
    for name in ('one_mcap: trial 1', 'one_sqlite: trial 1', 'three: trial 1', 'three: trial 2',
                 'three: trial 3'):
        assert name in printed, printed
    assert 'change of phase at frame 10' in printed
    result = json.loads((out / 'rank.json').read_text())
    assert len(result['trials']) == 5
    assert result['spec']['devices'] == {'mujoco': 'cpu'}  # where each entrant ran
    assert {c['device'] for c in result['cells']} == {'cpu'}
    group = result['answer']['towel_dynamic']
    assert len(result['groups']['towel_dynamic']['folds']) == 5
    assert len([k for k in result['identified'] if k.startswith('towel_dynamic|mujoco|')]) == 5
    (ranked,) = group['ranking']
    assert ranked['name'] == 'mujoco' and ranked['n'] == 5  # 5 held-out trials x 1 seed
    held = [c for c in result['cells'] if c['kind'] == 'held_out' and c['config'] == 'identified']
    assert sorted(c['trial'] for c in held) == sorted(t['name'] for t in result['trials'])
    floor = group['floor']
    assert len(floor['pairs']) == 20 and 0 < floor['min'] <= floor['mean'] <= floor['max']
    assert floor['mean'] < ranked['mean']  # the trials are copies of one simulation, noisier
    # Every number the table prints is in rank.json.
    row = next(line for line in printed.splitlines() if line.startswith('| towel_dynamic'))
    cells = [c.strip() for c in row.strip('|').split('|')]
    timing = group['entrants']['mujoco']['timing']['100']
    assert cells[3] == f'{ranked["mean"]:.4f}' and cells[8] == (
        f'{group["entrants"]["mujoco"]["preset"]["mean"]:.4f}'
    )
    assert cells[4] == f'{ranked["diverged"]}/5' and ranked['runs'] == 5
    assert cells[5] == f'[{ranked["low"]:.4f}, {ranked["high"]:.4f}]'
    assert cells[9] == f'{floor["mean"]:.4f}' and cells[10] == f'{timing["step_p99_ms"]:.2f}'
    assert 'towel_dynamic at 100 Hz (p99 < 5.00 ms): ' in printed
    _check_shared_simulations(out, result)
    _check_pooled_cells(result)
    # Two engines, two seeds: mujoco's identifications and seed-1 cells are kept.
    assert cli.main(['rank', str(recordings), '--output', str(out), *TINY, '--engine', 'bullet',
                     '--seeds', '2']) == 0
    printed = capsys.readouterr().out
    assert 'cells: 42 (11 kept from an earlier run)' in printed
    _check_paired_ranking(json.loads((out / 'rank.json').read_text()), printed)
    # The same command again: every identification and cell is kept.
    assert cli.main(['rank', str(recordings), '--output', str(out), *TINY]) == 0
    again = capsys.readouterr().out
    assert 'cells: 11 (11 kept from an earlier run)' in again
    assert json.loads((out / 'rank.json').read_text())['answer'] == result['answer']
    # Another metric: the same identifications (fitted on CD), held-out cells scored again with
    # every metric the evaluator reports, ranked on the F-score (more is better).
    assert cli.main(['rank', str(recordings), '--output', str(out), *TINY,
                     '--metric', 'fscore']) == 0
    printed = capsys.readouterr().out
    assert 'cells: 11 (1 kept from an earlier run)' in printed  # the timing cell is kept
    result = json.loads((out / 'rank.json').read_text())
    assert result['spec']['metric'] == 'fscore' and result['spec']['objective'] == 'cd'
    held = [c for c in result['cells'] if c['kind'] == 'held_out' and c['config'] == 'identified']
    assert all(0 < c['metrics']['fscore'] <= 1 and c['metrics']['cd'] == c['CD'] for c in held)
    (ranked,) = result['answer']['towel_dynamic']['ranking']
    assert ranked['mean'] == pytest.approx(sum(c['metrics']['fscore'] for c in held) / 5)
    assert 'FSCORE held-out |' in printed and 'so no engine is compared with it' in printed
    with pytest.raises(SystemExit) as refused:  # argparse's choices: one usage line, exit 2
        cli.main(['rank', str(recordings), '--output', str(out), *TINY, '--metric', 'nope'])
    assert refused.value.code == 2 and "invalid choice: 'nope'" in capsys.readouterr().err
    # `cloth-bench report` on the rank directory: the table, the sentences and both figures.
    assert cli.main(['report', str(out)]) == 0
    printed = capsys.readouterr().out
    md = (out / 'report' / 'report.md').read_text()
    assert f'| {ranked["mean"]:.4f} |' in md and 'so no engine is compared with it' in md
    for figure in ('rank_towel_dynamic.png', 'rank_speed_towel_dynamic.png'):
        assert (out / 'report' / figure).stat().st_size > 1000 and figure in md
    assert '| towel_dynamic | 1 | mujoco |' in printed and '2 plots' in printed
    # A recording made again (other noise): the folds trained on its trial, and its held-out
    # cells, anew. On a copy: the module's recordings stay as they are for the other tests.
    again = tmp_path / 'recordings'
    shutil.copytree(recordings, again)
    shutil.rmtree(again / 'one_sqlite')
    make_camera_recording(bundled_bag('towel', 'dynamic'), again / 'one_sqlite', seed=5,
                          pre_roll=30, noise=0.002, storage='sqlite3')
    assert cli.main(['rank', str(again), '--output', str(out), *TINY]) == 0
    printed = capsys.readouterr().out
    assert printed.count('changed since it was identified (bag data): identified again') == 4
    assert 'fold2: its trials' not in printed  # the fold that holds that trial out
    assert 'cells: 11 (9 kept from an earlier run)' in printed
    # Another version of the engine, on another device: every fold, simulation and cell anew.
    request.getfixturevalue('mujoco_upgraded')
    request.getfixturevalue('mujoco_on_cuda')
    assert cli.main(['rank', str(again), '--output', str(out), *TINY]) == 0
    printed = capsys.readouterr().out
    assert printed.count('changed since it was identified (device, engine version)') == 5, printed
    assert 'cells: 11 (0 kept from an earlier run)' in printed
    result = json.loads((out / 'rank.json').read_text())
    assert result['spec']['devices'] == {'mujoco': 'cuda:0'}
    assert {c['device'] for c in result['cells']} == {'cuda:0'}


def _check_paired_ranking(result: dict, printed: str) -> None:
    """Check two engines ranked on the same five held-out trials x two seeds, paired."""
    group = result['answer']['towel_dynamic']
    assert {k: v for k, v in group['bootstrap'].items() if k != 'resampled'} == {
        'trials': 5, 'seeds_per_trial': 2, 'replicates': 4000, 'seed': 0, 'confidence': 0.95}
    assert sorted(r['name'] for r in group['ranking']) == ['bullet', 'mujoco']
    held = [c for c in result['cells'] if c['kind'] == 'held_out' and c['config'] == 'identified']
    assert len(held) == 20 and {c['seed'] for c in held} == {1, 2}
    value = {(c['entrant'], c['trial'], c['seed']): c['value'] for c in held}
    for r in group['ranking']:
        lost = sum(c['status'] == 'diverged' for c in held if c['entrant'] == r['name'])
        assert (r['runs'], r['trials'], r['diverged'], r['n']) == (10, 5, lost, 10 - lost)
        assert r['divergence_rate'] == lost / 10
        assert f'| {r["name"]} | {r["mean"]:.4f} | {lost}/10 |' in printed
    (d,) = group['differences']
    assert [d['ahead'], d['behind']] == [r['name'] for r in group['ranking']]
    gaps = [value[(d['behind'], t, s)] - value[(d['ahead'], t, s)]
            for (e, t, s) in value if e == d['ahead']
            if all(math.isfinite(value[(n, t, s)] or math.nan) for n in ('mujoco', 'bullet'))]
    assert d['paired'] == len(gaps) and d['mean'] == pytest.approx(sum(gaps) / len(gaps))
    assert min(gaps) <= d['low'] <= d['mean'] <= d['high'] <= max(gaps)
    assert f'towel_dynamic: {group["significance"]}' in printed
    assert ('towel_dynamic: 95 % intervals from 4000 paired bootstrap replicates (seed 0) over 5'
            ' held-out trials x 2 seeds each') in printed


def _check_shared_simulations(out: Path, result: dict) -> None:
    """Later folds reuse the first's simulations, and a reused value is the one a run gives."""
    bags = {t['name']: t['bag'] for t in result['trials']}
    folder = out / 'identify' / 'towel_dynamic' / 'mujoco'
    kept = [json.loads(line) for line in (folder / SHARED_FILE).read_text().splitlines()]
    assert len(kept) == 3 and all(len(k['bags']) == 5 for k in kept)  # preset + 2 trials
    for fold in (1, 2):
        summary = json.loads((folder / f'fold{fold}' / 'identification.json').read_text())
        rows = [json.loads(line) for line in (folder / f'fold{fold}' / 'trials.jsonl')
                .read_text().splitlines()]
        assert summary['shared_simulations'] == (
            {'reused': 0, 'run': 3} if fold == 1 else {'reused': 3, 'run': 0})
        assert all(r['reused'] == (fold > 1) for r in rows)
        train = [bags[n] for n in result['identified'][f'towel_dynamic|mujoco|{fold}']['training']]
        row = rows[-1]
        direct = evaluate(Trial('mujoco', 'towel', 'dynamic', train[0],
                                tuple(sorted(row['params'].items())), grid=(6, 8), max_frames=6,
                                number=row['number'], sampler='tpe', also=tuple(train[1:])))
        for key in ('value', 'CD', 'HD', 'frames', 'status', 'per_bag'):
            assert row[key] == direct[key], key
        assert direct['cpu_s'] > 0 and (row['cpu_s'] == 0) == (fold > 1)
    # A worker keeps every bag a trial is scored on: five are decoded once, not every trial.
    pool = list(bags.values())
    evaluate(Trial('mujoco', 'towel', 'dynamic', pool[0], (), grid=(6, 8), max_frames=6,
                   also=tuple(pool[1:])))
    kept = {key[0] for key in objective._BAG_CACHE}
    assert {str(Path(b).resolve()) for b in pool} <= kept


def _check_pooled_cells(result: dict) -> None:
    """Check that the preset's held-out cells share one simulation, each with a run's value."""
    preset = [c for c in result['cells'] if c['kind'] == 'held_out' and c['config'] == 'preset']
    assert len(preset) == 5 and all(c['pooled'] == 5 for c in preset)
    assert sum(c['cpu_s'] > 0 for c in preset) == 1  # the simulation's time counted once
    bags = {t['name']: t['bag'] for t in result['trials']}
    for cell in preset[1:3]:
        direct = evaluate(Trial('mujoco', 'towel', 'dynamic', bags[cell['trial']], (), seed=1,
                                grid=(6, 8), max_frames=6, sampler='preset'))
        for key in ('value', 'CD', 'HD', 'frames', 'status'):
            assert cell[key] == direct[key], key
    identified = [c for c in result['cells'] if c['config'] == 'identified']
    for cell in identified:  # folds that identified the same parameters share their simulation
        assert cell['pooled'] == sum(c['params'] == cell['params'] for c in identified)
    timing = [c for c in result['cells'] if c['kind'] == 'timing']
    assert len(timing) == 1 and timing[0]['pooled'] == 1


def test_a_simulation_is_shared_only_whole_on_the_groups_trials_as_they_were(tmp_path):
    bags = []
    for name in 'abc':
        (tmp_path / name).write_bytes(name.encode())
        bags.append(str(tmp_path / name))
    a, b, c = bags
    path = tmp_path / SHARED_FILE
    path.write_text('{"key": "torn')  # an interrupted write: that simulation runs again
    shared = SharedSimulations(path, bags)
    assert shared.rows == {}
    trial = Trial('mujoco', 'towel', 'dynamic', a, (('young', 1e4),), also=(b,))
    assert shared.applies(trial) and shared.known(trial) is None
    assert not shared.applies(replace(trial, also=('elsewhere',)))
    assert not shared.applies(replace(trial, rung=0.25))
    assert not shared.applies(replace(trial, ladder=(((3, 4), None),)))
    assert not shared.applies(replace(trial, all_metrics=True))
    pooled = {'per_bag': [0.01, math.nan, 0.03], 'per_bag_hd': [0.1, math.nan, 0.3],
              'per_bag_frames': [10, 0, 9], 'diverged': ['nan in the state', 40], 'cpu_s': 2.0}
    lost = shared.finish(trial, pooled)  # b's frames all came after the divergence
    assert lost['status'] == 'diverged' and lost['step'] == 40 and lost['cpu_s'] == 2.0
    other_fold = replace(trial, bag=c, also=(a,), number=7, objective='hd')
    again = SharedSimulations(path, bags).known(other_fold)  # read back from the file
    assert again['value'] == pytest.approx(0.2) and again['CD'] == pytest.approx(0.02)
    assert again['reused'] and again['cpu_s'] == 0 and again['number'] == 7
    assert SharedSimulations(path, bags).known(replace(trial, params=())) is None
    time.sleep(0.01)
    (tmp_path / 'b').write_bytes(b'recorded again')
    rewritten = SharedSimulations(path, bags)
    assert rewritten.known(trial) is None and rewritten.known(other_fold) is not None


def _one_shared_simulation(tmp_path: Path) -> tuple[list[str], Trial]:
    """Write two small bags and one finished shared simulation of MuJoCo on them."""
    bags = []
    for name in 'ab':
        (tmp_path / name).write_bytes(name.encode())
        bags.append(str(tmp_path / name))
    trial = Trial('mujoco', 'towel', 'dynamic', bags[0], (('young', 1e4),), also=(bags[1],))
    pooled = {'per_bag': [0.01, 0.03], 'per_bag_hd': [0.1, 0.3], 'per_bag_frames': [10, 9],
              'diverged': None, 'cpu_s': 2.0}
    SharedSimulations(tmp_path / SHARED_FILE, bags).finish(trial, pooled)
    return bags, trial


def test_a_simulation_of_another_engine_version_is_not_reused(tmp_path, request):
    bags, trial = _one_shared_simulation(tmp_path)
    assert SharedSimulations(tmp_path / SHARED_FILE, bags).known(trial) is not None
    request.getfixturevalue('mujoco_upgraded')
    assert SharedSimulations(tmp_path / SHARED_FILE, bags).known(trial) is None


def test_a_simulation_or_cell_of_another_device_is_not_reused(tmp_path, request):
    from cloth_bench_ros.rank.study import _cell, RankSpec

    bags, trial = _one_shared_simulation(tmp_path)
    held = RankTrial('t', 'towel', 'dynamic', bags[0], bags[0], 0, 'metadata', 0.0, 132, 104)
    cell = _cell(RankSpec([bags[0]], tmp_path), 'mujoco', {'young': 1e4}, held, 1, 100.0, 'preset')
    assert SharedSimulations(tmp_path / SHARED_FILE, bags).known(trial) is not None
    request.getfixturevalue('mujoco_on_cuda')
    assert SharedSimulations(tmp_path / SHARED_FILE, bags).known(trial) is None
    again = _cell(RankSpec([bags[0]], tmp_path), 'mujoco', {'young': 1e4}, held, 1, 100.0,
                  'preset')
    assert again[0] != cell[0] and again[1] == cell[1]  # another key for the same simulation


def test_a_cell_scored_on_every_metric_is_not_kept_across_a_surface_metrics_revision(
    tmp_path, monkeypatch
):
    from cloth_bench_ros.rank import study as rank
    from cloth_bench_ros.rank.study import _cell, RankSpec

    (tmp_path / 'a').write_bytes(b'a')
    bag = str(tmp_path / 'a')
    held = RankTrial('t', 'towel', 'dynamic', bag, bag, 0, 'metadata', 0.0, 132, 104)

    def key(metric: str) -> str:
        spec = RankSpec([bag], tmp_path, metric=metric)
        return _cell(spec, 'mujoco', {'young': 1e4}, held, 1, 100.0, 'preset')[0]

    paper, surface = key('cd'), key('emd')
    monkeypatch.setattr(rank, 'SURFACE_REVISION', rank.SURFACE_REVISION + 1)
    assert key('cd') == paper  # the paper's CD does not read the surface metrics
    assert key('emd') != surface


def test_report_of_a_damaged_rank_directory_is_one_line(tmp_path, capsys):
    (tmp_path / 'rank.json').write_text('{"spec": {}}')
    assert cli.main(['report', str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert 'not a rank.json of cloth-bench rank' in err and len(err.splitlines()) == 1


def test_differences_under_a_bundled_references_numerical_error_are_said_to_be_so(recordings):
    def trial(bag, source='metadata'):
        return RankTrial('t', 'towel', 'dynamic', str(bag), str(bag), 0, source, 0.0, 132, 104)

    mujoco = [trial(bundled_bag('towel', 'dynamic'))] * 2
    vbd = trial(bundled_bag('towel', 'dynamic').with_name('towel_dynamic_newton_vbd'))
    assert reference_error(mujoco)['reference'] == 'mujoco'
    assert reference_error([vbd, vbd])['error_m'] > reference_error(mujoco)['error_m']
    assert reference_error([mujoco[0], vbd]) is None  # two references: no single error
    assert reference_error([trial(recordings / 'one_mcap', 'clouds')]) is None
    ranked = [Ranked('a', 1, 0.0300, 0.0299, 0.0301, 1.0, 5, 5, 0, 0.0, 5),
              Ranked('b', 2, 0.0320, 0.0319, 0.0321, 1.0, 5, 5, 0, 0.0, 5),
              Ranked('c', 3, 0.0400, 0.0399, 0.0401, 1.0, 5, 5, 0, 0.0, 5)]
    said = within_reference_error(ranked, reference_error(mujoco), metric('cd'))
    assert [p['pair'] for p in said['pairs']] == [['a', 'b']]  # 2 mm < 3 mm; 8 mm is not
    assert said['pairs'][0]['difference_m'] == pytest.approx(0.002)
    assert within_reference_error(ranked, reference_error(mujoco), metric('fscore')) is None


def test_one_trial_is_no_ranking(recordings, tmp_path, capsys):
    code = cli.main(['rank', str(recordings / 'one_mcap'), '--output', str(tmp_path), *TINY])
    assert code == 2
    err = capsys.readouterr()
    assert 'towel dynamic: 1 usable trial; left out (ranking needs 2)' in err.out
    assert err.err.strip().startswith('cloth-bench: error: rank: no cloth and task with two')
    assert len(err.err.strip().splitlines()) == 1


def test_rank_of_a_resized_cloth_names_it_and_never_reuses_another_sizes_cells(tmp_path, capsys):
    """--cloth-size/--cloth-mass: the group line names the cloth; another size runs anew."""
    make_repeated_recording(bundled_bag('towel', 'dynamic'), tmp_path / 'rec' / 'two',
                            repetitions=2, rest_s=1.0, seed=4)
    out = tmp_path / 'rank'
    command = ['rank', str(tmp_path / 'rec'), '--output', str(out), *TINY]
    assert cli.main([*command, '--cloth-size', '0.4,0.6', '--cloth-mass', '0.2']) == 0
    printed = capsys.readouterr().out
    assert 'towel_dynamic: 2 trials of a 0.40 x 0.60 m, 0.2 kg cloth' in printed
    assert 'towel_dynamic: cloth 0.40 x 0.60 m, mass 0.2 kg (--cloth-mass, not fitted)' in printed
    result = json.loads((out / 'rank.json').read_text())
    assert result['spec']['cloth_size'] == [0.4, 0.6] and result['spec']['cloth_mass'] == 0.2
    group = result['groups']['towel_dynamic']
    assert group['cloth_size'] == [0.4, 0.6] and group['floor']['vertices'] == 48  # --grid 6x8
    assert all('mass' not in v['params'] for v in result['identified'].values())
    cells = len(result['cells'])
    assert cli.main([*command, '--cloth-size', '0.45,0.6']) == 0  # another cloth: nothing kept
    printed = capsys.readouterr().out
    assert f'cells: {cells} (0 kept from an earlier run)' in printed
    assert 'mass the preset' in printed and '0.45 x 0.60 m' in printed
    assert json.loads((out / 'rank.json').read_text())['spec']['cloth_size'] == [0.45, 0.6]


def test_a_rank_starts_one_cluster_for_every_folds_identification_and_its_cells(
    tmp_path, monkeypatch, capsys
):
    """Two folds identified and their cells scored on one cluster; a kept rank starts none."""
    from cloth_bench_ros.studies import dask_executor

    started = []
    start_cluster = dask_executor._cluster_client  # the session's cluster (conftest.py)

    def counted(scheduler, workers, plugin):
        started.append(scheduler)
        return start_cluster(scheduler, workers, plugin)

    monkeypatch.setattr(dask_executor, '_cluster_client', counted)
    make_repeated_recording(bundled_bag('towel', 'dynamic'), tmp_path / 'rec' / 'two',
                            repetitions=2, rest_s=1.0, seed=4)
    command = ['rank', str(tmp_path / 'rec'), '--output', str(tmp_path / 'rank'), *TINY]
    assert cli.main(command) == 0
    printed = capsys.readouterr().out
    assert 'identify mujoco on towel_dynamic fold 2' in printed and 'cells: 5 (0 kept' in printed
    assert len(started) == 1  # not one per fold's identification and one more for the cells
    assert cli.main(command) == 0
    assert 'cells: 5 (5 kept' in capsys.readouterr().out and len(started) == 1


@pytest.mark.parametrize(
    'flag, rates, message',
    [('--recommend-rate', '0.5', '0.5 Hz is outside [1, 10000]'),
     ('--recommend-rate', 'abc', "'abc' is not a number"),
     ('--rates', '100,0.5', '0.5 Hz is outside [1, 10000]'), ('--rates', ',', 'no value in')],
)
def test_rates_are_checked_as_the_rate_option_is(flag, rates, message, capsys):
    with pytest.raises(SystemExit) as exit_:
        cli.main(['rank', 'bags', flag, rates])
    assert exit_.value.code == 2 and message in capsys.readouterr().err
