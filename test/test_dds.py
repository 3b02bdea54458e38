"""
The DDS transport over real Cyclone DDS, confined to loopback on a random domain per test.

Interface lo, no multicast, peer 127.0.0.1, so parallel runs do not hear each other.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time

from cloth_bench_ros.core.pointcloud2 import create_cloud_xyz32, read_xyz
from cloth_bench_ros.runtime import embedded as rclpy
from cloth_bench_ros.runtime import messages as M
from cloth_bench_ros.runtime.dds import loopback_environment
from cloth_bench_ros.runtime.dds.domain import domain_config
from cloth_bench_ros.runtime.dds.transport import dds_topic_name
from dds_domains import random_domain
import numpy as np
import pytest


@pytest.fixture
def dds_env(monkeypatch) -> dict[str, str]:
    """Loopback-only Cyclone on a random ROS domain; the environment for child processes too."""
    entries = loopback_environment(random_domain())
    for key, value in entries.items():
        monkeypatch.setenv(key, value)
    monkeypatch.delenv('ROS_AUTOMATIC_DISCOVERY_RANGE', raising=False)
    monkeypatch.delenv('ROS_STATIC_PEERS', raising=False)
    return {**os.environ, **entries}


def spin_until(executor, condition, timeout: float = 20.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, 'timed out'
        executor.spin_once(timeout_sec=0.05)


ECHO_NODE = """
import signal
from cloth_bench_ros.runtime import embedded as rclpy, messages as M
stop = []
signal.signal(signal.SIGTERM, lambda *_: stop.append(True))
rclpy.init(args=[], transport="dds")
node = rclpy.Node("echo", namespace="/dds_test")
pub = node.create_publisher(M.PointCloud2, "pong", 10)
node.create_subscription(M.PointCloud2, "ping", pub.publish, 10)
executor = rclpy.SingleThreadedExecutor()
executor.add_node(node)
while not stop:
    executor.spin_once(timeout_sec=0.1)
node.destroy_node()
rclpy.shutdown()  # the participant leaves: the others see its nodes go at once
"""


def test_loopback_configuration_from_the_ros_environment(dds_env):
    config = domain_config()
    assert '<AllowMulticast>false</AllowMulticast>' in config
    assert (
        '<Peer address="localhost"/>' in config
        and '<NetworkInterface name="lo"/>' in dds_env['CYCLONEDDS_URI']
    )
    assert (
        '<NetworkInterface name="lo"/>' in config.split(',')[0]
        or 'NetworkInterface' in dds_env['CYCLONEDDS_URI']
    )
    assert dds_topic_name('/cloth_bench/targets') == 'rt/cloth_bench/targets'


def test_two_processes_exchange_a_cloud_and_see_each_others_nodes(dds_env):
    child = subprocess.Popen([sys.executable, '-c', ECHO_NODE], env=dds_env)
    context = rclpy.Context()
    rclpy.init(args=[], context=context, transport='dds')
    try:
        node = rclpy.Node('pinger', namespace='/dds_test', context=context)
        received = []
        pub = node.create_publisher(M.PointCloud2, 'ping', 10)
        node.create_subscription(M.PointCloud2, 'pong', received.append, 10)
        executor = rclpy.SingleThreadedExecutor(context=context)
        executor.add_node(node)
        # started when the echo node's endpoints are in the graph and matched with ours
        spin_until(
            executor,
            lambda: (
                any(i.node_name == 'echo' for i in node.get_subscriptions_info_by_topic('ping'))
                and pub.get_subscription_count() == 1
                and node.count_publishers('pong') == 1
            ),
        )
        owners = {
            (i.node_name, i.node_namespace, i.topic_type)
            for i in node.get_publishers_info_by_topic('pong')
        }
        assert owners == {('echo', '/dds_test', 'sensor_msgs/msg/PointCloud2')}
        assert ('echo', '/dds_test') in node.get_node_names_and_namespaces()
        points = np.random.default_rng(0).normal(size=(20_000, 3)).astype(np.float32)
        header = M.Header(stamp=M.Time(sec=3, nanosec=7), frame_id='world')
        pub.publish(create_cloud_xyz32(header, points, M.PointCloud2, M.PointField))
        spin_until(executor, lambda: received)
        assert (received[0].header.stamp.sec, received[0].header.stamp.nanosec) == (3, 7)
        np.testing.assert_array_equal(read_xyz(received[0]), points)
    finally:
        rclpy.shutdown(context=context)
        child.terminate()
        child.wait(10)


def test_nodes_of_a_process_that_ends_leave_the_graph(dds_env):
    child = subprocess.Popen([sys.executable, '-c', ECHO_NODE], env=dds_env)
    context = rclpy.Context()
    rclpy.init(args=[], context=context, transport='dds')
    try:
        node = rclpy.Node('watcher', namespace='/dds_test', context=context)
        executor = rclpy.SingleThreadedExecutor(context=context)
        executor.add_node(node)
        spin_until(executor, lambda: ('echo', '/dds_test') in node.get_node_names_and_namespaces())
        child.terminate()  # SIGTERM: the node process shuts down cleanly
        child.wait(10)
        spin_until(
            executor,
            lambda: (
                ('echo', '/dds_test') not in node.get_node_names_and_namespaces()
                and not node.get_publishers_info_by_topic('pong')
            ),
        )
        assert node.get_node_names_and_namespaces() == [('watcher', '/dds_test')]
    finally:
        rclpy.shutdown(context=context)
        if child.poll() is None:
            child.kill()
