"""What every node's main() does: init, spin until done or interrupted, clean up, shut down."""

from __future__ import annotations

import signal
import sys
import threading
from typing import Callable, Iterable, Sequence

from cloth_bench_ros import validation
from cloth_bench_ros.core.task_data import load_task, Task
from cloth_bench_ros.errors import InputError, is_user_error, one_line
from cloth_bench_ros.runtime import (
    declare_option,
    EMBEDDED,
    rclpy,
    SingleThreadedExecutor,
)
from cloth_bench_ros.runtime.topic_endpoint_info import UNKNOWN_NODE
from cloth_bench_ros.runtime.transport import transport_choice

NAMESPACE = 'cloth_bench'
# The recorder's announcement, beside the trial on real/trial: the run-time stamps of the frames it
# replays on /clock. DDS gives no order across topics, so the evaluator closes the run only once
# it holds every announced frame up to the last target, not at the last engine state.
REPLAY_STATUS_NAME = 'cloth_bench/recorder/replay'


def replay_stamps(msg) -> list[int] | None:
    """Return the stamps (ns) announced in a real/trial DiagnosticArray, or None."""
    for status in msg.status:
        if status.name == REPLAY_STATUS_NAME:
            text = {kv.key: kv.value for kv in status.values}.get('stamps_ns', '')
            return [int(s) for s in text.split(',') if s]
    return None


_stop_requested = threading.Event()


def publish_serialises(node) -> bool:
    """
    Return True when publish() serialises the message (rclpy, DDS).

    Such a message may be refilled right after; the embedded intra-process transport hands
    subscribers the object itself.
    """
    return not EMBEDDED or node.context.transport.name != 'intra'


def _request_stop(signum, frame) -> None:
    # Only a flag: a callback is never cut in half, so what a node acknowledged it also finished.
    _stop_requested.set()


def close_nodes(nodes: Sequence) -> None:
    """Each node's close() (engines freed, recordings finalised), then destroy_node()."""
    for node in nodes:
        close = getattr(node, 'close', None)
        if close:
            close()
        node.destroy_node()


def node_grid(node) -> tuple[int, int]:
    """
    Declare grid_nx and grid_nz and return them: (0, 0) keeps the engine's default, else 2+ each.

    The one grid check of every node (simulator, recorder, evaluator): each error names the node.
    """
    nx, nz = declare_option(node, 'grid_nx'), declare_option(node, 'grid_nz')
    for name, side in (('grid_nx', nx), ('grid_nz', nz)):
        if side == 1:
            raise InputError(
                f'{node.get_name()}: parameter {name}: 1 vertex per side is no cloth (0 keeps the '
                "engine's default, else >= 2)"
            )
    if (nx == 0) != (nz == 0):
        raise InputError(
            f'{node.get_name()}: parameters grid_nx and grid_nz: set both or neither '
            f'(got {nx} and {nz})'
        )
    return nx, nz


def node_cloth_size(node) -> tuple[float, float] | None:
    """Declare cloth_size and return it checked: (W, L), or None: the benchmark's 0.5 x 0.7 m."""
    return validation.parse_cloth_size(
        declare_option(node, 'cloth_size'), f'{node.get_name()}: parameter cloth_size'
    )


def node_cloth_mesh(node) -> str | None:
    """Declare cloth_mesh and return it: a mesh file, or None: the grid (core/cloth_mesh.py)."""
    return declare_option(node, 'cloth_mesh') or None


def node_task(node) -> Task:
    """Declare primitive and task and return the task: the file's, else the shipped one."""
    primitive = declare_option(node, 'primitive')
    try:
        return load_task(primitive, declare_option(node, 'task'))
    except InputError as exc:
        raise InputError(f'{node.get_name()}: {exc}') from None


def node_cloth(node) -> tuple[tuple[float, float] | None, float | None]:
    """
    Declare cloth_size and cloth_mass and return them checked: (W, L) or None, kg or None.

    None: the benchmark's 0.5 x 0.7 m cloth, the preset's mass (core/cloth_size.py).
    """
    return node_cloth_size(node), declare_option(node, 'cloth_mass')


def node_keys(infos: Iterable) -> set[tuple[str, str]]:
    """
    Return (namespace, name) of the nodes behind a get_*_info_by_topic answer.

    Endpoints whose node is not known yet (rmw's `_NODE_NAME_UNKNOWN_`) are left out: two of them
    may belong to different nodes, so they never prove that one node has both.
    """
    return {
        (info.node_namespace, info.node_name)
        for info in infos
        if (info.node_name, info.node_namespace) != UNKNOWN_NODE
    }


