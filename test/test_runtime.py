"""The embedded runtime provides the rclpy subset the nodes use, with rclpy's semantics."""

from cloth_bench_ros.data.messages import deserialize
from cloth_bench_ros.runtime import embedded as rclpy
from cloth_bench_ros.runtime.embedded import (
    DurabilityPolicy,
    InvalidParameterTypeException,
    Node,
    Parameter,
    ParameterNotDeclaredException,
    QoSProfile,
    SingleThreadedExecutor,
    Time,
)
from cloth_bench_ros.runtime.messages import Clock, Header, Pose, PoseArray, String
import pytest


@pytest.fixture
def context():
    ctx = rclpy.Context()
    yield ctx
    ctx.shutdown()


def test_parameters_from_ros_args_and_params_file(tmp_path, context):
    params = tmp_path / 'p.yaml'
    params.write_text(
        '/**:\n  ros__parameters:\n    rate_hz: 10.0\n    engines: [mujoco, bullet]\n'
        '/ns/other:\n  ros__parameters:\n    rate_hz: 1.0\n'
    )
    rclpy.init(
        args=[
            'prog',
            '--ros-args',
            '--params-file',
            str(params),
            '-p',
            'seed:=3',
            '-r',
            '__ns:=/ns',
        ],
        context=context,
    )
    node = Node('sim', context=context)
    assert node.get_namespace() == '/ns'
    assert node.declare_parameter('rate_hz', 100.0).value == 10.0
    assert node.declare_parameter('engines', ['x']).value == ['mujoco', 'bullet']
    assert node.declare_parameter('seed', 0).value == 3
    assert node.declare_parameter('untouched', 'd').value == 'd'
    with pytest.raises(ParameterNotDeclaredException):
        node.get_parameter('missing')


def test_override_of_the_wrong_type_is_refused(context):
    """As rclpy: a string for a double, and an integer for a double, raise."""
    rclpy.init(args=[], context=context)
    node = Node(
        'n',
        context=context,
        parameter_overrides=[Parameter('rate_hz', value='fast'), Parameter('count', value=2)],
    )
    with pytest.raises(InvalidParameterTypeException, match='rate_hz'):
        node.declare_parameter('rate_hz', 100.0)
    with pytest.raises(InvalidParameterTypeException, match='count'):
        node.declare_parameter('count', 1.0)


def test_relative_absolute_and_private_names(context):
    rclpy.init(args=[], context=context)
    node = Node('n', namespace='cloth_bench', context=context)
    assert node.resolve_topic_name('targets') == '/cloth_bench/targets'
    assert node.resolve_topic_name('/clock') == '/clock'
    assert node.resolve_topic_name('~/debug') == '/cloth_bench/n/debug'


def test_messages_are_delivered_in_publish_order_across_nodes(context):
    rclpy.init(args=[], context=context)
    a, b = Node('a', context=context), Node('b', context=context)
    seen = []
    pub_x = a.create_publisher(String, 'x', 10)
    pub_y = a.create_publisher(String, 'y', 10)
    b.create_subscription(String, 'x', lambda m: seen.append(('x', m.data)), 10)
    b.create_subscription(
        String,
        'y',
        lambda m: (seen.append(('y', m.data)), pub_x.publish(String(data='from-y'))),
        10,
    )
    for i in range(3):
        pub_x.publish(String(data=str(i)))
        pub_y.publish(String(data=str(i)))
    ex = SingleThreadedExecutor(context=context)
    ex.add_node(a)
    ex.add_node(b)
    ex.spin_until_idle()
    assert seen == [
        ('x', '0'),
        ('y', '0'),
        ('x', '1'),
        ('y', '1'),
        ('x', '2'),
        ('y', '2'),
        ('x', 'from-y'),
        ('x', 'from-y'),
        ('x', 'from-y'),
    ]


def test_transient_local_reaches_late_subscribers_and_volatile_does_not(context):
    rclpy.init(args=[], context=context)
    node = Node('n', context=context)
    latched = node.create_publisher(
        String, 'latched', QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    )
    volatile = node.create_publisher(String, 'volatile', 10)
    latched.publish(String(data='old'))
    latched.publish(String(data='last'))
    volatile.publish(String(data='gone'))
    got = []
    node.create_subscription(
        String,
        'latched',
        lambda m: got.append(m.data),
        QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL),
    )
    node.create_subscription(String, 'volatile', lambda m: got.append(m.data), 10)
    ex = SingleThreadedExecutor(context=context)
    ex.add_node(node)
    ex.spin_until_idle()
    assert got == ['last']


def test_use_sim_time_follows_clock(context):
    rclpy.init(args=[], context=context)
    owner = Node('owner', context=context)
    follower = Node(
        'follower', context=context, parameter_overrides=[Parameter('use_sim_time', value=True)]
    )
    clock = owner.create_publisher(Clock, '/clock', 10)
    clock.publish(Clock(clock=Time(nanoseconds=3_250_000_000).to_msg()))
    ex = SingleThreadedExecutor(context=context)
    ex.add_node(owner)
    ex.add_node(follower)
    ex.spin_until_idle()
    assert follower.get_clock().now().nanoseconds == 3_250_000_000
    assert owner.get_clock().now().nanoseconds > 1e18  # wall time


def test_timer_fires_on_the_steady_clock_until_cancelled(context):
    rclpy.init(args=[], context=context)
    node = Node('n', context=context)
    ticks = []

    def tick():
        ticks.append(1)
        if len(ticks) == 3:
            timer.cancel()

    timer = node.create_timer(0.001, tick)
    ex = SingleThreadedExecutor(context=context)
    ex.add_node(node)
    ex.spin_until_idle()
    assert len(ticks) == 3


def test_default_constructed_messages_serialise_like_rosbags():
    msg = PoseArray()
    msg.header.frame_id = 'world'
    msg.poses.append(Pose())
    msg.poses[0].position.z = 1.5
    back = deserialize(rclpy.serialize_message(msg), 'geometry_msgs/msg/PoseArray')
    assert back.header.frame_id == 'world' and back.poses[0].position.z == 1.5
    assert Header().stamp.sec == 0


def test_node_needs_init():
    ctx = rclpy.Context()
    with pytest.raises(RuntimeError):
        Node('n', context=ctx)
