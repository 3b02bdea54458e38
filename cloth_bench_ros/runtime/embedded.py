"""An embedded, single-process stand-in for the subset of rclpy that the nodes use.

It composes nodes in one process as a component container with intra-process communication
would, and runs their callbacks deterministically: messages are delivered in the order they were
published (one FIFO for the whole context), timers fire on the steady clock, and a node with
use_sim_time follows /clock. What it provides (and nothing more):

- rclpy.init(args), ok(), shutdown(), spin(node), spin_once(node, timeout_sec)
- rclpy.node.Node(name, namespace=, parameter_overrides=, context=): create_publisher,
  create_subscription, create_timer, destroy_timer, declare_parameter, get_parameter,
  has_parameter, get_logger, get_clock, get_name, get_namespace, count_subscribers,
  count_publishers, destroy_node
- Publisher.publish / get_subscription_count; Timer.cancel; Clock.now(); Time(nanoseconds=),
  Time.from_msg, .to_msg(), .nanoseconds
- rclpy.qos: QoSProfile(depth=, reliability=, durability=, history=) and the policy enums;
  TRANSIENT_LOCAL publishers hand their last `depth` messages to late subscribers
- rclpy.executors.SingleThreadedExecutor: add_node, remove_node, spin, spin_once, shutdown,
  and spin_until_idle() (returns once no message is queued and no timer is armed)
- rclpy.serialization.serialize_message / deserialize_message (CDR through rosbags)
- command-line parameters: --ros-args -p name:=value, --params-file FILE, -r __ns:=/ns,
  -r __node:=name

Queues are unbounded (intra-process delivery loses nothing); QoS depth only bounds the
transient-local history.
"""

from __future__ import annotations

import enum
import fnmatch
import logging
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import yaml

from cloth_bench_ros.data import messages as cdr
from cloth_bench_ros.runtime import messages


# --- qos -------------------------------------------------------------------------------------


class ReliabilityPolicy(enum.IntEnum):
    SYSTEM_DEFAULT = 0
    RELIABLE = 1
    BEST_EFFORT = 2


class DurabilityPolicy(enum.IntEnum):
    SYSTEM_DEFAULT = 0
    TRANSIENT_LOCAL = 1
    VOLATILE = 2


class HistoryPolicy(enum.IntEnum):
    SYSTEM_DEFAULT = 0
    KEEP_LAST = 1
    KEEP_ALL = 2


@dataclass
class QoSProfile:
    depth: int = 10
    reliability: ReliabilityPolicy = ReliabilityPolicy.RELIABLE
    durability: DurabilityPolicy = DurabilityPolicy.VOLATILE
    history: HistoryPolicy = HistoryPolicy.KEEP_LAST


def _qos(qos: QoSProfile | int) -> QoSProfile:
    return QoSProfile(depth=qos) if isinstance(qos, int) else qos


# --- time ------------------------------------------------------------------------------------


class Time:
    """A point in ROS time, in integer nanoseconds."""

    def __init__(self, *, seconds: float = 0, nanoseconds: int = 0) -> None:
        self.nanoseconds = int(seconds * 1_000_000_000) + int(nanoseconds)

    @classmethod
    def from_msg(cls, msg: Any) -> "Time":
        return cls(nanoseconds=int(msg.sec) * 1_000_000_000 + int(msg.nanosec))

    def to_msg(self) -> Any:
        sec, nanosec = divmod(self.nanoseconds, 1_000_000_000)
        return messages.Time(sec=sec, nanosec=nanosec)

    def __repr__(self) -> str:
        return f"Time(nanoseconds={self.nanoseconds})"


class Clock:
    """ROS time of one node: the steady clock, or the last /clock message under use_sim_time."""

    def __init__(self) -> None:
        self.sim_time_ns: int | None = None

    def now(self) -> Time:
        if self.sim_time_ns is not None:
            return Time(nanoseconds=self.sim_time_ns)
        return Time(nanoseconds=time.time_ns())


# --- parameters ------------------------------------------------------------------------------


class Parameter:
    """A named parameter value, as rclpy.parameter.Parameter (value access only)."""

    def __init__(self, name: str, type_: Any = None, value: Any = None) -> None:
        self.name = name
        self.value = value

    def __repr__(self) -> str:
        return f"Parameter({self.name!r}, value={self.value!r})"


class ParameterError(ValueError):
    """A parameter that was not declared, or a value of the wrong type."""