def publishers_matched(node, subscription) -> int:
    """Return publishers matched with a subscription (rclpy >= Iron), else those in the graph."""
    count = getattr(subscription, 'get_publisher_count', None)
    return count() if count is not None else node.count_publishers(subscription.topic_name)


def all_subscriptions_matched(node, publisher) -> bool:
    """
    Return True once the publisher has matched every subscription of its topic in the graph.

    Under DDS, discovery is asynchronous and pairwise: a reader another node has created is in the
    graph before this publisher's writer has matched it, and a reliable volatile writer delivers
    only to matched readers. Both counts include this node's own subscriptions.
    """
    listed = len(node.get_subscriptions_info_by_topic(publisher.topic_name))
    return listed > 0 and publisher.get_subscription_count() >= listed


def run_nodes(
    factories: Sequence[Callable[[], object]],
    args: list[str] | None = None,
    transport: str | None = None,
) -> int:
    """
    Spin nodes in one executor until all are `done`, SIGINT/SIGTERM or shutdown.

    In the embedded runtime the nodes talk over `transport` (default: CLOTH_BENCH_TRANSPORT, else
    intra: nodes composed in one process, as in a component container).

    SIGINT and SIGTERM stop the loop between callbacks (rclpy's own handler, where installed, is
    replaced for the node's lifetime). Each node's close() runs on every way out (a recorder
    finalises its bag there). A user error
    (bad parameter, bag or engine) is one line on stderr and exit status 2, no traceback.
    """
    _stop_requested.clear()
    nodes: list = []
    executor = None
    starting = True
    try:
        # a bad --ros-args (or CLOTH_BENCH_TRANSPORT) fails here; real rclpy installs no signal
        # handler of its own (it would end spin_once in ExternalShutdownException), ours stops the
        # loop
        init_options = (
            {'transport': transport or transport_choice('intra')}
            if EMBEDDED
            else {'signal_handler_options': _no_rclpy_signal_handlers()}
        )
        rclpy.init(args=args if args is not None else sys.argv, **init_options)
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, _request_stop)
        for factory in factories:
            nodes.append(factory())
        executor = SingleThreadedExecutor()
        for node in nodes:
            executor.add_node(node)
        starting = False
        while (
            rclpy.ok()
            and not _stop_requested.is_set()
            and not all(getattr(n, 'done', False) for n in nodes)
        ):
            executor.spin_once(timeout_sec=0.1)
        return max((getattr(n, 'exit_status', 0) for n in nodes), default=0)
    except Exception as exc:
        if (
            type(exc).__name__ == 'ExternalShutdownException'
        ):  # rclpy shut down from outside: a stop
            return 0
        # The project's errors and rclpy's parameter, name and argument errors are bad input;
        # rcl's own RCLError while starting is a bad argument, parameter or params file too.
        # Anything else is a bug: its traceback goes out as Python prints it.
        if not (is_user_error(exc) or (starting and type(exc).__name__ == 'RCLError')):
            raise
        print(f'error: {one_line(exc)}', file=sys.stderr)
        return 2
    finally:
        if executor is not None:
            executor.shutdown()
        close_nodes(nodes)
        if rclpy.ok():
            rclpy.shutdown()


def _no_rclpy_signal_handlers():
    """Rclpy's SignalHandlerOptions.NO (real rclpy only)."""
    from rclpy.signals import SignalHandlerOptions  # lazy: real rclpy only (optional)

    return SignalHandlerOptions.NO


def run_node(factory: Callable[[], object], args: list[str] | None = None) -> int:
    """
    run_nodes for a single node: what `ros2 run cloth_bench_ros <node>` executes.

    In the embedded runtime it talks DDS unless CLOTH_BENCH_TRANSPORT=intra, so that console
    scripts in separate processes make one graph, as under `ros2 run`.
    """
    status = run_nodes([factory], args, transport_choice('dds') if EMBEDDED else None)
    if args is None and threading.current_thread() is threading.main_thread():
        # The process's own node has ended. Python puts its stop signals back to the default
        # while it finalises, so a launcher's SIGINT arriving then would kill the process with
        # status 130 after a clean run; there is nothing left to stop.
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, signal.SIG_IGN)
    return status
