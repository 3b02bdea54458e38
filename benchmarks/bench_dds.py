"""
Round trip over the DDS transport between two processes: a 20k-point PointCloud2 and a PoseArray.

This process publishes on `ping`; a child process (this script with --echo) republishes each
message on `pong`. Both run the embedded runtime over Cyclone DDS, confined to loopback (interface
lo, no multicast, peer 127.0.0.1) on a random ROS domain. Prints p50/p99 of the round trip, and
the same for Cyclone's own Python serialisation of the rosidl types (the element-by-element path
the transport avoids) as the baseline, with the ratio. Goal: cloud p50 <= 1 ms on an idle machine.

    .venv/bin/python benchmarks/bench_dds.py [--points 20000] [--count 300] [--no-baseline]
"""

from __future__ import annotations

import argparse
import os
import random
import subprocess
import sys
import time

from cloth_bench_ros.core.pointcloud2 import create_cloud_xyz32
from cloth_bench_ros.runtime import embedded as rclpy
from cloth_bench_ros.runtime import messages as M
from cloth_bench_ros.runtime.dds import loopback_environment
import numpy as np

TYPES = {'cloud': M.PointCloud2, 'poses': M.PoseArray}


def cloud(points: int) -> object:
    xyz = np.random.default_rng(0).uniform(-1, 1, (points, 3)).astype(np.float32)
    return create_cloud_xyz32(M.Header(frame_id='world'), xyz, M.PointCloud2, M.PointField)


def poses() -> object:
    msg = M.PoseArray(header=M.Header(frame_id='world'))
    msg.poses = [M.Pose(position=M.Point(x=0.1 * i, y=0.2, z=0.3)) for i in range(2)]
    return msg


def echo(kind: str) -> None:
    """Child: republish every `ping` on `pong` until killed."""
    rclpy.init(args=[], transport='dds')
    node = rclpy.Node('bench_echo')
    pub = node.create_publisher(TYPES[kind], 'pong', 10)
    node.create_subscription(TYPES[kind], 'ping', pub.publish, 10)
    executor = rclpy.SingleThreadedExecutor()
    executor.add_node(node)
    while rclpy.ok():
        executor.spin_once(timeout_sec=0.1)


def round_trips(kind: str, msg: object, count: int, env: dict[str, str]) -> np.ndarray:
    """Count round trips of msg through an echo process; seconds each."""
    child = subprocess.Popen([sys.executable, __file__, '--echo', kind], env=env)
    rclpy.init(args=[], transport='dds')
    try:
        node = rclpy.Node('bench_ping')
        got: list = []
        pub = node.create_publisher(TYPES[kind], 'ping', 10)
        node.create_subscription(TYPES[kind], 'pong', got.append, 10)
        executor = rclpy.SingleThreadedExecutor()
        executor.add_node(node)
        deadline = time.monotonic() + 30
        while not (pub.get_subscription_count() and node.get_publishers_info_by_topic('pong')):
            executor.spin_once(timeout_sec=0.05)
            if time.monotonic() > deadline:
                raise SystemExit('bench_dds: the echo process did not appear within 30 s')
        times = []
        for i in range(count + 20):  # the first 20 warm up
            got.clear()
            start = time.perf_counter()
            pub.publish(msg)
            while not got:
                executor.spin_once(timeout_sec=1.0)
            if i >= 20:
                times.append(time.perf_counter() - start)
        return np.array(times)
    finally:
        rclpy.shutdown()
        child.terminate()
        child.wait(10)


def baseline_echo(kind: str) -> None:
    """Child of the baseline: Cyclone's own typed reader and writer (element-by-element CDR)."""
    from cloth_bench_ros.runtime.dds.idl import dds_type
    from cloth_bench_ros.runtime.dds.domain import domain_id
    from cloth_bench_ros.runtime.dds.qos import endpoint_qos
    from cyclonedds.core import InstanceState, ReadCondition, SampleState, ViewState, WaitSet
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.pub import DataWriter
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic

    participant = DomainParticipant(domain_id())
    cls = dds_type(TYPES[kind].__msgtype__)
    qos = endpoint_qos(rclpy.QoSProfile(depth=10))
    reader = DataReader(participant, Topic(participant, 'rt/ping', cls), qos=qos)
    writer = DataWriter(participant, Topic(participant, 'rt/pong', cls), qos=qos)
    waitset = WaitSet(participant)
    waitset.attach(ReadCondition(reader, SampleState.Any | ViewState.Any | InstanceState.Any))
    while True:
        waitset.wait(10**9)
        for sample in reader.take(N=10):
            writer.write(sample)


