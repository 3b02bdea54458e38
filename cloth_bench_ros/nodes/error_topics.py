"""
The evaluator's error outputs: `<engine>/error_cloud`, frame and step metrics, the live view.

One computation feeds them all: each frame the evaluator's core scores (core.evaluation's
ScoredFrame: the vertices at the real frame's stamp and each vertex's L1 distance to the nearest
real point) is published on the graph's topics and, with `live`, sent to the Foxglove viewer
(live/view.py); the comparison bag is written from the same arrays. Topic names and field
orders are live/error_view.py's.
"""

from __future__ import annotations

import time
from typing import Any

from cloth_bench_ros.core.trajectory import TaskLike
from cloth_bench_ros.live import error_view
from cloth_bench_ros.live.view import LiveView
from cloth_bench_ros.runtime import (
    declare_option,
    Float64MultiArray,
    Header,
    make_qos,
    MultiArrayDimension,
    MultiArrayLayout,
    PointCloud2,
    PointField,
)

LIVE_OPTIONS = ('live', 'live_host', 'live_port', 'live_wait')
SETTLE_S = 0.3  # after a first viewer's first subscription: the rest of its subscriptions


def declare_live_parameters(node: Any) -> dict[str, Any]:
    """Declare and check the evaluator's live-view parameters (live, live_host, live_port, ...)."""
    return {name: declare_option(node, name) for name in LIVE_OPTIONS}


class ErrorTopics:
    """Publishers of the error outputs of one evaluator node, and its live view if asked."""

    def __init__(
        self,
        node: Any,
        engines: list[str],
        task: TaskLike,
        rate_hz: float,
        quintic_start_ns: int,
        realtime: bool,
        live: dict[str, Any],
        faces: Any = None,
    ) -> None:
        self.node, self.quintic_start_ns = node, quintic_start_ns
        qos = make_qos(100)
        self.clouds = {
            e: node.create_publisher(PointCloud2, f'{e}/{error_view.ERROR_CLOUD}', qos)
            for e in engines
        }
        array = Float64MultiArray
        self.frames = {
            e: node.create_publisher(array, f'{e}/{error_view.FRAME_METRICS_TOPIC}', qos)
            for e in engines
        }
        self.steps = {
            e: node.create_publisher(array, f'{e}/{error_view.STEP_METRICS_TOPIC}', qos)
            for e in engines
        }
        self.latency: dict[str, tuple[int, float]] = {}  # engine -> (state stamp, latency s)
        self.live: Any = None
        self.wait_s = float(live.get('live_wait', 0.0))
        self.waiting_until: float | None = None
        self.decided = realtime  # a realtime run starts on its schedule: no wait for a viewer
        if live.get('live'):
            self.live = LiveView(
                engines,
                task,
                rate_hz,
                live['live_host'],
                live['live_port'],
                realtime,
                warn=node.get_logger().warning,
                faces=faces,
            )
            if realtime:  # no wait: the schedule starts when the controller says
                node.get_logger().warning(f'live view at {self.live.url} (Foxglove WebSocket)')
        else:
            self.decided = True

    # the lockstep run's start: a first viewer, or the wait's end
    def ready_to_start(self) -> bool:
        """Return False while a lockstep run with `live` still waits for its first viewer."""
        if self.decided or self.live is None:
            return True
        now = time.monotonic()
        if self.waiting_until is None:
            self.waiting_until = now + self.wait_s
            self.node.get_logger().warning(  # shown by the CLI, which hides info lines
                f'live view: waiting up to {self.wait_s:g} s for a viewer at {self.live.url}'
                ' (Foxglove: Open connection, Foxglove WebSocket) before the run starts'
            )
        if self.live.viewers() and self.waiting_until > now + SETTLE_S:
            self.waiting_until = now + SETTLE_S  # its other subscriptions follow within a moment
        if now < self.waiting_until:
            return False
        self.decided = True
        if not self.live.viewers():
            self.node.get_logger().warning(
                f'live view: no viewer after {self.wait_s:g} s; the run goes on (a viewer may'
                ' still connect)'
            )
        return True

    # outputs
    def scored(self, scored: Any) -> None:
        """Publish one scored frame: error cloud and frame metrics (and send them live)."""
        engine = scored.score.engine
        # Volatile topics: a message no subscription is matched to goes nowhere, so it is not
        # even built (a run nobody watches pays nothing for them).
        if self.clouds[engine].get_subscription_count():
            header = Header(frame_id='world')
            header.stamp.sec, header.stamp.nanosec = divmod(int(scored.stamp_ns), 1_000_000_000)
            cloud = error_view.error_cloud(header, scored, PointCloud2, PointField)
            self.clouds[engine].publish(cloud)
        if self.frames[engine].get_subscription_count():
            self.frames[engine].publish(
                self._array(error_view.frame_values(scored.score), error_view.FRAME_METRICS)
            )
        if self.live is not None:
            self.live.frame(scored)

    def state_latency(self, engine: str, stamp_ns: int, latency_s: float) -> None:
        """Note the latency of an engine's state, for its step's metrics."""
        self.latency[engine] = (stamp_ns, latency_s)

    def step(self, engine: str, stamp_ns: int, step_time: float) -> None:
        """Publish one step's metrics: t, step time, latency (NaN if its state's is not in)."""
        known = self.latency.get(engine)
        latency = known[1] if known is not None and known[0] == stamp_ns else None
        values = error_view.step_values(
            (stamp_ns - self.quintic_start_ns) / 1e9, step_time, latency
        )
        if self.steps[engine].get_subscription_count():
            self.steps[engine].publish(self._array(values, error_view.STEP_METRICS))
        if self.live is not None:
            self.live.step(engine, stamp_ns, values)

    @staticmethod
    def _array(values: list[float], fields: tuple[str, ...]) -> Any:
        return error_view.metrics_array(
            values, fields, Float64MultiArray, MultiArrayLayout, MultiArrayDimension
        )

    def close(self) -> None:
        """Stop the live view's server."""
        if self.live is not None:
            self.live.close()
