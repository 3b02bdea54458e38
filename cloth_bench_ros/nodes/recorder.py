"""Replays a rosbag2 MCAP bag's PointCloud2 topic in simulation time, or records topics to a bag.

mode replay (default): each frame goes out once /clock reaches its stamp plus `time_offset`
  (clock: sim, the benchmark), or on the wall clock (clock: wall) at `rate_factor` times real
  time, from `start_offset` seconds into the bag, looping if `loop`.
mode record: subscribes to `record_topics` ("topic:type" entries, e.g.
  "/cloth_bench/mujoco/cloud:sensor_msgs/msg/PointCloud2") and writes every message to the bag
  `output`; the bag is finalised on normal end, SIGINT and SIGTERM, and the node reports how many
  messages it received and wrote.
"""

from __future__ import annotations

import errno
import shutil
import time
from functools import partial

from cloth_bench_ros import validation
from cloth_bench_ros.data.bag import TRIAL_STATUS_NAME, BagReader, BagWriter
from cloth_bench_ros.nodes.common import NAMESPACE, run_node
from cloth_bench_ros.runtime import (
    Clock, DiagnosticArray, DiagnosticStatus, KeyValue, Node, PointCloud2, Time, deserialize_message,
    make_qos, message_type, serialize_message, stamp_ns,
)
from cloth_bench_ros.core.scene import SETTLE_DURATION

MAX_RATE_FACTOR = 1e6  # wall-clock replay speed
# Record mode on a filling disk: stop while the open chunk (<= 1 MiB), the summary and
# metadata.yaml still fit; a small reserve file keeps room for metadata.yaml if another
# process fills the disk first.
DISK_MARGIN_BYTES = 4 * 1024 * 1024
DISK_CHECK_EVERY_BYTES = 256 * 1024
RESERVE_NAME = ".cloth_bench_reserve"
RESERVE_BYTES = 64 * 1024


