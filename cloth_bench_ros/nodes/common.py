"""What every node's main() does: init, spin until the node is done or interrupted, shut down."""

from __future__ import annotations

import sys
from typing import Callable

from cloth_bench_ros.data.bag import BagError
from cloth_bench_ros.runtime import SingleThreadedExecutor, rclpy

NAMESPACE = "cloth_bench"


def run_node(factory: Callable[[], object], args: list[str] | None = None) -> int:
    """Spin one node until its `done` is set, SIGINT or shutdown; one clear line on a user error."""
    rclpy.init(args=args if args is not None else sys.argv)
    node = None
    try:
        node = factory()
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        while rclpy.ok() and not getattr(node, "done", False):
            executor.spin_once(timeout_sec=0.1)
        return 0
    except KeyboardInterrupt:
        return 0
    except (ValueError, BagError) as exc:  # a bad parameter, bag or engine: one line, no traceback
        print(f"error: {exc}", file=sys.stderr)
        return 2
    finally:
        if node is not None:
            close = getattr(node, "close", None)
            if close:
                close()
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
