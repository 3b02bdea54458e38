"""MessagePool: a message is refilled only when nothing but the pool holds it or its parts."""

from __future__ import annotations

from cloth_bench_ros.nodes.message_pool import MessagePool
from cloth_bench_ros.nodes.simulator import StateMessages
from cloth_bench_ros.runtime import EMBEDDED, Node, PointCloud2, rclpy, SingleThreadedExecutor
import numpy as np
import pytest


def test_free_messages_are_reused_and_held_ones_never_refilled():
    pool = MessagePool(lambda: {'data': np.zeros(3)}, lambda m: (m, m['data']), size=2)
    first = pool.take()
    first['data'][:] = 1.0
    kept = first  # a subscriber keeps the message
    del first
    second = pool.take()
    assert second is not kept
    del second
    again = pool.take()  # slot 0 is still held: built anew, the kept one is untouched
    assert again is not kept and pool.built == 3 and kept['data'].tolist() == [1.0] * 3
    del again
    data_only = pool.take()['data']  # slot 1 was free: reused; keep only its array this time
    assert pool.built == 3
    pool.take()  # slot 0 (free again)
    assert pool.take()['data'] is not data_only and pool.built == 4  # its array is held


@pytest.mark.skipif(not EMBEDDED, reason='the intra-process transport is the embedded one')
def test_a_subscriber_keeping_every_state_sees_each_state_unchanged():
    context = rclpy.Context()
    rclpy.init(args=[], context=context, transport='intra')
    try:
        node = Node('keeper', context=context)
        kept = []
        node.create_subscription(PointCloud2, 'cloud', kept.append, 10)
        pub = node.create_publisher(PointCloud2, 'cloud', 10)
        messages = StateMessages('mujoco', 4, in_place=False)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        for step in range(12):
            cloud, _ = messages.fill(cloud_stamp(), np.full((4, 3), float(step)), step, 0.0,
                                     None, 0)
            pub.publish(cloud)
            if step % 3 == 2:  # the subscriber runs late: three states queued at once
                while context.queue:
                    executor.spin_once(0.0)
        xyz = [np.frombuffer(m.data, dtype=np.float32).reshape(4, 3) for m in kept]
        assert [float(x[0, 0]) for x in xyz] == [float(s) for s in range(12)]
        assert messages.pool.built == 4 + 8  # past the first four, every kept state is a new one
    finally:
        rclpy.shutdown(context=context)


def cloud_stamp():
    from cloth_bench_ros.runtime import Time

    return Time(nanoseconds=0).to_msg()
