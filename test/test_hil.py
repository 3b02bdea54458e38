"""
Hardware in the loop: a short real-time run in three processes over DDS.

On loopback, own domain: the controller's timeline and its bookkeeping, keep-last skipping, the
lean step path, process settings, and the configuration recommended for a rate; real engines, real
Cyclone DDS.
"""

from __future__ import annotations

import contextlib
from dataclasses import replace
import gc
import math
import os
import subprocess
import sys
import threading

from cloth_bench_ros.cli import main
from cloth_bench_ros.core import realtime_process as realtime
from cloth_bench_ros.core.hil_timing import check_bookkeeping, hil_figures, TargetTimeline
from cloth_bench_ros.core.pointcloud2 import read_xyz
from cloth_bench_ros.core.scene import ClothGrid
from cloth_bench_ros.core.trajectory import full_targets
from cloth_bench_ros.engines.base import check_divergence
from cloth_bench_ros.engines.mujoco_cloth import MujocoCloth
from cloth_bench_ros.hil import study as hil
from cloth_bench_ros.nodes.simulator import Simulator, StateMessages
from cloth_bench_ros.report.hil import write_hil_report
from cloth_bench_ros.runtime import (
    embedded,
    Parameter,
    PointCloud2,
    Pose,
    PoseArray,
    stamp_ns,
    Time,
)
from cloth_bench_ros.runtime.dds import loopback_environment
from cloth_bench_ros.sweep.recommend import load_recommendations, recommend_for_rate
from dds_domains import random_domain
import numpy as np
import pytest

MS = 1_000_000


@pytest.fixture
def dds_loopback(monkeypatch) -> None:
    """Confine Cyclone to lo, no multicast, peer 127.0.0.1, a random domain; children inherit."""
    for key, value in loopback_environment(random_domain()).items():
        monkeypatch.setenv(key, value)
    monkeypatch.delenv('ROS_AUTOMATIC_DISCOVERY_RANGE', raising=False)
    monkeypatch.delenv('ROS_STATIC_PEERS', raising=False)


