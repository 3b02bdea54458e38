"""rclpy.context for the embedded runtime: one graph, its transport, queue and arguments."""

from __future__ import annotations

from collections import deque
from typing import Any

from cloth_bench_ros.errors import InputError
from cloth_bench_ros.runtime.arguments import parse_ros_args, RosArguments
from cloth_bench_ros.runtime.parameter_errors import RCLError
from cloth_bench_ros.runtime.qos import HistoryPolicy
from cloth_bench_ros.runtime.rosout import PROCESS_LOG_LEVELS
from cloth_bench_ros.runtime.transport import IntraProcessTransport, transport_choice, TRANSPORTS


def make_transport(context: 'Context', name: str, domain_id: int | None = None) -> Any:
    """Return the transport `name` ('intra' or 'dds'); DDS loads Cyclone only when chosen."""
    if name == 'dds':
        from cloth_bench_ros.runtime.dds.transport import DdsTransport  # lazy: Cyclone, +0.19 s

        return DdsTransport(context, domain_id)
    if name not in TRANSPORTS:
        raise InputError(f'unknown transport {name!r} (valid: intra, dds)')
    return IntraProcessTransport(context)


class Context:
    """One graph: its transport (intra-process or DDS), delivery queue and shutdown flag."""

    def __init__(self) -> None:
        self.args = RosArguments()
        self._ok = False
        # Publishers, subscriptions and nodes of runtime/node.py (which imports this module).
        self.subscriptions: dict[str, list[Any]] = {}
        self.publishers: dict[str, list[Any]] = {}
        self.services: dict[str, list[Any]] = {}  # services and clients of runtime/services.py
        self.clients: dict[str, list[Any]] = {}
        self.queue: deque[tuple[Any, Any]] = deque()
        self.nodes: list[Any] = []
        self.transport: Any = IntraProcessTransport(self)
        self.topic_types: dict[str, tuple[str, int]] = {}  # topic -> (type, endpoints using it)

    def init(
        self,
        args: list[str] | None = None,
        *,
        domain_id: int | None = None,
        transport: str | None = None,
    ) -> None:
        """Parse the ROS arguments and open the transport (default: CLOTH_BENCH_TRANSPORT)."""
        self.args = parse_ros_args(args)
        # `--log-level unset` leaves the process's default severity as it was (as rcl does)
        PROCESS_LOG_LEVELS.update({k: v for k, v in self.args.log_levels.items() if k or v})
        self.transport = make_transport(self, transport or transport_choice('intra'), domain_id)
        self._ok = True

    def ok(self) -> bool:
        return self._ok

    def claim_topic(self, topic: str, msg_type: Any, kind: str) -> None:
        """Count an endpoint on `topic`; a second type is refused, as rmw refuses it."""
        typename = msg_type.__msgtype__
        known, count = self.topic_types.get(topic, (typename, 0))
        if known != typename:
            raise RCLError(
                f'Failed to create {kind}: create_{kind}() called for existing topic name '
                f'{topic} with incompatible type {typename} (the topic has {known})'
            )
        self.topic_types[topic] = (typename, count + 1)

    def release_topic(self, topic: str) -> None:
        typename, count = self.topic_types.get(topic, ('', 1))
        if count > 1:
            self.topic_types[topic] = (typename, count - 1)
        else:
            self.topic_types.pop(topic, None)

    def enqueue(self, sub: Any, msg: Any) -> None:
        """Queue a message for `sub`; a keep-last reader keeps only its newest `depth` ones."""
        if sub.qos.history == HistoryPolicy.KEEP_LAST and sub._queued >= max(1, sub.qos.depth):
            sub._dropped += 1  # the oldest one still queued for it is skipped when reached
        else:
            sub._queued += 1
        self.queue.append((sub, msg))

    def shutdown(self) -> None:
        self._ok = False
        self.queue.clear()
        self.topic_types.clear()
        self.transport.shutdown()
        self.transport = IntraProcessTransport(self)


default_context = Context()
