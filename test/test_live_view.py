"""
`cloth-bench run --live` seen by an independent Foxglove WebSocket client.

The client here is written from the Foxglove WebSocket protocol specification with the
`websockets` library (none of foxglove-sdk's code): it connects while the run waits for a viewer,
subscribes to every advertised channel, and decodes what comes: binary frames of opcode 0x01
(uint32 subscription id, uint64 log time, then the payload, little-endian), payloads in CDR with
`ros2msg` schemas, decoded by rosbags and plain numpy. What it decodes is checked against the
run's frames.csv and summary.json, which the evaluator wrote from the same computation.
"""

from __future__ import annotations

import asyncio
import csv
import json
import os
from pathlib import Path
import re
import socket
import struct
import subprocess
import sys
import time

from cloth_bench_ros.core.task_data import load_task
import numpy as np
import pytest
from rosbags.typesys import get_typestore, Stores

websockets = pytest.importorskip('websockets')
pytest.importorskip('foxglove')

TYPES = get_typestore(Stores.ROS2_HUMBLE)
SUBPROTOCOLS = ['foxglove.sdk.v1', 'foxglove.websocket.v1']  # newest first, as the spec allows
SETTLE_NS = int(round(load_task('dynamic').settle_duration * 1e9))  # the motion's start, run time
GRID = '6x8'


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        return s.getsockname()[1]


def _cli(*args: str) -> list[str]:
    return [sys.executable, '-m', 'cloth_bench_ros.cli', *args]


def _start_run(out: Path, port: int, *extra: str) -> subprocess.Popen:
    cloth = () if '--cloth-mesh' in extra else ('--grid', GRID)
    return subprocess.Popen(
        _cli('run', *cloth, '--output', str(out), '--live', '--live-port', str(port), *extra),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, 'PYTHONPATH': os.pathsep.join(sys.path)},
    )


async def _connect(port: int, timeout: float = 60.0):
    deadline = time.monotonic() + timeout
    while True:
        try:
            return await websockets.connect(
                f'ws://127.0.0.1:{port}', subprotocols=SUBPROTOCOLS, max_size=None
            )
        except (OSError, websockets.exceptions.InvalidHandshake):
            if time.monotonic() > deadline:
                raise
            await asyncio.sleep(0.1)


async def _watch(port: int, read: bool = True, leave_after: int | None = None) -> dict:
    """Subscribe to every channel; return {topic: [(log_time, payload)]} and the channels."""
    ws = await _connect(port)
    channels: dict[int, dict] = {}
    got: dict[str, list] = {}
    subscribed: dict[int, str] = {}
    try:
        while True:
            try:
                msg = await asyncio.wait_for(ws.recv(), timeout=120)
            except websockets.exceptions.ConnectionClosed:
                break
            if isinstance(msg, str):
                op = json.loads(msg)
                if op['op'] == 'advertise':
                    new = [c for c in op['channels'] if c['id'] not in channels]
                    for c in new:
                        channels[c['id']] = c
                    subs = [{'id': 100 + c['id'], 'channelId': c['id']} for c in new]
                    for s in subs:
                        subscribed[s['id']] = channels[s['channelId']]['topic']
                    await ws.send(json.dumps({'op': 'subscribe', 'subscriptions': subs}))
                    if not read:  # a viewer that stops reading: the server must not wait on it
                        await asyncio.sleep(90)
                        break
                continue
            assert msg[0] == 0x01, f'unexpected binary opcode {msg[0]}'
            sub_id, log_time = struct.unpack_from('<IQ', msg, 1)
            got.setdefault(subscribed[sub_id], []).append((log_time, bytes(msg[13:])))
            if leave_after is not None and sum(map(len, got.values())) >= leave_after:
                break
    finally:
        await ws.close()
    return {'channels': list(channels.values()), 'messages': got}


def _cloud(payload: bytes) -> dict[str, np.ndarray]:
    """Every float32 field of a PointCloud2 (decoded here: rosbags CDR + numpy, not our codec)."""
    msg = TYPES.deserialize_cdr(payload, 'sensor_msgs/msg/PointCloud2')
    n, step = msg.width * msg.height, msg.point_step
    raw = np.frombuffer(bytes(msg.data), dtype=np.uint8).reshape(n, step)
    return {
        f.name: raw[:, f.offset:f.offset + 4].copy().view('<f4').ravel()
        for f in msg.fields
        if f.datatype == 7
    }


def _array(payload: bytes) -> tuple[str, list[float]]:
    msg = TYPES.deserialize_cdr(payload, 'std_msgs/msg/Float64MultiArray')
    return msg.layout.dim[0].label, [float(v) for v in msg.data]


def _frames_csv(path: Path) -> list[dict]:
    with path.open() as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope='module')