def _coerce(name: str, default: Any, value: Any) -> Any:
    """Keep the declared type as rclpy does; an integer is accepted where a double is declared."""
    if default is None or value is None:
        return value
    if isinstance(default, bool) != isinstance(value, bool):
        raise ParameterError(f"parameter {name}: expected {type(default).__name__}, got {value!r}")
    if isinstance(default, float) and isinstance(value, int):
        return float(value)
    if isinstance(default, (int, float, str)) and not isinstance(value, type(default)):
        raise ParameterError(f"parameter {name}: expected {type(default).__name__}, got {value!r}")
    if isinstance(default, list) and not isinstance(value, list):
        raise ParameterError(f"parameter {name}: expected a list, got {value!r}")
    return value


# --- context ---------------------------------------------------------------------------------


@dataclass
class _Args:
    overrides: dict[str, dict[str, Any]]  # node pattern -> name -> value
    namespace: str | None = None
    node_name: str | None = None


def _parse_ros_args(args: list[str] | None) -> _Args:
    parsed = _Args({})
    if not args or "--ros-args" not in args:
        return parsed
    rest = args[args.index("--ros-args") + 1 :]
    i = 0
    while i < len(rest):
        flag = rest[i]
        if flag == "--":
            break
        if flag in ("-p", "--param") and i + 1 < len(rest):
            name, _, text = rest[i + 1].partition(":=")
            parsed.overrides.setdefault("/**", {})[name] = yaml.safe_load(text)
            i += 2
        elif flag == "--params-file" and i + 1 < len(rest):
            for pattern, params in load_params_file(rest[i + 1]).items():
                parsed.overrides.setdefault(pattern, {}).update(params)
            i += 2
        elif flag in ("-r", "--remap") and i + 1 < len(rest):
            key, _, value = rest[i + 1].partition(":=")
            if key == "__ns":
                parsed.namespace = value
            elif key == "__node":
                parsed.node_name = value
            i += 2
        else:
            i += 1
    return parsed


def load_params_file(path: str | Path) -> dict[str, dict[str, Any]]:
    """A ROS 2 parameter file: {node pattern: {name: value}} from the ros__parameters form."""
    with open(path) as f:
        doc = yaml.safe_load(f) or {}
    out: dict[str, dict[str, Any]] = {}
    for pattern, body in doc.items():
        params = (body or {}).get("ros__parameters", {})
        out[pattern] = _flatten(params)
    return out


def _flatten(params: dict, prefix: str = "") -> dict[str, Any]:
    flat: dict[str, Any] = {}
    for key, value in params.items():
        if isinstance(value, dict):
            flat.update(_flatten(value, f"{prefix}{key}."))
        else:
            flat[f"{prefix}{key}"] = value
    return flat


class Context:
    """One process-wide graph: topics, the delivery queue and the shutdown flag."""

    def __init__(self) -> None:
        self.args = _Args({})
        self._ok = False
        self.subscriptions: dict[str, list["Subscription"]] = {}
        self.publishers: dict[str, list["Publisher"]] = {}
        self.queue: deque[tuple["Subscription", Any]] = deque()
        self.nodes: list["Node"] = []

    def init(self, args: list[str] | None = None) -> None:
        self.args = _parse_ros_args(args)
        self._ok = True

    def ok(self) -> bool:
        return self._ok

    def shutdown(self) -> None:
        self._ok = False
        self.queue.clear()


_default_context = Context()


def init(args: list[str] | None = None, context: Context | None = None) -> None:
    (context or _default_context).init(args)


def ok(context: Context | None = None) -> bool:
    return (context or _default_context).ok()


def shutdown(context: Context | None = None) -> None:
    (context or _default_context).shutdown()


# --- node ------------------------------------------------------------------------------------


def _resolve(name: str, namespace: str, node_name: str) -> str:
    if name.startswith("/"):
        return name
    if name.startswith("~/"):
        return f"{namespace.rstrip('/')}/{node_name}/{name[2:]}"
    return f"{namespace.rstrip('/')}/{name}"


class Publisher:
    def __init__(self, node: "Node", msg_type: type, topic: str, qos: QoSProfile) -> None:
        self.node, self.msg_type, self.topic_name, self.qos = node, msg_type, topic, qos
        self._history: deque = deque(maxlen=max(1, qos.depth))

    def publish(self, msg: Any) -> None:
        ctx = self.node.context
        if not ctx.ok():
            return
        if self.qos.durability == DurabilityPolicy.TRANSIENT_LOCAL:
            self._history.append(msg)
        for sub in ctx.subscriptions.get(self.topic_name, ()):
            ctx.queue.append((sub, msg))

    def get_subscription_count(self) -> int:
        return len(self.node.context.subscriptions.get(self.topic_name, ()))

    def destroy(self) -> None:
        pubs = self.node.context.publishers.get(self.topic_name, [])
        if self in pubs:
            pubs.remove(self)