@pytest.mark.slow
@pytest.mark.parametrize('layout', ['sleeping', 'pinned_polling'])
@pytest.mark.timing
def test_short_realtime_run_in_three_processes_accounts_for_every_target(
    dds_loopback, hanging_bag, tmp_path, layout
):
    rate = 200.0
    config = hil.HilConfig('mujoco', rate, hanging_bag, grid=(6, 8), duration=0.4)  # 81 targets
    if (
        layout == 'pinned_polling'
    ):  # the real-time layout of docs/hil.md: step loop alone on the last core, polling
        if len(os.sched_getaffinity(0)) < 2:
            pytest.skip('the pinned layout needs two cores')
        config = replace(config, cpu=max(os.sched_getaffinity(0)), busy_wait=True)
    result = hil.run_hil(config, tmp_path, lockstep=False)
    timeline = TargetTimeline.from_csv((result.run_dir / 'timeline_mujoco.csv').read_text())
    f = result.figures
    assert result.problems == []
    # Every target sent, each either stepped (its state came back) or skipped by the simulator.
    assert f.targets == f.sent == len(timeline) == 81
    assert result.stepped + result.skipped == f.sent and f.states == result.stepped and f.lost == 0
    assert result.stepped >= 1
    # The schedule: target k due k / rate after the first; none sent before half a period ahead of
    # it.
    period = round(1e9 / rate)
    assert np.all(np.diff(timeline.due) == period)
    assert np.all(timeline.sent >= timeline.due - period // 2)
    got = timeline.received >= 0
    assert got[-1] and np.all(
        timeline.received[got][1:] > timeline.sent[got][1:]
    )  # keep-last: the last is stepped
    # Target 0 is the start-up handshake's: answered before the schedule, which starts at its
    # answer.
    assert timeline.sent[0] == timeline.due[0] == timeline.received[0]
    # Latencies and misses are the timestamps' own: received - due, missed when over one period.
    latency = (timeline.received[got] - timeline.due[got]) / 1e9
    assert f.deadline_misses == int(np.sum(latency > 1 / rate))
    assert f.latency_max == pytest.approx(latency.max()) and f.latency_p50 == pytest.approx(
        np.median(latency)
    )
    assert 0 < f.latency_p50 <= f.latency_p99 <= f.latency_p999 <= f.latency_max
    # The simulator ran in a process of its own, heap frozen, and timed its steps.
    assert any('automatic collection off' in line for line in result.realtime)
    assert 0 < result.step_time['p50'] <= result.step_time['p99']
    assert (result.run_dir / 'simulator.log').is_file() and (
        result.run_dir / 'controller.log'
    ).is_file()
    if layout == 'pinned_polling':
        assert any(
            line.startswith(f'cpu: step loop pinned to core {config.cpu}, ')
            for line in result.realtime
        )
        assert any(line.startswith('poll: step loop polls') for line in result.realtime)
        others = (result.run_dir / 'controller.log').read_text() + (
            result.run_dir / 'observer.log'
        ).read_text()
        assert others.count(f'kept off core {config.cpu}') == 2 and 'observer: nice 19' in others
    report = write_hil_report([result.row()], tmp_path, tmp_path / 'report')
    assert 'lat p99.9 ms' in report.read_text() and (tmp_path / 'report' / 'hil.csv').is_file()
    assert (tmp_path / 'report' / f'latency_{result.run_dir.name}.png').stat().st_size > 1000


def _timeline(received_ms: list[float | None], sent_late_ms: float = 1.0) -> TargetTimeline:
    timeline = TargetTimeline(np.arange(len(received_ms), dtype=np.int64) * 10 * MS)  # 100 Hz
    timeline.start(1_000 * MS)
    timeline.sent[:] = timeline.due + int(sent_late_ms * MS)
    for k, ms in enumerate(received_ms):
        if ms is not None:
            timeline.received[k] = timeline.due[k] + int(ms * MS)
    return timeline


def test_figures_and_bookkeeping_follow_the_timestamps():
    timeline = _timeline([2.0, 12.0, None, 5.0, 3.0])  # target 2 skipped, target 1 late
    f = hil_figures(timeline, skipped=1, period_s=0.01)
    assert (f.sent, f.states, f.skipped, f.lost, f.deadline_misses) == (5, 4, 1, 0, 1)
    assert f.latency_max == pytest.approx(0.012) and f.latency_p50 == pytest.approx(0.004)
    assert f.send_lag_p99 == pytest.approx(0.001)
    assert f.real_time_factor == pytest.approx(0.040 / 0.043)
    assert check_bookkeeping(timeline, stepped=4, skipped=1) == []
    assert check_bookkeeping(timeline, stepped=4, skipped=0) == ['sent 5 != stepped 4 + skipped 0']
    assert hil_figures(timeline, skipped=0, period_s=0.01).lost == 1
    early = _timeline([2.0, 3.0, 2.0])
    early.received[1] = early.sent[1] - 1
    assert 'a state came back before its target was sent' in check_bookkeeping(early, 3, 0)
    unsent = _timeline([2.0, None, None])
    unsent.sent[2] = -1
    assert '1 of 3 targets were never sent' in check_bookkeeping(unsent, 1, 1)
    again = TargetTimeline.from_csv(timeline.to_csv())
    assert all(
        np.array_equal(getattr(again, a), getattr(timeline, a))
        for a in ('stamps', 'due', 'sent', 'received')
    )
    with pytest.raises(ValueError, match='header'):
        TargetTimeline.from_csv('a,b\n1,2\n')


def _target(targets, k: int) -> PoseArray:
    msg = PoseArray()
    msg.header.stamp = Time(nanoseconds=targets.stamp_ns(k)).to_msg()
    for xyz in (targets.left[k], targets.right[k]):
        pose = Pose()
        pose.position.x, pose.position.y, pose.position.z = (float(c) for c in xyz)
        msg.poses.append(pose)
    return msg


def test_a_late_simulator_steps_to_the_newest_target_and_counts_the_skipped_ones():
    context = embedded.Context()
    embedded.init(args=[], context=context, transport='intra')
    try:
        sim = Simulator(
            context=context,
            parameter_overrides=[
                Parameter('engine', value='mujoco'),
                Parameter('grid_nx', value=6),
                Parameter('grid_nz', value=8),
            ],
        )
        targets = full_targets('dynamic', 100.0)
        prepared = sim.prepared.copy()
        clouds = []
        sim.create_subscription(PointCloud2, 'mujoco/cloud', clouds.append, 10)
        executor = embedded.SingleThreadedExecutor(context=context)
        executor.add_node(sim)
        # Target 0 twice (the controller's start-up handshake, then the schedule's first target):
        # answered twice, stepped once; then the transport kept only the newest: 2, 3, 5-8 never
        # arrived.
        for k in (0, 0, 1, 4, 9):
            sim.on_target(_target(targets, k))
            while context.queue:
                executor.spin_once(0)
        assert (sim.step, sim.skipped, sim.last_k) == (3, 6, 9)
        assert [stamp_ns(c.header.stamp) for c in clouds] == [
            targets.stamp_ns(k) for k in (0, 0, 1, 4, 9)
        ]
        assert clouds[0] is clouds[1]  # the same state again, no step
        assert np.isfinite(sim.step_times[1:4]).all() and np.isnan(sim.step_times[4:]).all()
        # Target 0 was answered with the state prepared at start-up, no reset on the deadline.
        assert np.array_equal(sim.engine.reset(0, targets.left[0], targets.right[0]), prepared)
        sim.close()
    finally:
        embedded.shutdown(context=context)


def test_state_messages_are_filled_in_place_only_where_publish_serialises():
    vertices = [np.full((4, 3), float(i)) for i in range(2)]
    stamp = Time(nanoseconds=5).to_msg()
    reused = StateMessages('mujoco', 4, in_place=True)
    first = reused.fill(stamp, vertices[0], 1, 1e-3, None, 0)
    second = reused.fill(stamp, vertices[1], 2, 2e-3, None, 3)
    assert first[0] is second[0] and np.array_equal(read_xyz(second[0]), vertices[1])
    assert {kv.key: kv.value for kv in second[1].status[0].values}['skipped_targets'] == '3'
    fresh = StateMessages('mujoco', 4, in_place=False)
    a, b = (
        fresh.fill(stamp, vertices[0], 1, 1e-3, None, 0),
        fresh.fill(stamp, vertices[1], 2, 1e-3, None, 0),
    )
    assert a[0] is not b[0] and np.array_equal(read_xyz(a[0]), vertices[0])


def test_the_cheap_divergence_check_agrees_with_the_full_one():
    engine = MujocoCloth(100.0, {}, ClothGrid(6, 8))
    targets = full_targets('dynamic', 100.0)
    left, right = targets.left[0], targets.right[0]
    rest = engine.reset(0, left, right).copy()
    cases = {
        'ok': rest + 1e-4,
        'nan': rest.copy(),
        'far': rest + [6.0, 0, 0],
        'fast': rest + [1.5, 0, 0],
    }
    cases['nan'][3, 1] = np.nan
    reasons = {}
    for name, vertices in cases.items():
        reasons[name] = engine._check(vertices, left, right)
        assert reasons[name] == check_divergence(vertices, rest, engine.dt, (left + right) / 2)
    assert reasons['ok'] is None and 'non-finite' in reasons['nan']
    assert 'from the grippers' in reasons['far'] and 'm/s' in reasons['fast']
    engine.close()


def test_pinning_gives_the_step_loop_its_core_and_moves_the_other_threads_off_it():
    before = os.sched_getaffinity(0)
    if len(before) < 2:
        pytest.skip('needs two cores')
    core = max(before)
    stop = threading.Event()
    helper = threading.Thread(target=stop.wait)  # stands in for a DDS receive thread
    helper.start()
    try:
        assert realtime.pin_to_cpu(core).startswith(f'step loop pinned to core {core}, ')
        assert os.sched_getaffinity(0) == {core}  # the calling thread
        assert os.sched_getaffinity(helper.native_id) == before - {core}
        assert realtime.keep_off_cpu(core).startswith(f'kept off core {core}')
        assert all(core not in _affinity(tid) for tid in realtime.threads())
    finally:
        stop.set()
        helper.join()
        for tid in realtime.threads():
            with contextlib.suppress(ProcessLookupError):  # a thread that ended meanwhile
                os.sched_setaffinity(tid, before)


def _affinity(tid: int) -> set[int]:
    """Return a thread's cores, none for one that ended since it was listed."""
    try:
        return os.sched_getaffinity(tid)
    except ProcessLookupError:
        return set()
    assert realtime.keep_off_cpu(-1).startswith('not pinned')


def test_a_polling_loop_leaves_sched_fifo_for_the_kernels_real_time_budget():
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))  # this thread only
    except PermissionError:
        assert realtime.poll_on_default_scheduler() == 'step loop polls on the default scheduler'
        return
    line = realtime.poll_on_default_scheduler()
    assert os.sched_getscheduler(0) == os.SCHED_OTHER
    assert 'SCHED_OTHER' in line and 'throttled' in line
    assert realtime.poll_on_default_scheduler() == 'step loop polls on the default scheduler'


