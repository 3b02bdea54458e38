"""Streams the quintic gripper targets of both arms as PoseArray [left, right] and owns /clock."""

from __future__ import annotations

from functools import partial

from cloth_bench_ros import validation
from cloth_bench_ros.nodes.common import NAMESPACE, run_node
from cloth_bench_ros.runtime import (
    Clock, Node, Pose, PoseArray, PointCloud2, Time, make_qos, stamp_ns,
)
from cloth_bench_ros.core.trajectory import full_targets, parse_primitive, quaternion_xyz

PACINGS = ("lockstep", "realtime")


class TrajectoryPublisher(Node):
    """Publishes target k; in lockstep, target k+1 once every simulator has published state k."""

    def __init__(self, **kwargs) -> None:
        super().__init__("trajectory_publisher", namespace=kwargs.pop("namespace", NAMESPACE), **kwargs)
        primitive = parse_primitive(self.declare_parameter("primitive", "dynamic").value)
        rate_hz = float(self.declare_parameter("rate_hz", 100.0).value)
        self.pacing = self.declare_parameter("pacing", "lockstep").value
        self.engines = list(self.declare_parameter("engines", ["mujoco"]).value)
        self.min_clock_subscribers = int(self.declare_parameter("min_clock_subscribers", 0).value)
        # Every value through the one validation layer; an error names the node and parameter.
        validation.node_parameters(self, {
            "rate_hz": validation.rate_hz, "engines": validation.unique,
            "min_clock_subscribers": lambda v, n: validation.integer(v, n, 0, 10_000)})
        if self.pacing not in PACINGS:
            raise ValueError(f"unknown pacing {self.pacing!r} (valid: {', '.join(PACINGS)})")
        self.targets = full_targets(primitive, rate_hz)
        self.target_pub = self.create_publisher(PoseArray, "targets", make_qos(10))
        self.clock_pub = self.create_publisher(Clock, "/clock", make_qos(10))
        for engine in self.engines:
            self.create_subscription(PointCloud2, f"{engine}/cloud", partial(self.on_state, engine), make_qos(10))
        self.k = -1
        self.reported: dict[str, int] = {}
        self.done = False
        self.pace_timer = None
        self.start_timer = self.create_timer(0.02, self.try_start)

    def try_start(self) -> None:
        """Start once every simulator (and every sim-time node) is listening."""
        if self.target_pub.get_subscription_count() < len(self.engines):
            return
        if self.clock_pub.get_subscription_count() < self.min_clock_subscribers:
            return
        self.destroy_timer(self.start_timer)
        if self.pacing == "realtime":
            self.pace_timer = self.create_timer(1.0 / self.targets.rate_hz, self.publish_next)
        self.publish_next()

    def publish_next(self) -> None:
        if self.k + 1 >= len(self.targets):
            self.done = True
            if self.pace_timer is not None:
                self.destroy_timer(self.pace_timer)
            return
        self.k += 1
        k, tg = self.k, self.targets
        stamp = Time(nanoseconds=tg.stamp_ns(k)).to_msg()
        self.clock_pub.publish(Clock(clock=stamp))
        msg = PoseArray()
        msg.header.stamp = stamp
        msg.header.frame_id = "world"
        qx, qy, qz, qw = quaternion_xyz(tg.roll[k], tg.pitch[k], tg.yaw[k])
        for position in (tg.left[k], tg.right[k]):
            pose = Pose()
            pose.position.x, pose.position.y, pose.position.z = (float(c) for c in position)
            pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w = qx, qy, qz, qw
            msg.poses.append(pose)
        self.target_pub.publish(msg)

    def on_state(self, engine: str, msg: PointCloud2) -> None:
        self.reported[engine] = stamp_ns(msg.header.stamp)
        if self.pacing != "lockstep" or self.k < 0:
            return
        current = self.targets.stamp_ns(self.k)
        if all(self.reported.get(e, -1) >= current for e in self.engines):
            self.publish_next()


def main(args: list[str] | None = None) -> int:
    return run_node(TrajectoryPublisher, args)


if __name__ == "__main__":
    raise SystemExit(main())