def watched(tmp_path_factory):
    """One lockstep run with --live and the independent client connected from its start."""
    out = tmp_path_factory.mktemp('live') / 'run'
    port = _free_port()
    proc = _start_run(out, port, '--live-wait', '60')
    try:
        seen = asyncio.run(_watch(port))
        stdout, stderr = proc.communicate(timeout=300)
    finally:
        proc.kill()
    assert proc.returncode == 0, stderr
    return out, seen, stdout, stderr


@pytest.mark.slow
def test_the_client_sees_every_channel_and_the_run_said_it_waited(watched):
    _, seen, _, stderr = watched
    topics = {c['topic']: c for c in seen['channels']}
    assert set(topics) == {
        '/cloth_bench/real/cloud',
        '/cloth_bench/targets',
        '/cloth_bench/scene',
        '/cloth_bench/mujoco/error_cloud',
        '/cloth_bench/mujoco/mesh',
        '/cloth_bench/mujoco/frame_metrics',
        '/cloth_bench/mujoco/step_metrics',
    }
    assert all(c['encoding'] == 'cdr' for c in topics.values())
    assert all(c['schemaEncoding'] == 'ros2msg' for c in topics.values())
    assert topics['/cloth_bench/mujoco/error_cloud']['schemaName'] == 'sensor_msgs/msg/PointCloud2'
    assert set(seen['messages']) == set(topics)  # every channel carried something
    waits = [line for line in stderr.splitlines() if 'waiting up to 60 s for a viewer' in line]
    assert len(waits) == 1


def _triangles_match_the_vertices(seen: dict, faces: np.ndarray) -> int:
    """Assert each mesh Marker is its frame's error-cloud vertices, triangle by triangle."""
    clouds = seen['messages']['/cloth_bench/mujoco/error_cloud']
    meshes = seen['messages']['/cloth_bench/mujoco/mesh']
    assert len(meshes) == len(clouds) > 0
    for (_, cloud), (_, mesh) in zip(clouds, meshes):
        msg = TYPES.deserialize_cdr(mesh, 'visualization_msgs/msg/Marker')
        assert msg.type == 11  # TRIANGLE_LIST
        points = np.array([[p.x, p.y, p.z] for p in msg.points])
        fields = _cloud(cloud)
        vertices = np.column_stack([fields['x'], fields['y'], fields['z']])
        assert points == pytest.approx(vertices[faces.ravel()], abs=1e-6)
    return len(meshes)


@pytest.mark.slow
def test_the_cloths_triangles_are_streamed_with_each_frame(watched):
    from cloth_bench_ros.core.scene import ClothGrid

    assert _triangles_match_the_vertices(watched[1], ClothGrid(6, 8).faces()) > 0


@pytest.mark.slow
def test_a_meshs_own_triangles_are_streamed_and_its_run_is_named(tmp_path):
    from cloth_bench_ros.core.scene import ClothGrid

    grid = ClothGrid(6, 8)
    faces = grid.faces()[::-1, ::-1]  # its own order and winding: not the grid's triangles
    mesh = tmp_path / 'sheet.obj'
    mesh.write_text(''.join(f'v {x!r} {y!r} {z!r}\n' for x, y, z in grid.vertices().tolist())
                    + ''.join(f'f {a + 1} {b + 1} {c + 1}\n' for a, b, c in faces.tolist()))
    port = _free_port()
    proc = _start_run(tmp_path / 'run', port, '--live-wait', '60', '--cloth-mesh', str(mesh))
    try:
        seen = asyncio.run(_watch(port))
        stdout, stderr = proc.communicate(timeout=300)
    finally:
        proc.kill()
    assert proc.returncode == 0, stderr
    assert _triangles_match_the_vertices(seen, faces) > 0
    assert f'run of: cloth mesh {mesh} (48 vertices, 70 triangles, sha256 ' in stdout


def test_clouds_and_their_error_field_match_frames_csv(watched):
    out, seen, _, _ = watched
    rows = _frames_csv(out / 'frames.csv')
    clouds = seen['messages']['/cloth_bench/mujoco/error_cloud']
    real = seen['messages']['/cloth_bench/real/cloud']
    assert len(clouds) == len(rows) == len(real)  # one engine: every scored frame, once
    for (log_time, payload), row in zip(clouds, rows):
        fields = _cloud(payload)
        assert set(fields) == {'x', 'y', 'z', 'error'}
        assert len(fields['error']) == 6 * 8  # the scored vertices of the 6x8 mesh
        error = fields['error'].astype(float)
        # each vertex's own term of CD: their mean is CD, their max HD (float32 on the wire)
        assert error.min() >= 0.0
        assert error.max() == pytest.approx(float(row['hd']), rel=1e-6, abs=1e-7)
        assert error.mean() == pytest.approx(float(row['cd']), rel=1e-5, abs=1e-7)
        # lockstep: stamped in simulation time, the real frame's stamp
        assert abs(log_time - (SETTLE_NS + float(row['t']) * 1e9)) < 2
    for log_time, payload in real:
        assert len(_cloud(payload)['x']) > 100  # the real frame, not the mesh


