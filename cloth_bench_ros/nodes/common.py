"""What every node's main() does: init, spin until done or interrupted, clean up, shut down."""

from __future__ import annotations

import signal
import sys
from typing import Callable, Sequence

from cloth_bench_ros.data.bag import BagError
from cloth_bench_ros.runtime import SingleThreadedExecutor, rclpy

NAMESPACE = "cloth_bench"


def _interrupt(signum, frame) -> None:
    raise KeyboardInterrupt  # SIGTERM ends the node as SIGINT does: through the finally below


def run_nodes(factories: Sequence[Callable[[], object]], args: list[str] | None = None) -> int:
    """Spin nodes in one executor until all are `done`, SIGINT/SIGTERM or shutdown.

    Each node's close() runs on every way out (a recorder finalises its bag there). A user error
    (bad parameter, bag or engine) is one line on stderr and exit status 2, no traceback.
    """
    signal.signal(signal.SIGTERM, _interrupt)
    rclpy.init(args=args if args is not None else sys.argv)
    nodes: list = []
    try:
        for factory in factories:
            nodes.append(factory())
        executor = SingleThreadedExecutor()
        for node in nodes:
            executor.add_node(node)
        while rclpy.ok() and not all(getattr(n, "done", False) for n in nodes):
            executor.spin_once(timeout_sec=0.1)
        return 0
    except KeyboardInterrupt:
        return 0
    except (ValueError, BagError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    finally:
        for node in nodes:
            close = getattr(node, "close", None)
            if close:
                close()
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()


def run_node(factory: Callable[[], object], args: list[str] | None = None) -> int:
    """run_nodes for a single node: what `ros2 run cloth_bench_ros <node>` executes."""
    return run_nodes([factory], args)
