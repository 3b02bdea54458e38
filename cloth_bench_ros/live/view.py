"""
The live viewer stream of a run: a Foxglove WebSocket server (foxglove-sdk) fed by the evaluator.

An output sink like the comparison bag's writer: it takes the evaluator's scored frames
(core.evaluation.ScoredFrame) and steps and sends them, as ROS 2 messages in CDR with `ros2msg`
schemas, on the topics of live/error_view.py (the node graph's and the comparison bag's names), so
one Foxglove layout opens a live run, a recorded comparison and a graph seen through
foxglove_bridge. Messages are logged at simulation time under lockstep, wall time under realtime.

Nothing here blocks the run: a channel nobody subscribes to is not even encoded, the server
queues a bounded backlog per viewer and drops the oldest messages of a slow one, and a viewer
that leaves is reported in one warning line. Messages are handed to the server in bursts, a
scored frame's with the steps before it: each hand-over wakes the server's threads, which costs
the run more than the encoding of a step's numbers.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any, Callable, cast

from cloth_bench_ros.core.trajectory import full_targets, TaskLike
from cloth_bench_ros.data import messages
from cloth_bench_ros.errors import ClothBenchError
from cloth_bench_ros.live import error_view
from cloth_bench_ros.live.comparison_bag import (
    cloth_triangles, MARKER, mesh_marker, table_marker, target_poses,
)
from cloth_bench_ros.options import OPTIONS
import numpy as np

DEFAULT_HOST = OPTIONS['live_host'].default
DEFAULT_PORT = OPTIONS['live_port'].default
DEFAULT_WAIT_S = OPTIONS['live_wait'].default
BACKLOG = 256  # messages queued per viewer before the oldest are dropped
CLOSE_GRACE_S = 0.25  # at the end, for the server's threads to send what is queued
FLUSH_EVERY = 64  # step messages held at most before they go out without a frame
LAYOUT_FILE = 'cloth_bench_live.json'  # in the package's share/config


class LiveViewError(ClothBenchError, ValueError):
    """The live view cannot start (port in use, address not available, foxglove-sdk missing)."""


class _Listener:
    """Counts the viewers subscribed; notes a viewer that leaves before the run ends."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.subscriptions: dict[int, int] = {}  # client id -> channels subscribed
        self.seen: set[int] = set()
        self.left: list[int] = []

    def on_subscribe(self, client: Any, channel: Any) -> None:
        with self.lock:
            self.subscriptions[client.id] = self.subscriptions.get(client.id, 0) + 1
            self.seen.add(client.id)

    def on_unsubscribe(self, client: Any, channel: Any) -> None:
        with self.lock:
            left = self.subscriptions.get(client.id, 0) - 1
            if left > 0:
                self.subscriptions[client.id] = left
            elif self.subscriptions.pop(client.id, None) is not None:
                self.left.append(client.id)

    def viewers(self) -> int:
        with self.lock:
            return len(self.subscriptions)


