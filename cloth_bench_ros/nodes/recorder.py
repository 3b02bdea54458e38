"""Replays the PointCloud2 topic of a rosbag2 MCAP bag in simulation time."""

from __future__ import annotations

from cloth_bench_ros.data.bag import TRIAL_STATUS_NAME, BagReader
from cloth_bench_ros.nodes.common import NAMESPACE, run_node
from cloth_bench_ros.runtime import (
    Clock, DiagnosticArray, DiagnosticStatus, KeyValue, Node, PointCloud2, Time, deserialize_message,
    make_qos, stamp_ns,
)
from cloth_bench_ros.scene import SETTLE_DURATION


class Recorder(Node):
    """Publishes each bag frame once /clock reaches its stamp plus `time_offset`."""

    def __init__(self, **kwargs) -> None:
        super().__init__("recorder", namespace=kwargs.pop("namespace", NAMESPACE), **kwargs)
        path = self.declare_parameter("bag", "").value
        if not path:
            raise ValueError("recorder: parameter 'bag' is empty (path to a rosbag2 MCAP bag)")
        # Bag stamps count from the start of the quintic part; the run starts with the settle phase.
        self.offset_ns = int(round(self.declare_parameter("time_offset", SETTLE_DURATION).value * 1e9))
        self.bag = BagReader(path)
        topic = self.declare_parameter("topic", "").value or self.bag.cloud_topic()
        self.frames = self.bag.raw_messages([topic])
        self.next_frame = next(self.frames, None)
        self.published = 0
        self.cloud_pub = self.create_publisher(PointCloud2, "real/cloud", make_qos(10))
        self.trial_pub = self.create_publisher(DiagnosticArray, "real/trial", make_qos(1, latched=True))
        self.trial_pub.publish(self.trial_message())
        self.create_subscription(Clock, "/clock", self.on_clock, make_qos(10))
        self.done = self.next_frame is None

    def trial_message(self) -> DiagnosticArray:
        """The bag's trial metadata (cloth, primitive, change of phase, ...) as key/values."""
        info = self.bag.trial.to_strings() if self.bag.trial else {}
        values = [KeyValue(key=k, value=v) for k, v in info.items()]
        status = DiagnosticStatus(level=DiagnosticStatus.OK, name=TRIAL_STATUS_NAME,
                                  message=str(self.bag.path), hardware_id="recorder", values=values)
        return DiagnosticArray(status=[status])

    def on_clock(self, msg: Clock) -> None:
        now = stamp_ns(msg.clock)
        while self.next_frame is not None:
            _, _, bag_stamp, cdr = self.next_frame
            replay_stamp = bag_stamp + self.offset_ns
            if replay_stamp > now:
                break
            cloud = deserialize_message(cdr, PointCloud2)
            cloud.header.stamp = Time(nanoseconds=replay_stamp).to_msg()
            self.cloud_pub.publish(cloud)
            self.published += 1
            self.next_frame = next(self.frames, None)
        self.done = self.next_frame is None


def main(args: list[str] | None = None) -> int:
    return run_node(Recorder, args)


if __name__ == "__main__":
    raise SystemExit(main())