def test_the_observer_yields_the_cpu():
    code = (
        'import os; from cloth_bench_ros.core import realtime_process as realtime;'
        ' print(realtime.lower_priority()); print(os.getpriority(os.PRIO_PROCESS, 0))'
    )
    out = subprocess.run(
        [sys.executable, '-c', code], capture_output=True, text=True, check=True
    ).stdout.split('\n')
    assert out[0] == 'nice 19 (off the critical path)' and out[1] == '19'


def test_process_settings_report_what_the_system_granted():
    assert 'refused' in realtime.pin_to_cpu(100_000)
    assert realtime.pin_to_cpu(-1).startswith('not pinned')
    assert realtime.request_fifo(0).startswith('default scheduler')
    assert 'outside' in realtime.request_fifo(1000)
    try:
        assert (
            'frozen' in realtime.freeze_heap() and not gc.isenabled() and gc.get_freeze_count() > 0
        )
        junk = [[] for _ in range(realtime.YOUNG_THRESHOLD + 10)]
        assert gc.get_count()[0] >= realtime.YOUNG_THRESHOLD
        realtime.collect_young()
        assert gc.get_count()[0] < realtime.YOUNG_THRESHOLD
        del junk
    finally:
        gc.unfreeze()
        gc.enable()
    outcome = realtime.apply(-1, 0, True)
    assert not gc.isenabled()
    realtime.release(outcome)
    assert gc.isenabled() and gc.get_freeze_count() == 0


