"""What every node's main() does: init, spin until done or interrupted, clean up, shut down."""

from __future__ import annotations

import signal
import sys
import threading
from typing import Callable, Sequence

from cloth_bench_ros.data.bag import BagError
from cloth_bench_ros.runtime import SingleThreadedExecutor, is_user_error, rclpy

NAMESPACE = "cloth_bench"


_stop_requested = threading.Event()


def _request_stop(signum, frame) -> None:
    # Only a flag: a callback is never cut in half, so what a node acknowledged it also finished.
    _stop_requested.set()


def close_nodes(nodes: Sequence) -> None:
    """Each node's close() (engines freed, recordings finalised), then destroy_node()."""
    for node in nodes:
        close = getattr(node, "close", None)
        if close:
            close()
        node.destroy_node()


def run_nodes(factories: Sequence[Callable[[], object]], args: list[str] | None = None) -> int:
    """Spin nodes in one executor until all are `done`, SIGINT/SIGTERM or shutdown.

    SIGINT and SIGTERM stop the loop between callbacks (rclpy's own handler, where installed, is
    replaced for the node's lifetime). Each node's close() runs on every way out (a recorder
    finalises its bag there). A user error
    (bad parameter, bag or engine) is one line on stderr and exit status 2, no traceback.
    """
    _stop_requested.clear()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _request_stop)
    nodes: list = []
    try:
        rclpy.init(args=args if args is not None else sys.argv)  # a bad --ros-args fails here
        for factory in factories:
            nodes.append(factory())
        executor = SingleThreadedExecutor()
        for node in nodes:
            executor.add_node(node)
        while rclpy.ok() and not _stop_requested.is_set() and not all(getattr(n, "done", False) for n in nodes):
            executor.spin_once(timeout_sec=0.1)
        return 0
    except Exception as exc:
        # rclpy's parameter, name and argument errors are not ValueErrors: matched by class name
        if not (isinstance(exc, (ValueError, BagError)) or is_user_error(exc)):
            raise
        print(f"error: {str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__}",
              file=sys.stderr)
        return 2
    finally:
        close_nodes(nodes)
        if rclpy.ok():
            rclpy.shutdown()


def run_node(factory: Callable[[], object], args: list[str] | None = None) -> int:
    """run_nodes for a single node: what `ros2 run cloth_bench_ros <node>` executes."""
    return run_nodes([factory], args)
