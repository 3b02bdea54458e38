"""
Real rclpy over Fast DDS against the embedded runtime over Cyclone DDS, on this machine.

Two figures, each measured on both runtimes in the same command, inside loopback-only network
namespaces (`unshare -n`; Fast DDS multicasts on every interface otherwise):

- the round trip of a 20k-point PointCloud2 between two processes (ping -> echo -> ping), p50 and
  p99, and the ratio real / embedded;
- the wall time of the four-node graph run node by node as `ros2 run` starts them (MuJoCo 6x8,
  towel fling, the bundled bag; lockstep), from the first start to the evaluator's exit, and the
  ratio real / embedded.

Needs the real-ROS 2 venv that `./quickstart.sh test` makes (`.venv-ros`, or CLOTH_BENCH_ROS_VENV).

    .venv/bin/python benchmarks/bench_real_ros.py [--points 20000] [--count 300] [--runs 2]
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path
import random
import subprocess
import sys
import tempfile
import time

ROOT = Path(__file__).resolve().parents[1]
ROS_PYTHON = Path(os.environ.get('CLOTH_BENCH_ROS_VENV', ROOT / '.venv-ros')) / 'bin' / 'python'
NAMESPACE = 'ip link set lo up && ip link set lo multicast on && '


def _environment(real: bool, domain: int) -> dict[str, str]:
    """Return a process environment for one runtime on `domain`, confined to loopback."""
    from cloth_bench_ros.runtime.dds import loopback_environment

    env = {k: v for k, v in os.environ.items() if not k.startswith(('CYCLONEDDS', 'ROS_'))}
    env['PYTHONPATH'] = str(ROOT)
    if real:
        env.update(ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    else:
        env.update(loopback_environment(domain), CLOTH_BENCH_TRANSPORT='dds')
    return env


def _python(real: bool) -> str:
    return str(ROS_PYTHON) if real else sys.executable


# --- round trip (runs inside the namespace, under either runtime) ----------------------------


def _cloud(points: int):
    from cloth_bench_ros.core.pointcloud2 import create_cloud_xyz32
    from cloth_bench_ros.runtime import Header, PointCloud2, PointField
    import numpy as np

    xyz = np.random.default_rng(0).uniform(-1, 1, (points, 3)).astype(np.float32)
    return create_cloud_xyz32(Header(frame_id='world'), xyz, PointCloud2, PointField)


def echo() -> None:
    """Child: republish every `ping` on `pong` until killed."""
    from cloth_bench_ros.runtime import PointCloud2, rclpy, SingleThreadedExecutor

    rclpy.init(args=[])
    node = rclpy.create_node('bench_echo')
    pub = node.create_publisher(PointCloud2, 'pong', 10)
    node.create_subscription(PointCloud2, 'ping', pub.publish, 10)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    while rclpy.ok():
        executor.spin_once(timeout_sec=0.1)


def ping(points: int, count: int) -> None:
    """Parent: `count` round trips through an echo child; prints the seconds as JSON."""
    from cloth_bench_ros.runtime import PointCloud2, rclpy, SingleThreadedExecutor

    child = subprocess.Popen([sys.executable, __file__, '--echo'])
    rclpy.init(args=[])
    try:
        node = rclpy.create_node('bench_ping')
        got: list = []
        pub = node.create_publisher(PointCloud2, 'ping', 10)
        sub = node.create_subscription(PointCloud2, 'pong', got.append, 10)
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and not (
            pub.get_subscription_count() and sub.get_publisher_count()
        ):
            executor.spin_once(timeout_sec=0.05)
        msg, times = _cloud(points), []
        for i in range(count + 10):  # the first 10 warm up
            got.clear()
            start = time.perf_counter()
            pub.publish(msg)
            while not got and time.perf_counter() - start < 5:
                executor.spin_once(timeout_sec=0.5)
            if i >= 10 and got:
                times.append(time.perf_counter() - start)
        print(json.dumps(times))
    finally:
        child.kill()
        rclpy.shutdown()


def round_trips(real: bool, points: int, count: int) -> list[float]:
    command = f'{NAMESPACE}exec {_python(real)} {__file__} --ping {points} {count}'
    out = subprocess.run(
        ['unshare', '-n', 'sh', '-c', command],
        capture_output=True,
        text=True,
        env=_environment(real, random.randint(1, 101)),
        timeout=600,
    )
    if out.returncode != 0:
        raise SystemExit(f'round trip ({"real" if real else "embedded"}) failed: {out.stderr}')
    return json.loads(out.stdout.strip().splitlines()[-1])


# --- the four-node graph ---------------------------------------------------------------------


def graph_wall(real: bool, output: Path) -> float:
    """Run the four nodes as `ros2 run` does (one process each); return the wall time."""
    bag = ROOT / 'bags' / 'towel_dynamic'
    grid = '-p grid_nx:=6 -p grid_nz:=8'
    nodes = {
        'simulator': f'-p use_sim_time:=true -p engine:=mujoco {grid}',
        'recorder': f'-p use_sim_time:=true -p bag:={bag} {grid}',
        'trajectory_publisher': '',
        'evaluator': f'-p use_sim_time:=true -p output_dir:={output}',
    }
    python = _python(real)
    launches = ' & '.join(
        f'{python} -m cloth_bench_ros.nodes.{node} --ros-args -r __ns:=/cloth_bench {args}'
        f' > {output}.{node}.log 2>&1'
        for node, args in nodes.items()
    )
    stop = ' '.join(
        f"pkill -INT -f '^{python} -m cloth_bench_ros.nodes.{node} ';"
        for node in ('simulator', 'recorder')
    )
    # The evaluator is started last and waited for; its exit ends the run.
    script = f'{NAMESPACE}start=$(date +%s.%N); {launches}; end=$(date +%s.%N); {stop} wait; '
    script += 'echo "$start $end"'
    out = subprocess.run(
        ['unshare', '-n', 'sh', '-c', script],
        capture_output=True,
        text=True,
        env=_environment(real, random.randint(1, 101)),
        timeout=900,
    )
    summary = output / 'summary.json'
    if not summary.exists():
        raise SystemExit(f'graph ({"real" if real else "embedded"}) did not finish: {out.stderr}')
    start, end = map(float, out.stdout.split()[-2:])
    return end - start


def _p(times: list[float], q: float) -> float:
    ordered = sorted(times)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))] * 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--points', type=int, default=20000)
    parser.add_argument('--count', type=int, default=300)
    parser.add_argument('--runs', type=int, default=2, help='graph runs per runtime')
    parser.add_argument('--echo', action='store_true', help=argparse.SUPPRESS)
    parser.add_argument('--ping', nargs=2, type=int, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.echo:
        return echo()
    if args.ping:
        return ping(*args.ping)
    if not ROS_PYTHON.exists():
        raise SystemExit(f'no real-ROS 2 venv at {ROS_PYTHON} (./quickstart.sh test makes it)')
    trips = {real: round_trips(real, args.points, args.count) for real in (False, True)}
    for real, times in trips.items():
        name = 'real rclpy / Fast DDS' if real else 'embedded / Cyclone DDS'
        print(
            f'{args.points}-point cloud round trip, {name}: p50 {_p(times, 0.5):.2f} ms, '
            f'p99 {_p(times, 0.99):.2f} ms ({len(times)} of {args.count})'
        )
    ratio = _p(trips[True], 0.5) / _p(trips[False], 0.5)
    print(f'round trip p50 real / embedded: {ratio:.2f}')
    walls: dict[bool, list[float]] = {False: [], True: []}
    with tempfile.TemporaryDirectory() as tmp:
        for run in range(args.runs):
            for real in (False, True):  # back to back: this machine's speed drifts
                walls[real].append(graph_wall(real, Path(tmp) / f'{int(real)}_{run}'))
    for real, values in walls.items():
        name = 'real rclpy / Fast DDS' if real else 'embedded / Cyclone DDS'
        print(f'four-node graph, {name}: ' + ', '.join(f'{w:.1f} s' for w in values))
    ratios = [r / e for r, e in zip(walls[True], walls[False])]
    print('four-node graph wall real / embedded: ' + ', '.join(f'{r:.2f}' for r in ratios))


if __name__ == '__main__':
    main()