def baseline_round_trips(kind: str, msg: object, count: int, env: dict[str, str]) -> np.ndarray:
    """Return the same round trip with typed samples serialised by Cyclone's Python binding."""
    from cloth_bench_ros.data import messages as cdr
    from cloth_bench_ros.runtime.dds.idl import dds_type
    from cloth_bench_ros.runtime.dds.domain import domain_id
    from cloth_bench_ros.runtime.dds.qos import endpoint_qos
    from cyclonedds.core import InstanceState, ReadCondition, SampleState, ViewState, WaitSet
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.pub import DataWriter
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic

    child = subprocess.Popen([sys.executable, __file__, '--baseline-echo', kind], env=env)
    try:
        participant = DomainParticipant(domain_id())
        cls = dds_type(TYPES[kind].__msgtype__)
        sample = cls.deserialize(cdr.serialize(msg))
        qos = endpoint_qos(rclpy.QoSProfile(depth=10))
        writer = DataWriter(participant, Topic(participant, 'rt/ping', cls), qos=qos)
        reader = DataReader(participant, Topic(participant, 'rt/pong', cls), qos=qos)
        waitset = WaitSet(participant)
        waitset.attach(ReadCondition(reader, SampleState.Any | ViewState.Any | InstanceState.Any))
        deadline = time.monotonic() + 30
        while not (
            writer.get_publication_matched_status().current_count
            and reader.get_subscription_matched_status().current_count
        ):
            time.sleep(0.05)
            if time.monotonic() > deadline:
                raise SystemExit('bench_dds: the baseline echo did not appear within 30 s')
        times = []
        for i in range(count + 5):
            start = time.perf_counter()
            writer.write(sample)
            while not reader.take(N=1):
                if not waitset.wait(10 * 10**9):
                    raise SystemExit('bench_dds: a baseline round trip took over 10 s')
            if i >= 5:
                times.append(time.perf_counter() - start)
        return np.array(times)
    finally:
        child.terminate()
        child.wait(10)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--points', type=int, default=20_000)
    parser.add_argument('--count', type=int, default=300)
    parser.add_argument('--no-baseline', action='store_true')
    parser.add_argument('--echo', choices=TYPES, help=argparse.SUPPRESS)
    parser.add_argument('--baseline-echo', choices=TYPES, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.echo:
        return echo(args.echo)
    if args.baseline_echo:
        return baseline_echo(args.baseline_echo)
    domain = random.randint(1, 100)
    env = {**os.environ, **loopback_environment(domain)}
    baseline_env = {**env, 'ROS_DOMAIN_ID': str(domain + 100)}  # a domain of its own
    os.environ.update(env)
    messages = {'cloud': cloud(args.points), 'poses': poses()}
    print(
        'bench_dds: round trip between two processes over Cyclone DDS on loopback '
        f'(domain {env["ROS_DOMAIN_ID"]}, {args.count} round trips each)'
    )
    for kind, msg in messages.items():
        label = f'PointCloud2 {args.points} points' if kind == 'cloud' else 'PoseArray 2 poses'
        t = round_trips(kind, msg, args.count, env) * 1e3
        line = (
            f'  {label:28s} transport  p50 {np.percentile(t, 50):7.3f} ms  p99'
            f' {np.percentile(t, 99):7.3f} ms'
        )
        print(line, flush=True)
        if not args.no_baseline:
            os.environ.update(baseline_env)
            b = baseline_round_trips(kind, msg, max(20, args.count // 10), baseline_env) * 1e3
            os.environ.update(env)
            print(
                f'  {"":28s} baseline   p50 {np.percentile(b, 50):7.3f} ms  p99'
                f' {np.percentile(b, 99):7.3f} ms'
                f"  (Cyclone's element-by-element serialisation; p50 ratio "
                f'{np.percentile(b, 50) / np.percentile(t, 50):.1f}x)',
                flush=True,
            )
    print('goal: cloud p50 <= 1 ms on an idle machine')


if __name__ == '__main__':
    main()