class LiveView:
    """The Foxglove WebSocket server of one run (see module doc)."""

    def __init__(
        self,
        engines: list[str],
        task: TaskLike,
        rate_hz: float,
        host: str = DEFAULT_HOST,
        port: int = DEFAULT_PORT,
        realtime: bool = False,
        warn: Callable[[str], None] = print,
        faces: np.ndarray | None = None,
    ) -> None:
        try:
            import foxglove.websocket  # lazy: --live only; foxglove-sdk is not in .venv-ros
        except ImportError as exc:
            raise LiveViewError(f'live view: foxglove-sdk is not installed ({exc})') from None
        logging.getLogger('foxglove').setLevel(logging.ERROR)  # its drops: our one line instead
        self.realtime, self.warn, self.rate_hz = realtime, warn, float(rate_hz)
        self.targets = full_targets(task, rate_hz)
        self.faces = faces  # the cloth's triangles (a --cloth-mesh's; None: the grid's)
        self.listener = _Listener()
        self.context = foxglove.Context()
        self.channels: dict[str, Any] = {}
        self._add(foxglove, error_view.topic(error_view.REAL_CLOUD), messages.POINTCLOUD2)
        self._add(foxglove, error_view.topic(error_view.TARGETS), messages.POSE_ARRAY)
        self._add(foxglove, error_view.topic(error_view.SCENE), MARKER)
        for engine in engines:
            self._add(
                foxglove, error_view.topic(error_view.ERROR_CLOUD, engine), messages.POINTCLOUD2
            )
            self._add(foxglove, error_view.topic(error_view.MESH, engine), MARKER)
            for name in (error_view.FRAME_METRICS_TOPIC, error_view.STEP_METRICS_TOPIC):
                self._add(
                    foxglove, error_view.topic(name, engine), error_view.FLOAT64_MULTI_ARRAY
                )
        try:
            self.server = foxglove.start_server(
                name='cloth_bench',
                host=host,
                port=int(port),
                server_listener=cast(Any, self.listener),  # the SDK's Protocol, by shape
                context=self.context,
                message_backlog_size=BACKLOG,
            )
        except Exception as exc:  # the SDK raises its own RuntimeError for bind failures
            raise LiveViewError(
                f'live view: cannot serve on {host}:{port} ({str(exc).splitlines()[0]});'
                ' another run or viewer bridge may hold the port: pick one with --live-port'
            ) from None
        self.url = f'ws://{host}:{self.server.port}'
        self.held: list[tuple[Any, bytes, int]] = []  # (channel, CDR, log time) not yet sent
        self.last_real = -1
        self.scene_sent = False
        self.warned_left = False
        self.closed = False

    def _add(self, foxglove: Any, topic: str, msgtype: str) -> None:
        schema = foxglove.Schema(
            name=msgtype, encoding='ros2msg', data=messages.msgdef(msgtype).encode()
        )
        self.channels[topic] = foxglove.Channel(
            topic, schema=schema, message_encoding='cdr', context=self.context
        )

    @property
    def port(self) -> int:
        return int(self.server.port)

    def viewers(self) -> int:
        """Return how many viewers are subscribed now."""
        return self.listener.viewers()

    def wait_for_viewer(self, seconds: float, poll_s: float = 0.05) -> bool:
        """Wait up to `seconds` for a first viewer's subscriptions; True if one came."""
        deadline = time.monotonic() + seconds
        while self.viewers() == 0 and time.monotonic() < deadline:
            time.sleep(poll_s)
        if self.viewers():
            time.sleep(0.2)  # its other subscriptions follow the first within a moment
        return self.viewers() > 0

    def _log(self, topic: str, make: Callable[[], bytes], stamp_ns: int) -> None:
        channel = self.channels.get(topic)
        if channel is None or not channel.has_sinks():
            return
        log_time = time.time_ns() if self.realtime else int(stamp_ns)
        self.held.append((channel, make(), log_time))

    def _flush(self) -> None:
        held, self.held = self.held, []
        for channel, data, log_time in held:
            channel.log(data, log_time=log_time)

    def _check_viewers(self) -> None:
        if self.listener.left and not self.warned_left:
            self.warned_left = True
            self.warn(
                'live view: a viewer left or was dropped (too slow); the run goes on and the'
                ' server keeps serving'
            )

    def frame(self, scored: Any) -> None:
        """Send one scored frame: the real cloud (once per frame), error cloud, frame metrics."""
        if self.closed:
            return
        self._check_viewers()
        stamp = int(scored.stamp_ns)
        if not self.scene_sent:
            self.scene_sent = True
            self._log(
                error_view.topic(error_view.SCENE),
                lambda: messages.serialize(table_marker(stamp)),
                stamp,
            )
        if stamp != self.last_real:
            self.last_real = stamp
            real = np.asarray(scored.real)
            self._log(
                error_view.topic(error_view.REAL_CLOUD),
                lambda: error_view.cdr_cloud(stamp, real),
                stamp,
            )
            self._log(
                error_view.topic(error_view.TARGETS),
                lambda: error_view.cdr_poses(
                    stamp, target_poses(self.targets, self.rate_hz, stamp)
                ),
                stamp,
            )
        engine = scored.score.engine
        self._log(
            error_view.topic(error_view.ERROR_CLOUD, engine),
            lambda: error_view.cdr_error_cloud(scored),
            stamp,
        )
        vertices = np.asarray(scored.vertices)
        self._log(
            error_view.topic(error_view.MESH, engine),
            lambda: messages.serialize(mesh_marker(
                stamp, engine, vertices, cloth_triangles(vertices, self.faces))),
            stamp,
        )
        self._log(
            error_view.topic(error_view.FRAME_METRICS_TOPIC, engine),
            lambda: error_view.cdr_metrics(
                error_view.frame_values(scored.score), error_view.FRAME_METRICS
            ),
            stamp,
        )
        self._flush()

    def step(self, engine: str, stamp_ns: int, values: list[float]) -> None:
        """Send one step's numbers (error_view.STEP_METRICS order)."""
        if self.closed:
            return
        self._log(
            error_view.topic(error_view.STEP_METRICS_TOPIC, engine),
            lambda: error_view.cdr_metrics(values, error_view.STEP_METRICS),
            stamp_ns,
        )
        if len(self.held) >= FLUSH_EVERY:
            self._flush()

    def close(self) -> None:
        """Stop the server (viewers see it go), a moment after the last message to a viewer."""
        if not self.closed:
            self._flush()
            self.closed = True
            if self.viewers():
                time.sleep(CLOSE_GRACE_S)  # the server sends on its own threads
            self.server.stop()