def test_metric_numbers_equal_frames_csv_and_the_summary(watched):
    out, seen, _, _ = watched
    rows = _frames_csv(out / 'frames.csv')
    metrics = [_array(p) for _, p in seen['messages']['/cloth_bench/mujoco/frame_metrics']]
    assert {label for label, _ in metrics} == {'t,cd,hd,in_window'}
    assert len(metrics) == len(rows)
    for (_, (t, cd, hd, in_window)), row in zip(metrics, rows):
        assert t == pytest.approx(float(row['t']), abs=1e-9)
        assert (cd, hd) == (float(row['cd']), float(row['hd']))  # the very numbers
        assert in_window == (1.0 if row['in_window'] == 'True' else 0.0)
    summary = json.loads((out / 'summary.json').read_text())['engines']['mujoco']
    steps = [_array(p) for _, p in seen['messages']['/cloth_bench/mujoco/step_metrics']]
    assert {label for label, _ in steps} == {'t,step_time,latency'}
    count = summary['step_time']['count']  # steps after the reset (step 0)
    assert len(steps) in (count, count + 1)
    step_times = np.array([v[1] for _, v in steps[len(steps) - count:]])
    assert step_times.max() == summary['step_time']['max']
    assert step_times.mean() == pytest.approx(summary['step_time']['mean'], rel=1e-12)
    latencies = np.array([v[2] for _, v in steps])
    finite = latencies[np.isfinite(latencies)]
    assert len(finite) >= count and finite.max() == summary['latency']['max']
    assert [v[0] for _, v in steps] == sorted(v[0] for _, v in steps)  # t in step order


