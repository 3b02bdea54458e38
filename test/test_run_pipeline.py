"""The four nodes in one process run a whole benchmark on a real engine and a real bag."""

import json

from cloth_bench_ros.studies.run_pipeline import run_pipeline, RunConfig
import numpy as np
import pytest

GRID = (6, 8)  # coarse mesh: fast, still a real MuJoCo cloth


def _run(bag, tmp_path, name, **kw):
    config = RunConfig(bag=bag, grid=GRID, output_dir=tmp_path / name, **kw)
    return run_pipeline(config)


@pytest.fixture(scope='module')
def two_runs(hanging_bag, tmp_path_factory):
    out = tmp_path_factory.mktemp('runs')
    return [_run(hanging_bag, out, f'run{i}') for i in range(2)], out


def test_every_real_frame_is_scored_and_the_window_is_cut_at_the_change_of_phase(two_runs):
    (summary, _), out = two_runs
    m = summary['engines']['mujoco']
    assert summary['real']['frames'] == 132 and summary['real']['unpaired_frames'] == 0
    assert (
        m['frames_scored'] == 132 and m['frames_in_window'] == 99
    )  # cut-off from the bag's metadata
    assert 0 < m['CD_d'] <= m['HD_d'] < 1.0
    assert m['L_s'] > 0 and not m['diverged']
    assert m['step_time']['count'] == 740  # 3 s settle + 4.4 s at 100 Hz, after the reset
    assert m['step_time']['p50'] <= m['step_time']['p99'] <= m['step_time']['max']


def test_report_files_match_the_summary(two_runs):
    (summary, _), out = two_runs
    written = json.loads((out / 'run0' / 'summary.json').read_text())
    assert written['engines']['mujoco']['CD_d'] == pytest.approx(
        summary['engines']['mujoco']['CD_d']
    )
    rows = (out / 'run0' / 'frames.csv').read_text().splitlines()
    assert rows[0] == (
        'engine,frame,t,cd,hd,in_window,diverged,cd_reverse,hd_reverse,cd_surface,hd_surface,'
        'cd_two_sided,hd_two_sided,precision,recall,fscore,emd,real_contact,sim_contact'
    ) and len(rows) == 133
    cds = np.array([float(r.split(',')[3]) for r in rows[1:100]])
    assert np.mean(cds) == pytest.approx(summary['engines']['mujoco']['CD_d'], rel=1e-12)


def test_two_runs_of_one_configuration_give_identical_metrics(two_runs):
    (a, b), out = two_runs
    for key in ('CD_d', 'HD_d', 'L_s', 'frames_scored'):
        assert a['engines']['mujoco'][key] == b['engines']['mujoco'][key]
    assert (out / 'run0' / 'frames.csv').read_text() == (out / 'run1' / 'frames.csv').read_text()


def test_another_seed_gives_another_result(hanging_bag, tmp_path, two_runs):
    (a, _), _ = two_runs
    other = _run(hanging_bag, tmp_path, 'seed1', seed=1)
    assert other['engines']['mujoco']['CD_d'] != a['engines']['mujoco']['CD_d']


@pytest.mark.parametrize('rate', [10.0, 1000.0])
def test_runs_at_10_and_1000_hz(hanging_bag, tmp_path, rate):
    summary = _run(hanging_bag, tmp_path, f'r{rate}', rate_hz=rate)
    m = summary['engines']['mujoco']
    assert m['frames_scored'] == 132
    assert m['step_time']['count'] == round(7.4 * rate)
    assert m['diverged'] or np.isfinite(m['CD_d'])


@pytest.mark.timing
def test_realtime_pacing_reports_latency_deadline_misses_and_real_time_factor(
    hanging_bag, tmp_path
):
    summary = _run(hanging_bag, tmp_path, 'rt', rate_hz=100.0, pacing='realtime')
    m = summary['engines']['mujoco']
    assert m['frames_scored'] == 132
    # one state per target (741), less any a simulator skipped when it fell behind on a loaded
    # machine (keep-last 1 targets: it steps to the newest)
    assert 700 <= m['latency']['count'] <= 741
    assert m['latency']['count'] + m['skipped_targets'] == 741  # each target: a state or skipped
    assert 0 < m['latency']['p50'] <= m['latency']['p99'] <= m['latency']['max']
    assert 0 <= m['deadline_misses'] <= 741
    assert 0.5 < m['real_time_factor'] <= 1.05  # paced by the wall clock: about real time
    assert summary['run']['wall_time'] >= 7.4 * 0.95


def test_two_engines_in_one_run_are_scored_against_the_same_bag(hanging_bag, tmp_path):
    summary = _run(hanging_bag, tmp_path, 'both', engines=['mujoco', 'bullet'])
    assert set(summary['engines']) == {'mujoco', 'bullet'}
    for name, m in summary['engines'].items():
        assert m['frames_scored'] == 132 and m['frames_in_window'] == 99, name
        assert m['step_time']['count'] == 740 and m['skipped_targets'] == 0, name
    rows = (tmp_path / 'both' / 'frames.csv').read_text().splitlines()[1:]
    assert sorted({r.split(',')[0] for r in rows}) == ['bullet', 'mujoco'] and len(rows) == 264
    assert summary['engines']['mujoco']['CD_d'] != summary['engines']['bullet']['CD_d']


def test_the_printout_names_late_states_and_skipped_targets_only_when_paced_in_real_time():
    from cloth_bench_ros.report.run_report import result_table

    timing = {'mean': 1e-3, 'p50': 1e-3, 'p99': 2e-3, 'max': 3e-3}
    m = {
        'CD_d': 0.03, 'HD_d': 0.1, 'L_s': 1e-4, 'diverged': False, 'diverged_at_step': None,
        'step_time': {'count': 741, **timing}, 'latency': {'count': 709, **timing},
        'deadline_misses': 42, 'skipped_targets': 32,
    }
    summary = {'run': {'primitive': 'dynamic'}, 'engines': {'mujoco': m}}
    assert 'real time' not in result_table(summary)  # lockstep: no deadline to miss
    line = result_table(summary, realtime=True).splitlines()[-1]
    assert line.startswith('mujoco real time: latency p50 1.000 ms, p99 2.000 ms')
    assert '42 of 709 states late' in line and '32 targets skipped' in line
