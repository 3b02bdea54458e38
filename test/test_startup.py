"""
Start-up by who is in the graph, not by counting; the end of a run whatever the arrival order.

Both rules are checked on the intra-process transport and on real Cyclone DDS (loopback, from the
session fixture), with the real trajectory publisher, recorder and evaluator; the other graph
members are plain nodes with the simulator's and evaluator's topics.
"""

from __future__ import annotations

import time

from cloth_bench_ros.core.pointcloud2 import create_cloud_xyz32
from cloth_bench_ros.core.trajectory import full_targets
from cloth_bench_ros.nodes.common import node_keys
from cloth_bench_ros.nodes.evaluator import Evaluator
from cloth_bench_ros.nodes.recorder import Recorder
from cloth_bench_ros.nodes.trajectory_publisher import TrajectoryPublisher
from cloth_bench_ros.runtime import embedded as rclpy
from cloth_bench_ros.runtime import make_qos
from cloth_bench_ros.runtime import messages as M
from cloth_bench_ros.runtime.topic_endpoint_info import (
    TopicEndpointInfo,
    TopicEndpointTypeEnum,
    UNKNOWN_NODE,
)
import numpy as np
import pytest

NS = 'cloth_bench'


@pytest.fixture(params=['intra', 'dds'])
def context(request):
    ctx = rclpy.Context()
    rclpy.init(args=[], context=ctx, transport=request.param)
    yield ctx
    rclpy.shutdown(context=ctx)


def _spin(executor, seconds: float, until=lambda: False) -> None:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and not until():
        executor.spin_once(timeout_sec=0.02)


def _member(context, executor, name: str, subscribes=(), publishes=()) -> rclpy.Node:
    node = rclpy.Node(name, namespace=NS, context=context)
    for topic, msg_type in subscribes:
        node.create_subscription(msg_type, topic, lambda msg: None, make_qos(10))
    node.pubs = {
        topic: node.create_publisher(msg_type, topic, make_qos(10))
        for topic, msg_type in publishes
    }
    executor.add_node(node)
    return node


def test_lockstep_starts_when_every_named_simulator_is_there_not_when_enough_subscribers_are(
    context,
):
    executor = rclpy.SingleThreadedExecutor(context=context)
    tp = TrajectoryPublisher(
        context=context,
        parameter_overrides=[
            rclpy.Parameter('engines', value=['mujoco', 'bullet']),
            rclpy.Parameter('rate_hz', value=10.0),
        ],
    )
    executor.add_node(tp)
    _member(
        context,
        executor,
        'evaluator',
        [('targets', M.PoseArray)],
        [('metrics', M.DiagnosticArray)],
    )
    _member(context, executor, 'recorder', [('/clock', M.Clock)], [('real/cloud', M.PointCloud2)])
    _member(
        context,
        executor,
        'simulator_mujoco',
        [('targets', M.PoseArray)],
        [('mujoco/cloud', M.PointCloud2)],
    )
    # three `targets` subscriptions for two engines, and a bullet cloud from a node that gets no
    # targets
    _member(context, executor, 'bullet_replayer', [], [('bullet/cloud', M.PointCloud2)])
    _spin(executor, 1.5)
    assert tp.k == -1 and not tp.graph_ready()
    _member(
        context,
        executor,
        'simulator_bullet',
        [('targets', M.PoseArray)],
        [('bullet/cloud', M.PointCloud2)],
    )
    _spin(executor, 20.0, until=lambda: tp.k == 0)
    assert tp.k == 0  # target 0 is out; the next waits for both engines' state 0


def test_endpoints_of_nodes_not_known_yet_never_make_a_node_that_has_both():
    """
    An endpoint whose graph message has not come is `_NODE_NAME_UNKNOWN_` (rmw_dds_common).

    A `targets` reader and a `mujoco/cloud` writer both unknown may belong to two different
    nodes (or to a real node and a stranger): they must not count as one simulator.
    """
    kinds = TopicEndpointTypeEnum

    def unknown(kind, topic_type):
        return TopicEndpointInfo(*UNKNOWN_NODE, topic_type, kind)

    readers = [unknown(kinds.SUBSCRIPTION, 'geometry_msgs/msg/PoseArray')]
    writers = [
        unknown(kinds.PUBLISHER, 'sensor_msgs/msg/PointCloud2'),
        TopicEndpointInfo('simulator_mujoco', '/cloth_bench', 'sensor_msgs/msg/PointCloud2', 1),
    ]
    assert node_keys(readers) & node_keys(writers) == set()
    assert node_keys(writers) == {('/cloth_bench', 'simulator_mujoco')}


def _cloud(stamp_ns: int, points: np.ndarray):
    header = M.Header(stamp=rclpy.Time(nanoseconds=stamp_ns).to_msg(), frame_id='world')
    return create_cloud_xyz32(header, points, M.PointCloud2, M.PointField)


def _step(stamp_ns: int, step: int):
    values = [
        M.KeyValue(key='step', value=str(step)),
        M.KeyValue(key='step_time', value='0.001'),
        M.KeyValue(key='diverged', value='false'),
        M.KeyValue(key='diverged_at_step', value=''),
    ]
    return M.DiagnosticArray(
        header=M.Header(stamp=rclpy.Time(nanoseconds=stamp_ns).to_msg()),
        status=[M.DiagnosticStatus(name='cloth_bench/mujoco', values=values)],
    )


def test_the_evaluator_ends_only_with_every_announced_frame_and_the_last_state(
    context, hanging_bag
):
    executor = rclpy.SingleThreadedExecutor(context=context)
    rate = {'rate_hz': 10.0, 'use_sim_time': True}
    evaluator = Evaluator(
        context=context,
        parameter_overrides=[
            rclpy.Parameter(k, value=v) for k, v in {**rate, 'engines': ['mujoco']}.items()
        ],
    )
    recorder = Recorder(
        context=context,
        parameter_overrides=[
            rclpy.Parameter('bag', value=str(hanging_bag)),
            rclpy.Parameter('use_sim_time', value=True),
        ],
    )
    feeder = _member(
        context,
        executor,
        'feeder',
        [],
        [('mujoco/cloud', M.PointCloud2), ('mujoco/step_time', M.DiagnosticArray)],
    )
    for node in (evaluator, recorder):
        executor.add_node(node)
    _spin(
        executor, 20.0, until=lambda: evaluator.metrics_pub is not None
    )  # ready: inputs matched, trial in
    assert (
        evaluator.expected_real is not None and len(evaluator.expected_real) == 132
    )  # 4.4 s at 30 fps
    targets = full_targets('dynamic', 10.0)
    final = targets.stamp_ns(len(targets) - 1)
    vertices = np.zeros((4, 3))
    # the last state and step first (DDS keeps no order across topics), then the real frames
    feeder.pubs['mujoco/cloud'].publish(_cloud(final, vertices))
    feeder.pubs['mujoco/step_time'].publish(_step(final, len(targets) - 1))
    _spin(executor, 1.0)
    assert not evaluator.done
    stamps = sorted(evaluator.expected_real)
    points = np.random.default_rng(0).normal(size=(10, 3))
    for stamp in stamps[:-1]:
        recorder.cloud_pub.publish(_cloud(stamp, points))
    _spin(executor, 2.0, until=lambda: len(evaluator.received_real) == len(stamps) - 1)
    assert not evaluator.done
    recorder.cloud_pub.publish(_cloud(stamps[-1], points))
    _spin(executor, 20.0, until=lambda: evaluator.done)
    assert evaluator.done and evaluator.summary['real']['frames'] == 132
