"""The recorder node: replay options, and recording that loses nothing on SIGINT/SIGTERM."""

import signal
import subprocess
import sys
import textwrap
import time

from cloth_bench_ros.data import BagReader
from cloth_bench_ros.nodes.common import run_nodes
from cloth_bench_ros.nodes.recorder import Recorder
from cloth_bench_ros.runtime import embedded as rclpy
from cloth_bench_ros.runtime import make_qos, Node, PointCloud2, SingleThreadedExecutor, stamp_ns
from cloth_bench_ros.runtime.embedded import Parameter
import pytest

BURST = textwrap.dedent('''
    import sys
    import numpy as np
    from cloth_bench_ros.nodes.common import run_nodes
    from cloth_bench_ros.nodes.recorder import Recorder
    from cloth_bench_ros.core.pointcloud2 import create_cloud_xyz32
    from cloth_bench_ros.runtime import Header, Node, PointCloud2, PointField, Time, make_qos

    TOTAL = int(sys.argv[1])

    class Burst(Node):
        """Publishes TOTAL clouds, 20 per millisecond tick, stamped with their index."""
        def __init__(self):
            super().__init__("burst", namespace="cloth_bench")
            self.pub = self.create_publisher(PointCloud2, "sim/cloud", make_qos(10))
            self.points = np.random.default_rng(0).normal(size=(100, 3))
            self.k = 0
            self.done = True  # the process runs until it is signalled
            self.timer = self.create_timer(0.001, self.tick)

        def tick(self):
            for _ in range(20):
                if self.k == TOTAL:
                    print("published", TOTAL, flush=True)
                    self.timer.cancel()
                    return
                header = Header(stamp=Time(nanoseconds=self.k).to_msg(), frame_id="world")
                self.pub.publish(create_cloud_xyz32(header, self.points, PointCloud2, PointField))
                self.k += 1
                if self.k == 100:
                    print("started", flush=True)

    sys.exit(run_nodes([Burst, Recorder], sys.argv[2:]))
''')


def _record(tmp_path, total, wait_for, sig):
    script = tmp_path / 'burst.py'
    script.write_text(BURST)
    out = tmp_path / 'recorded'
    proc = subprocess.Popen(
        [
            sys.executable,
            str(script),
            str(total),
            '--ros-args',
            '-p',
            'mode:=record',
            '-p',
            f'output:={out}',
            '-p',
            "record_topics:=['sim/cloud:sensor_msgs/msg/PointCloud2']",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    for line in proc.stdout:
        if line.startswith(wait_for):
            break
    if wait_for == 'started':
        time.sleep(0.3)
    proc.send_signal(sig)
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 0, stderr
    report = [line for line in stdout.splitlines() if line.startswith('recorder:')]
    assert len(report) == 1, stdout + stderr
    received, written = (int(w) for w in report[0].replace(',', '').split() if w.isdigit())
    return out, received, written


def _stamps(bag):
    return [stamp for _, _, stamp, _ in BagReader(bag).raw_messages()]


def test_sigint_after_10000_messages_keeps_all_of_them(tmp_path):
    out, received, written = _record(tmp_path, 10_000, 'published', signal.SIGINT)
    assert received == written == 10_000
    assert _stamps(out) == list(range(10_000))


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM])
def test_interrupted_recording_holds_every_acknowledged_message(tmp_path, sig):
    out, received, written = _record(tmp_path, 10_000_000, 'started', sig)
    assert 100 <= received == written
    assert _stamps(out) == list(range(written))


def _replay(bag, **params):
    ctx = rclpy.Context()
    rclpy.init(args=[], context=ctx)
    recorder = Recorder(
        context=ctx,
        parameter_overrides=[
            Parameter(k, value=v) for k, v in {'bag': str(bag), 'clock': 'wall', **params}.items()
        ],
    )
    listener = Node('listener', context=ctx)
    got = []
    listener.create_subscription(
        PointCloud2,
        '/cloth_bench/real/cloud',
        lambda m: got.append(stamp_ns(m.header.stamp)),
        make_qos(10),
    )
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(recorder)
    ex.add_node(listener)
    start = time.monotonic()
    ex.spin_until_idle()
    ctx.shutdown()
    return got, time.monotonic() - start


def test_wall_clock_replay_with_rate_factor_and_start_offset(hanging_bag):
    got, elapsed = _replay(hanging_bag, rate_factor=20.0, start_offset=1.0)
    assert got == [round(k * 1e9 / 30) for k in range(30, 132)]
    assert 0.8 * (131 - 30) / 30 / 20 <= elapsed < 5.0  # 3.4 s of bag at 20x


def test_replay_of_missing_bag_is_a_clear_error(tmp_path):
    code = run_nodes([lambda: Recorder()], ['x', '--ros-args', '-p', f'bag:={tmp_path / "none"}'])
    assert code == 2