class Subscription:
    def __init__(self, node: "Node", msg_type: type, topic: str, callback: Callable, qos: QoSProfile) -> None:
        self.node, self.msg_type, self.topic_name, self.callback, self.qos = node, msg_type, topic, callback, qos

    def destroy(self) -> None:
        subs = self.node.context.subscriptions.get(self.topic_name, [])
        if self in subs:
            subs.remove(self)


class Timer:
    """Fires every `period` seconds of the steady clock, the first time one period after creation."""

    def __init__(self, period: float, callback: Callable) -> None:
        self.period_ns = max(1, int(period * 1e9))
        self.callback = callback
        self.next_ns = time.monotonic_ns() + self.period_ns
        self.cancelled = False

    def cancel(self) -> None:
        self.cancelled = True

    def is_canceled(self) -> bool:
        return self.cancelled

    def reset(self) -> None:
        self.cancelled = False
        self.next_ns = time.monotonic_ns() + self.period_ns


class Node:
    """The rclpy.node.Node subset listed in this module's docstring."""

    def __init__(
        self,
        node_name: str,
        *,
        namespace: str | None = None,
        parameter_overrides: list[Parameter] | None = None,
        context: Context | None = None,
        **_: Any,
    ) -> None:
        self.context = context or _default_context
        if not self.context.ok():
            raise RuntimeError("rclpy.init() has not been called")
        args = self.context.args
        self._name = args.node_name or node_name
        ns = args.namespace if args.namespace is not None else (namespace or "/")
        self._namespace = ns if ns.startswith("/") else "/" + ns
        self._overrides: dict[str, Any] = {}
        full = f"{self._namespace.rstrip('/')}/{self._name}"
        for pattern, params in args.overrides.items():
            if pattern in ("/**", "**") or fnmatch.fnmatch(full, pattern) or pattern in (self._name, full):
                self._overrides.update(params)
        for p in parameter_overrides or []:
            self._overrides[p.name] = p.value
        self._parameters: dict[str, Parameter] = {}
        self._declared_defaults: dict[str, Any] = {}
        self._timers: list[Timer] = []
        self._subscriptions: list[Subscription] = []
        self._publishers: list[Publisher] = []
        self._clock = Clock()
        self._logger = _Logger(logging.getLogger(f"cloth_bench_ros.{self._name}"), self._name)
        self.context.nodes.append(self)
        if self.declare_parameter("use_sim_time", False).value:
            self.create_subscription(messages.Clock, "/clock", self._on_clock, 10)

    def _on_clock(self, msg: Any) -> None:
        self._clock.sim_time_ns = Time.from_msg(msg.clock).nanoseconds

    # names
    def get_name(self) -> str:
        return self._name

    def get_namespace(self) -> str:
        return self._namespace

    def resolve_topic_name(self, topic: str) -> str:
        return _resolve(topic, self._namespace, self._name)

    # parameters
    def declare_parameter(self, name: str, value: Any = None, descriptor: Any = None) -> Parameter:
        if name in self._parameters:
            raise ParameterError(f"parameter {name} is already declared")
        chosen = _coerce(name, value, self._overrides[name]) if name in self._overrides else value
        self._parameters[name] = Parameter(name, value=chosen)
        return self._parameters[name]

    def has_parameter(self, name: str) -> bool:
        return name in self._parameters

    def get_parameter(self, name: str) -> Parameter:
        if name not in self._parameters:
            raise ParameterError(f"parameter {name} is not declared on node {self._name}")
        return self._parameters[name]

    # graph
    def create_publisher(self, msg_type: type, topic: str, qos_profile: QoSProfile | int) -> Publisher:
        pub = Publisher(self, msg_type, self.resolve_topic_name(topic), _qos(qos_profile))
        self.context.publishers.setdefault(pub.topic_name, []).append(pub)
        self._publishers.append(pub)
        return pub

    def create_subscription(self, msg_type: type, topic: str, callback: Callable,
                            qos_profile: QoSProfile | int) -> Subscription:
        sub = Subscription(self, msg_type, self.resolve_topic_name(topic), callback, _qos(qos_profile))
        self.context.subscriptions.setdefault(sub.topic_name, []).append(sub)
        self._subscriptions.append(sub)
        if sub.qos.durability == DurabilityPolicy.TRANSIENT_LOCAL:
            for pub in self.context.publishers.get(sub.topic_name, ()):
                for msg in pub._history:
                    self.context.queue.append((sub, msg))
        return sub

    def create_timer(self, timer_period_sec: float, callback: Callable, **_: Any) -> Timer:
        timer = Timer(timer_period_sec, callback)
        self._timers.append(timer)
        return timer

    def destroy_timer(self, timer: Timer) -> bool:
        timer.cancel()
        if timer in self._timers:
            self._timers.remove(timer)
        return True

    def count_subscribers(self, topic: str) -> int:
        return len(self.context.subscriptions.get(self.resolve_topic_name(topic), ()))

    def count_publishers(self, topic: str) -> int:
        return len(self.context.publishers.get(self.resolve_topic_name(topic), ()))

    def get_clock(self) -> Clock:
        return self._clock

    def get_logger(self) -> "_Logger":
        return self._logger

    def destroy_node(self) -> None:
        for sub in self._subscriptions:
            sub.destroy()
        for pub in self._publishers:
            pub.destroy()
        for timer in self._timers:
            timer.cancel()
        self._timers.clear()
        if self in self.context.nodes:
            self.context.nodes.remove(self)