class RecordingStopped(ValueError):
    """A recording that cannot go on (disk full, write error); str() is one line naming the bag."""


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
        # Bag stamps count from the start of the quintic part; the run starts with the settle phase.
        self.declare_parameter("time_offset", SETTLE_DURATION)
        clock = self.declare_parameter("clock", "sim").value
        self.declare_parameter("rate_factor", 1.0)
        self.declare_parameter("start_offset", 0.0)
        self.declare_parameter("loop", False)
        # Every value through the one validation layer; an error names the node and parameter.
        p = validation.node_parameters(self, {
            "time_offset": validation.time_offset, "start_offset": validation.time_offset,
            "rate_factor": lambda v, n: validation.positive(v, n, MAX_RATE_FACTOR), "loop": validation.boolean})
        self.offset_ns = int(round(p["time_offset"] * 1e9))
        self.start_offset_ns = int(round(p["start_offset"] * 1e9))
        self.rate_factor, self.loop = p["rate_factor"], p["loop"]
        if clock not in ("sim", "wall"):
            raise ValueError(f"recorder: unknown clock {clock!r} (valid: sim, wall)")
        self.bag = BagReader(path)
        self.topic = self.declare_parameter("topic", "").value or self.bag.cloud_topic()
        self.published = 0
        self.cloud_pub = self.create_publisher(PointCloud2, "real/cloud", make_qos(10))
        self.trial_pub = self.create_publisher(DiagnosticArray, "real/trial", make_qos(1, latched=True))
        self.trial_pub.publish(self.trial_message())
        self.rewind()
        if clock == "sim":
            self.create_subscription(Clock, "/clock", self.on_clock, make_qos(10))
        else:
            self.wall_start_ns = time.monotonic_ns()
            self.wall_timer = self.create_timer(0.001, self.on_wall_tick)

    def rewind(self) -> None:
        self.frames = (f for f in self.bag.raw_messages([self.topic]) if f[2] >= self.start_offset_ns)
        self.next_frame = next(self.frames, None)
        self.done = self.next_frame is None

    def trial_message(self) -> DiagnosticArray:
        """The bag's trial metadata (cloth, primitive, change of phase, ...) as key/values."""
        info = self.bag.trial.to_strings() if self.bag.trial else {}
        values = [KeyValue(key=k, value=v) for k, v in info.items()]
        status = DiagnosticStatus(level=DiagnosticStatus.OK, name=TRIAL_STATUS_NAME,
                                  message=str(self.bag.path), hardware_id="recorder", values=values)
        return DiagnosticArray(status=[status])

    def publish_until(self, bag_time_ns: int, restamp_offset_ns: int) -> None:
        """Publish every frame whose bag stamp is <= bag_time_ns, restamped by the offset."""
        while self.next_frame is not None:
            _, _, bag_stamp, cdr = self.next_frame
            if bag_stamp > bag_time_ns:
                break
            cloud = deserialize_message(cdr, PointCloud2)
            cloud.header.stamp = Time(nanoseconds=bag_stamp + restamp_offset_ns).to_msg()
            self.cloud_pub.publish(cloud)
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
        self.stopped = False
        self.unchecked_bytes = 0
        self.writer = BagWriter(output)
        self.reserve = self.writer.path / RESERVE_NAME
        try:  # room for metadata.yaml even if something else fills the disk
            self.reserve.write_bytes(bytes(RESERVE_BYTES))
        except OSError as exc:
            self.stop_recording(exc, failed_write=True)
        for topic, typename in topics:
            msg_type = message_type(typename)
            name = self.resolve_topic_name(topic)
            self.create_subscription(msg_type, topic, partial(self.on_record, name, typename), make_qos(1000))
        self.get_logger().info(f"recording {', '.join(t for t, _ in topics)} to {output}")

    def on_record(self, topic: str, typename: str, msg) -> None:
        self.received += 1
        if self.stopped:
            return  # counted as received, not written
        stamp = stamp_ns(msg.header.stamp) if hasattr(msg, "header") else self.get_clock().now().nanoseconds
        cdr = serialize_message(msg)
        self.unchecked_bytes += len(cdr)
        if self.unchecked_bytes >= DISK_CHECK_EVERY_BYTES:
            self.unchecked_bytes = 0
            free = shutil.disk_usage(self.writer.path).free
            if free < DISK_MARGIN_BYTES:  # stop while the bag can still be finished cleanly
                self.stop_recording(OSError(errno.ENOSPC, f"disk nearly full, {free} bytes left"), False)
        try:
            self.writer.write(topic, typename, stamp, cdr)
        except OSError as exc:
            self.stop_recording(exc, failed_write=True)

    def stop_recording(self, exc: OSError, failed_write: bool) -> None:
        """End the recording on a full disk or write error: finalise what is on disk, then one error line.

        After a failed write the MCAP writer's state no longer matches the file, so the bag is
        kept as written (`BagWriter.abandon`) instead of finished over the gap.
        """
        self.stopped = True
        self.reserve.unlink(missing_ok=True)
        if failed_write:
            self.writer.abandon()
        else:
            self.close_writer()
        reason = exc.strerror or str(exc)
        raise RecordingStopped(f"recorder: bag {self.writer.path}: {reason}; recording stopped, the bag keeps "
                               f"the {self.writer.written} messages written before")

    def close_writer(self) -> None:
        """Finalise the bag; if finishing it fails (disk full), keep what is on disk."""
        if not self.writer.closed:
            try:
                self.writer.close()
            except OSError:
                self.writer.abandon()
        self.reserve.unlink(missing_ok=True)

    def close(self) -> None:
        """Finalise a recording and report received and written counts."""
        if self.writer is not None and not getattr(self, "reported", False):
            self.reported = True
            self.close_writer()
            report = f"recorder: received {self.received} messages, wrote {self.writer.written}"
            if self.received != self.writer.written and not self.stopped:  # a stop has said so already
                self.get_logger().error(report + " (some were lost)")
            print(report, flush=True)


def main(args: list[str] | None = None) -> int:
    return run_node(Recorder, args)


if __name__ == "__main__":
    raise SystemExit(main())