@pytest.mark.slow
def test_metrics_are_identical_without_live(watched, tmp_path):
    out, _, _, _ = watched
    plain = tmp_path / 'plain'
    done = subprocess.run(
        _cli('run', '--grid', GRID, '--output', str(plain)),
        capture_output=True,
        text=True,
        env={**os.environ, 'PYTHONPATH': os.pathsep.join(sys.path)},
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    assert (plain / 'frames.csv').read_bytes() == (out / 'frames.csv').read_bytes()
    assert 'live view' not in done.stderr


@pytest.mark.slow
def test_a_port_in_use_is_one_line_and_exit_2(tmp_path):
    with socket.socket() as held:
        held.bind(('127.0.0.1', 0))
        held.listen()
        port = held.getsockname()[1]
        done = subprocess.run(
            _cli('run', '--grid', GRID, '--output', str(tmp_path / 'r'), '--live',
                 '--live-port', str(port)),
            capture_output=True,
            text=True,
            env={**os.environ, 'PYTHONPATH': os.pathsep.join(sys.path)},
            timeout=120,
        )
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and f'127.0.0.1:{port}' in lines[0] and 'Traceback' not in done.stderr


@pytest.mark.slow
def test_a_viewer_that_leaves_or_stops_reading_never_stalls_the_run(tmp_path):
    # One viewer subscribes to everything and never reads again; the run must end on its own.
    port = _free_port()
    proc = _start_run(tmp_path / 'slow', port, '--live-wait', '60')
    try:

        async def slow_then_gone() -> None:
            task = asyncio.create_task(_watch(port, read=False))
            while proc.poll() is None:
                await asyncio.sleep(0.2)
            task.cancel()

        started = time.monotonic()
        asyncio.run(slow_then_gone())
        stdout, stderr = proc.communicate(timeout=60)
        assert proc.returncode == 0, stderr
        assert time.monotonic() - started < 120
    finally:
        proc.kill()
    # A viewer that vanishes mid-run: one warning line, the run goes on to its report.
    port = _free_port()
    proc = _start_run(tmp_path / 'gone', port, '--live-wait', '60')
    try:
        seen = asyncio.run(_watch(port, leave_after=20))
        stdout, stderr = proc.communicate(timeout=300)
    finally:
        proc.kill()
    assert sum(map(len, seen['messages'].values())) >= 20
    assert proc.returncode == 0, stderr
    assert (tmp_path / 'gone' / 'frames.csv').is_file()
    left = [line for line in stderr.splitlines() if 'viewer left' in line]
    assert len(left) == 1, stderr


def test_the_shipped_layout_is_made_from_the_topic_names_the_stream_uses(watched):
    from cloth_bench_ros.live.layout import layout_json
    from cloth_bench_ros.live.view import LAYOUT_FILE
    from cloth_bench_ros.paths import share_dir

    shipped = share_dir('config') / 'foxglove' / LAYOUT_FILE
    assert shipped.read_text() == layout_json()  # `python -m cloth_bench_ros.live.layout`
    layout = json.loads(shipped.read_text())
    text = json.dumps(layout)
    paths = re.findall(r'/cloth_bench/[\w/]+(?:\.data\[\d\])?', text)
    referenced = {re.sub(r'\.data\[\d\]$', '', t) for t in paths}
    streamed = {c['topic'] for c in watched[1]['channels']}
    for engine in ('bullet', 'newton'):  # the layout's other engines, by the same names
        streamed |= {t.replace('/mujoco/', f'/{engine}/') for t in streamed}
    assert referenced and referenced <= streamed
    # the plotted indices are those of the documented field orders
    assert '/cloth_bench/mujoco/frame_metrics.data[1]' in text  # cd
    assert '/cloth_bench/mujoco/step_metrics.data[1]' in text  # step_time
    assert layout['content']['items'][0]['content']['panelType'] == 'ThreeDee'


def test_the_streams_shortcut_encodings_are_rosbags_cdr_byte_for_byte():
    """Error clouds, poses and metric arrays are put into bytes serialised once by rosbags."""
    from cloth_bench_ros.core.evaluation import FrameScore, ScoredFrame
    from cloth_bench_ros.core.pointcloud2 import create_cloud_xyz_fields
    from cloth_bench_ros.core.trajectory import full_targets
    from cloth_bench_ros.live import error_view
    from cloth_bench_ros.live.comparison_bag import target_poses, targets_message

    rng = np.random.default_rng(5)
    tg = full_targets('dynamic', 100.0)
    for n, stamp, diverged in ((48, 3_000_000_001, False), (165, 7_123_456_789, False),
                               (48, 4_000_000_000, True)):
        score = FrameScore('mujoco', 3, 0.1, 0.02, 0.05, True, diverged)
        vertices = rng.normal(size=(n, 3))
        errors = None if diverged else rng.uniform(0, 0.1, n)
        scored = ScoredFrame(score, stamp, rng.normal(size=(10, 3)), vertices, errors)
        msg = create_cloud_xyz_fields(
            TYPES.types['std_msgs/msg/Header'](
                stamp=TYPES.types['builtin_interfaces/msg/Time'](
                    sec=stamp // 10**9, nanosec=stamp % 10**9
                ),
                frame_id='world',
            ),
            vertices,
            {'error': np.full(n, np.nan) if errors is None else errors},
            TYPES.types['sensor_msgs/msg/PointCloud2'],
            TYPES.types['sensor_msgs/msg/PointField'],
        )
        assert error_view.cdr_error_cloud(scored) == bytes(
            TYPES.serialize_cdr(msg, 'sensor_msgs/msg/PointCloud2')
        )
        poses = error_view.cdr_poses(stamp, target_poses(tg, 100.0, stamp))
        reference = targets_message(tg, 100.0, stamp)
        assert poses == bytes(TYPES.serialize_cdr(reference, 'geometry_msgs/msg/PoseArray'))
        values = [score.t, score.cd, float('nan'), 1.0]
        array = TYPES.deserialize_cdr(
            error_view.cdr_metrics(values, error_view.FRAME_METRICS),
            'std_msgs/msg/Float64MultiArray',
        )
        assert array.layout.dim[0].label == 't,cd,hd,in_window'
        np.testing.assert_array_equal(array.data, values)


@pytest.mark.slow
def test_hil_live_is_stamped_in_wall_time_and_never_waits(tmp_path):
    port = _free_port()
    started = time.time_ns()
    proc = subprocess.Popen(
        _cli('hil', '--in-process', '--grid', GRID, '--no-lockstep', '--output',
             str(tmp_path / 'hil'), '--live', '--live-port', str(port)),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, 'PYTHONPATH': os.pathsep.join(sys.path)},
    )
    try:
        seen = asyncio.run(_watch(port))
        stdout, stderr = proc.communicate(timeout=300)
    finally:
        proc.kill()
    ended = time.time_ns()
    assert proc.returncode == 0, stderr
    assert 'waiting up to' not in stderr and f'live view at ws://127.0.0.1:{port}' in stderr
    clouds = seen['messages']['/cloth_bench/mujoco/error_cloud']
    assert clouds  # a realtime run starts on its schedule: the client sees what follows its join
    log_times = [log_time for log_time, _ in clouds]
    assert started <= log_times[0] and log_times[-1] <= ended  # wall time, not simulation time
    assert log_times == sorted(log_times)
