"""Replays a rosbag2 MCAP bag's PointCloud2 topic in simulation time, or records topics to a bag.

mode replay (default): the bag's cloud topic is read once (data.replay.plan_replay: transformed to
  world, cleaned, aligned, every frame accounted for); the trial message on real/trial announces
  `frames_to_send`, and each frame goes out once /clock reaches its stamp plus `time_offset`
  (clock: sim, the benchmark), or on the wall clock (clock: wall) at `rate_factor` times real
  time, from `start_offset` seconds into the bag, looping if `loop`.
mode record: subscribes to `record_topics` ("topic:type" entries, e.g.
  "/cloth_bench/mujoco/cloud:sensor_msgs/msg/PointCloud2") and writes every message to the bag
  `output`; the bag is finalised on normal end, SIGINT and SIGTERM, and the node reports how many
  messages it received and wrote.
"""

from __future__ import annotations

import json
import time
from functools import partial

from cloth_bench_ros.core.pointcloud2 import create_cloud_xyz32
from cloth_bench_ros.core.scene import SETTLE_DURATION, ClothGrid
from cloth_bench_ros.data import BagReader, BagWriter
from cloth_bench_ros.data.alignment import SearchSettings, reference_motion
from cloth_bench_ros.data.replay import ReplayOptions, plan_replay
from cloth_bench_ros.data.trial import TRIAL_STATUS_NAME
from cloth_bench_ros.engines import make_engine
from cloth_bench_ros.engines.presets import load_preset
from cloth_bench_ros.nodes.common import NAMESPACE, REPLAY_STATUS_NAME, run_node
from cloth_bench_ros.runtime import (
    Clock, DiagnosticArray, DiagnosticStatus, Header, KeyValue, Node, PointCloud2, PointField, Time,
    declare_float, make_qos, message_type, serialize_message, stamp_ns, steady_clock,
)