def _settings_row(
    config: str, cd: float, mean_ms: float, p99_ms: float, grid: str | None = None
) -> dict:
    return {
        'mode': 'settings',
        'engine': 'mujoco',
        'cloth': 'towel',
        'primitive': 'dynamic',
        'rate_hz': 100.0,
        'config': config,
        'status': 'ok',
        'seed': 0,
        'CD': cd,
        'HD': 2 * cd,
        'step_time_mean': mean_ms / 1e3,
        'step_time_p50': mean_ms / 1e3,
        'step_time_p99': p99_ms / 1e3,
        'grid': grid,
        'params': {'solver_iterations': 5} if grid else {},
    }


def test_recommendation_is_the_cheapest_accurate_enough_within_the_deadline(tmp_path):
    rows = [
        _settings_row('accurate', 0.020, 3.0, 12.0),
        _settings_row('fine', 0.021, 1.0, 4.0, '8x11'),
        _settings_row('coarse', 0.030, 0.5, 1.0, '6x8'),
    ]
    rec = recommend_for_rate(rows, 'mujoco', 'towel', 'dynamic', 100.0, 0.05, 0.002)
    assert (rec.config, rec.grid, rec.params, rec.meets_deadline) == (
        'fine',
        (8, 11),
        {'solver_iterations': 5},
        True,
    )
    assert rec.best_config == 'accurate' and rec.step_p99_ms == pytest.approx(4.0)
    tight = recommend_for_rate(rows, 'mujoco', 'towel', 'dynamic', 100.0, 0.05, 0.002, budget=0.3)
    assert (tight.config, tight.meets_deadline) == (
        'fine',
        False,
    )  # none within 3 ms: cheapest accurate
    assert recommend_for_rate(rows, 'mujoco', 'towel', 'dynamic', 1000.0) is None
    from cloth_bench_ros.report.document import render_report

    outcome = render_report(
        rows, tmp_path, tmp_path / 'report'
    )  # the settings report shows the criterion
    table = outcome.tables['deadline_mujoco_towel_dynamic_100hz']
    assert [row[0] for row in table.rows] == ['coarse', 'fine', 'accurate']  # by step p99
    assert [row[3] for row in table.rows] == ['yes', 'yes', 'no'] and table.rows[1][
        -1
    ] == '**recommended**'


