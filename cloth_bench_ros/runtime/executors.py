"""rclpy.executors for the embedded runtime: one thread, callbacks in publish order."""

from __future__ import annotations

import time

from cloth_bench_ros.runtime.clock import Timer
from cloth_bench_ros.runtime.context import Context, default_context
from cloth_bench_ros.runtime.node import Node
from cloth_bench_ros.runtime.services import Future


class SingleThreadedExecutor:
    """Runs queued message callbacks in publish order, then due timers of its nodes."""

    def __init__(self, context: Context | None = None) -> None:
        self.context = context or default_context
        self.nodes: list[Node] = []

    def add_node(self, node: Node) -> bool:
        if node not in self.nodes:
            self.nodes.append(node)
        return True

    def remove_node(self, node: Node) -> None:
        if node in self.nodes:
            self.nodes.remove(node)

    def _armed_timers(self) -> list[Timer]:
        return [t for n in self.nodes for t in n._timers if not t.cancelled]

    def _deliver_one(self) -> bool:
        self.context.transport.receive()
        queue = self.context.queue
        for _ in range(len(queue)):
            sub, msg = queue.popleft()
            if sub.node in self.nodes:
                if sub._dropped:  # pushed out by newer ones (keep-last depth)
                    sub._dropped -= 1
                    continue
                sub._queued -= 1
                sub.handle(msg)
                return True
            if sub.node in self.context.nodes:
                queue.append((sub, msg))  # for a node of another executor
        return False

    def spin_once(self, timeout_sec: float | None = None) -> None:
        """Run one ready callback, waiting up to timeout_sec for a timer if none is ready."""
        if not self.context.ok() or self._deliver_one():
            return
        timers = self._armed_timers()
        ready = next((t for t in timers if t.is_ready()), None)
        if ready is None:
            # Timers on a sim clock become due only through /clock: no point sleeping for them.
            waits = [t.time_until_next_call() for t in timers if t.follows_wall_time]
            # The transport waits: a sleep in one process, a DDS wait set that a sample ends early.
            transport = self.context.transport
            if not waits:
                if timeout_sec:
                    transport.wait(
                        timeout_sec if transport.name == 'dds' else min(timeout_sec, 0.01)
                    )
                return
            wait = min(w for w in waits if w is not None) / 1e9
            if timeout_sec is not None and wait > timeout_sec:
                transport.wait(timeout_sec)
                return
            if transport.wait(max(wait, 0.0)):
                return  # a message came first: delivered on the next spin_once
            ready = next((t for t in timers if t.is_ready()), None)
        if ready is not None:
            ready.call()

    def spin(self) -> None:
        while self.context.ok():
            self.spin_once(0.1)

    def spin_until_idle(self) -> None:
        """Spin until no message is queued and no timer is armed (the run is complete)."""
        while self.context.ok() and (
            self.context.queue or any(t.follows_wall_time for t in self._armed_timers())
        ):
            self.spin_once(0.1)

    def spin_until_future_complete(self, future: Future, timeout_sec: float | None = None) -> None:
        """Spin until the future is done, or timeout_sec passed (None: no limit)."""
        end = None if timeout_sec is None else time.monotonic() + timeout_sec
        while self.context.ok() and not future.done():
            if end is not None and time.monotonic() >= end:
                return
            self.spin_once(0.01 if end is None else max(0.0, min(0.01, end - time.monotonic())))

    def shutdown(self, timeout_sec: float | None = None) -> bool:
        self.nodes.clear()
        return True


def spin_once(
    node: Node, *, executor: SingleThreadedExecutor | None = None, timeout_sec: float | None = None
) -> None:
    ex = executor or SingleThreadedExecutor(node.context)
    ex.add_node(node)
    ex.spin_once(timeout_sec)


def spin_until_future_complete(
    node: Node,
    future: Future,
    executor: SingleThreadedExecutor | None = None,
    timeout_sec: float | None = None,
) -> None:
    ex = executor or SingleThreadedExecutor(node.context)
    ex.add_node(node)
    ex.spin_until_future_complete(future, timeout_sec)


def spin(node: Node, executor: SingleThreadedExecutor | None = None) -> None:
    ex = executor or SingleThreadedExecutor(node.context)
    ex.add_node(node)
    ex.spin()