class _Logger:
    def __init__(self, logger: logging.Logger, name: str) -> None:
        self._logger, self._name = logger, name

    def _log(self, level: int, msg: str) -> None:
        self._logger.log(level, "[%s]: %s", self._name, msg)

    def debug(self, msg: str) -> None:
        self._log(logging.DEBUG, msg)

    def info(self, msg: str) -> None:
        self._log(logging.INFO, msg)

    def warning(self, msg: str) -> None:
        self._log(logging.WARNING, msg)

    warn = warning

    def error(self, msg: str) -> None:
        self._log(logging.ERROR, msg)

    def fatal(self, msg: str) -> None:
        self._log(logging.CRITICAL, msg)


# --- executors -------------------------------------------------------------------------------


class SingleThreadedExecutor:
    """Runs queued message callbacks in publish order, then due timers of its nodes."""

    def __init__(self, context: Context | None = None) -> None:
        self.context = context or _default_context
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
        queue = self.context.queue
        for _ in range(len(queue)):
            sub, msg = queue.popleft()
            if sub.node in self.nodes:
                sub.callback(msg)
                return True
            if sub.node in self.context.nodes:
                queue.append((sub, msg))  # for a node of another executor
        return False

    def spin_once(self, timeout_sec: float | None = None) -> None:
        """Run one ready callback, waiting up to timeout_sec for a timer if none is ready."""
        if not self.context.ok() or self._deliver_one():
            return
        timers = self._armed_timers()
        if not timers:
            if timeout_sec:
                time.sleep(min(timeout_sec, 0.01))
            return
        timer = min(timers, key=lambda t: t.next_ns)
        wait = (timer.next_ns - time.monotonic_ns()) / 1e9
        if wait > 0:
            if timeout_sec is not None and wait > timeout_sec:
                time.sleep(timeout_sec)
                return
            time.sleep(wait)
        timer.next_ns += timer.period_ns
        timer.callback()

    def spin(self) -> None:
        while self.context.ok():
            self.spin_once(0.1)

    def spin_until_idle(self) -> None:
        """Spin until no message is queued and no timer is armed (the run is complete)."""
        while self.context.ok() and (self.context.queue or self._armed_timers()):
            self.spin_once(0.1)

    def shutdown(self, timeout_sec: float | None = None) -> bool:
        self.nodes.clear()
        return True


def spin_once(node: Node, *, executor: SingleThreadedExecutor | None = None,
              timeout_sec: float | None = None) -> None:
    ex = executor or SingleThreadedExecutor(node.context)
    ex.add_node(node)
    ex.spin_once(timeout_sec)


def spin(node: Node, executor: SingleThreadedExecutor | None = None) -> None:
    ex = executor or SingleThreadedExecutor(node.context)
    ex.add_node(node)
    ex.spin()


# --- serialization ---------------------------------------------------------------------------


def serialize_message(msg: Any) -> bytes:
    return cdr.serialize(msg)


def deserialize_message(data: bytes, msg_type: type) -> Any:
    return cdr.deserialize(data, msg_type.__msgtype__)