class Recorder(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__("recorder", namespace=kwargs.pop("namespace", NAMESPACE), **kwargs)
        self.mode = self.declare_parameter("mode", "replay").value
        self.done = False
        self.writer: BagWriter | None = None
        if self.mode == "record":
            self.start_recording()
        elif self.mode == "replay":
            self.start_replay()
        else:
            raise ValueError(f"recorder: unknown mode {self.mode!r} (valid: replay, record)")

    # --- replay ------------------------------------------------------------------------------

    def start_replay(self) -> None:
        path = self.declare_parameter("bag", "").value
        if not path:
            raise ValueError("recorder: parameter 'bag' is empty (path to a rosbag2 MCAP bag)")
        # Frames are stamped from the start of the quintic part; the run starts with the settle phase.
        self.offset_ns = int(round(declare_float(self, "time_offset", SETTLE_DURATION) * 1e9))
        clock = self.declare_parameter("clock", "sim").value
        self.rate_factor = declare_float(self, "rate_factor", 1.0)
        self.start_offset_ns = int(round(declare_float(self, "start_offset", 0.0) * 1e9))
        self.loop = bool(self.declare_parameter("loop", False).value)
        if clock not in ("sim", "wall"):
            raise ValueError(f"recorder: unknown clock {clock!r} (valid: sim, wall)")
        if not self.rate_factor > 0:
            raise ValueError(f"recorder: rate_factor must be > 0, got {self.rate_factor}")
        self.bag = BagReader(path)
        options = self.replay_options()
        nx, nz = (int(self.declare_parameter(n, 0).value) for n in ("grid_nx", "grid_nz"))
        self.plan = plan_replay(self.bag, options, partial(self.reference_motion, options, nx, nz))
        self.topic = self.plan.topic
        self.published = 0
        self.cloud_pub = self.create_publisher(PointCloud2, "real/cloud", make_qos(10))
        self.trial_pub = self.create_publisher(DiagnosticArray, "real/trial", make_qos(1, latched=True))
        self.rewind()
        trial = self.trial_message()
        if clock == "sim":
            trial.status.append(self.replay_status())
        self.trial_pub.publish(trial)
        if clock == "sim":
            self.create_subscription(Clock, "/clock", self.on_clock, make_qos(10))
        else:
            self.wall_start_ns = time.monotonic_ns()
            self.wall_timer = self.create_timer(0.001, self.on_wall_tick, clock=steady_clock())  # not sim time

    def replay_options(self) -> ReplayOptions:
        """What the bag does not say, from the node's parameters."""
        cut = int(self.declare_parameter("change_of_phase_frame", -1).value)
        transform = list(self.declare_parameter("transform", [0.0]).value)
        if transform != [0.0] and len(transform) != 16:
            raise ValueError(f"recorder: transform needs 16 numbers (a 4x4 matrix), got {len(transform)}")
        search = SearchSettings(window=declare_float(self, "align_window", 1.0),
                                coarse_step=declare_float(self, "align_step", 1.0 / 30.0))
        return ReplayOptions(
            cloth=self.declare_parameter("cloth", "towel").value,
            primitive=self.declare_parameter("primitive", "dynamic").value,
            change_of_phase_frame=cut if cut >= 0 else None,
            topic=self.declare_parameter("topic", "").value,
            start_time=self.declare_parameter("start_time", "").value,
            targets_topic=self.declare_parameter("targets_topic", "").value,
            transform=tuple(transform) if len(transform) == 16 else None,
            clean=self.declare_parameter("clean", "auto").value,
            voxel=declare_float(self, "voxel", 0.0),
            table_plane=self.declare_parameter("table_plane", "auto").value,
            rate_hz=declare_float(self, "rate_hz", 100.0),
            align_engine=self.declare_parameter("align_engine", "mujoco").value,
            search=search,
        )

    @staticmethod
    def reference_motion(options: ReplayOptions, nx: int, nz: int, seconds: float):
        """The reference simulation the automatic alignment compares the bag with (the run's engine and grid)."""
        preset = load_preset(options.align_engine, options.cloth, options.primitive)
        engine = make_engine(options.align_engine, options.rate_hz, preset, ClothGrid(nx, nz) if nx and nz else None)
        try:
            return reference_motion(engine, options.primitive, options.rate_hz, seconds)
        finally:
            engine.close()

    @property
    def frames_to_send(self) -> int:
        """How many real frames this replay publishes (the evaluator waits for as many)."""
        return len(self.plan.frames)

    def rewind(self) -> None:
        skipped = sum(1 for t, _ in self.plan.frames if t < self.start_offset_ns)
        self.plan.counts["skipped_by_start_offset"] = skipped
        self.frames = iter([f for f in self.plan.frames if f[0] >= self.start_offset_ns])
        self.next_frame = next(self.frames, None)
        self.done = self.next_frame is None

    def trial_message(self) -> DiagnosticArray:
        """The trial (cloth, primitive, change of phase, ...) and the replay's frame accounting."""
        info = self.plan.trial.to_strings()
        info["replay"] = json.dumps(self.plan.accounting())
        info["frames_to_send"] = str(self.frames_to_send - self.plan.counts["skipped_by_start_offset"])
        values = [KeyValue(key=k, value=v) for k, v in info.items()]
        status = DiagnosticStatus(level=DiagnosticStatus.OK, name=TRIAL_STATUS_NAME,
                                  message=str(self.bag.path), hardware_id="recorder", values=values)
        return DiagnosticArray(status=[status])

    def replay_status(self) -> DiagnosticStatus:
        """The run-time stamps of every frame the sim-clock replay will send (common.REPLAY_STATUS_NAME)."""
        stamps = [t + self.offset_ns for t, _ in self.plan.frames if t >= self.start_offset_ns]
        return DiagnosticStatus(level=DiagnosticStatus.OK, name=REPLAY_STATUS_NAME, hardware_id="recorder",
                                message=f"{len(stamps)} frames, sent as /clock reaches their stamps",
                                values=[KeyValue(key="frames", value=str(len(stamps))),
                                        KeyValue(key="stamps_ns", value=",".join(map(str, stamps)))])

    def publish_until(self, t_ns: int, restamp_offset_ns: int) -> None:
        """Publish every frame at or before t_ns (from the motion's start), restamped by the offset."""
        while self.next_frame is not None:
            frame_t, points = self.next_frame
            if frame_t > t_ns:
                break
            header = Header(stamp=Time(nanoseconds=frame_t + restamp_offset_ns).to_msg(), frame_id="world")
            self.cloud_pub.publish(create_cloud_xyz32(header, points, PointCloud2, PointField))
            self.published += 1
            self.next_frame = next(self.frames, None)
        self.done = self.next_frame is None

    def on_clock(self, msg: Clock) -> None:
        self.publish_until(stamp_ns(msg.clock) - self.offset_ns, self.offset_ns)

    def on_wall_tick(self) -> None:
        elapsed = (time.monotonic_ns() - self.wall_start_ns) * self.rate_factor
        self.publish_until(int(elapsed) + self.start_offset_ns, 0)
        if self.done and self.loop:
            self.rewind()
            self.wall_start_ns = time.monotonic_ns()
        elif self.done:
            self.destroy_timer(self.wall_timer)

    # --- record ------------------------------------------------------------------------------

    def start_recording(self) -> None:
        output = self.declare_parameter("output", "").value
        entries = list(self.declare_parameter("record_topics", [""]).value)
        if not output:
            raise ValueError("recorder: parameter 'output' is empty (bag directory to record into)")
        topics = [e.rsplit(":", 1) for e in entries if e]
        if not topics or any(len(t) != 2 for t in topics):
            raise ValueError("recorder: record_topics needs entries 'topic:package/msg/Type'")
        self.received = 0
        self.writer = BagWriter(output)
        for topic, typename in topics:
            msg_type = message_type(typename)
            name = self.resolve_topic_name(topic)
            self.create_subscription(msg_type, topic, partial(self.on_record, name, typename), make_qos(1000))
        self.get_logger().info(f"recording {', '.join(t for t, _ in topics)} to {output}")

    def on_record(self, topic: str, typename: str, msg) -> None:
        self.received += 1
        # As rosbag2 records: log time is the receive time, the header stamp stays in the message.
        self.writer.write(topic, typename, 0, serialize_message(msg), log_time_ns=self.get_clock().now().nanoseconds)

    def close(self) -> None:
        """Finalise a recording and report received and written counts."""
        if self.writer is not None and not self.writer.closed:
            self.writer.close()
            report = f"recorder: received {self.received} messages, wrote {self.writer.written}"
            if self.received != self.writer.written:
                self.get_logger().error(report + " (some were lost)")
            print(report, flush=True)


def main(args: list[str] | None = None) -> int:
    return run_node(Recorder, args)


if __name__ == "__main__":
    raise SystemExit(main())