def test_recommended_falls_back_to_the_shipped_file_with_its_provenance(tmp_path, capsys):
    rec, source = hil.recommended('mujoco', 'towel', 'dynamic', 1000.0, tmp_path / 'no_sweep_here')
    assert 'hil_recommended.yaml (shipped' in source
    shipped = {
        (r.engine, r.rate_hz): r for r in load_recommendations(hil.Path(source.split(' ')[0]))
    }
    assert {('mujoco', 100.0), ('mujoco', 1000.0), ('bullet', 100.0), ('bullet', 1000.0)} <= set(
        shipped
    )
    assert (
        rec == shipped['mujoco', 1000.0]
        and rec.grid is not None
        and rec.cd <= rec.best_cd + rec.tolerance_m
    )
    with pytest.raises(ValueError, match='no settings-sweep result'):
        hil.recommended('mujoco', 'linen', 'quasi_static', 1000.0, tmp_path)
    bad = tmp_path / 'bad.yaml'
    bad.write_text('recommendations: [{engine: mujoco}]\n')
    with pytest.raises(ValueError, match='bad.yaml: entry 0'):
        load_recommendations(bad)


@pytest.mark.timing
def test_cli_hil_in_process_with_the_recommended_configuration(hanging_bag, tmp_path, capsys):
    from cloth_bench_ros.sweep.study import append_row

    settings = tmp_path / 'settings'
    settings.mkdir()
    for row in (
        _settings_row('grid=6x8', 0.030, 1.0, 4.0, '6x8'),
        _settings_row('grid=8x11', 0.050, 0.5, 2.0, '8x11'),
    ):
        append_row(settings / 'results.jsonl', row)
    code = main(
        [
            'hil',
            '--rate',
            '100',
            '--bag',
            str(hanging_bag),
            '--config',
            'recommended',
            '--settings',
            str(settings),
            '--in-process',
            '--duration',
            '0.3',
            '--no-lockstep',
            '--output',
            str(tmp_path / 'o'),
        ]
    )
    out = capsys.readouterr().out
    assert code == 0, out
    assert f'recommended `grid=6x8` from settings sweep {settings}' in out and 'under 5 ms' in out
    assert (
        'lat p99.9 ms' in out and '1 process' in out and (tmp_path / 'o' / 'hil.jsonl').is_file()
    )
    assert gc.isenabled()  # the simulator froze the heap of this process and gave it back
    assert (
        main(['hil', '--config', 'recommended', '--grid', '6x8', '--bag', str(hanging_bag)]) == 2
    )
    assert main(['hil', '--engine', 'nosuch']) == 2
    assert math.isfinite(hil.HilConfig('mujoco', 100.0, hanging_bag).rate_hz)
