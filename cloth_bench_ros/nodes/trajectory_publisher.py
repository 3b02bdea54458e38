"""Streams the quintic gripper targets of both arms as PoseArray [left, right] and owns /clock."""

from __future__ import annotations

from functools import partial
from pathlib import Path
import time
from typing import Any

from cloth_bench_ros import validation
from cloth_bench_ros.core.cloth_size import grasp_width
from cloth_bench_ros.core.hil_timing import TargetTimeline
from cloth_bench_ros.core.trajectory import full_targets, quaternion_xyz
from cloth_bench_ros.nodes.common import (
    all_subscriptions_matched,
    NAMESPACE,
    node_cloth_size,
    node_keys,
    node_task,
    publish_serialises,
    publishers_matched,
    run_node,
)
from cloth_bench_ros.nodes.message_pool import MessagePool
from cloth_bench_ros.runtime import (
    Clock,
    declare_fixed,
    declare_option,
    Header,
    make_qos,
    Node,
    PointCloud2,
    Pose,
    PoseArray,
    stamp_ns,
    steady_clock,
    Time,
)
from cloth_bench_ros.safe_io import atomic_write_text
import numpy as np

PREROLL_RESEND_S = (
    0.5  # real time: the start-up handshake's target 0 is sent again after this long
)
LOCKSTEP_RESEND_S = (
    1.0  # lockstep: a target whose states have not all come back is sent again after this long
)


class TrajectoryPublisher(Node):
    """Publishes target k; in lockstep, target k+1 once every simulator has published state k."""

    def __init__(self, **kwargs) -> None:
        super().__init__(
            'trajectory_publisher', namespace=kwargs.pop('namespace', NAMESPACE), **kwargs
        )
        task = node_task(self)
        rate_hz = declare_option(self, 'rate_hz')
        self.pacing = declare_option(self, 'pacing')
        declare_fixed(self, 'engines')
        declare_fixed(self, 'wait_for_recorder')
        declare_fixed(self, 'wait_for_evaluator')
        # Every value through the one validation layer; an error names the node and parameter.
        p = validation.node_parameters(
            self,
            {
                'engines': validation.unique,
                'wait_for_recorder': validation.boolean,
                'wait_for_evaluator': validation.boolean,
            },
        )
        self.engines = p['engines']
        self.wait_for_recorder, self.wait_for_evaluator = (
            p['wait_for_recorder'],
            p['wait_for_evaluator'],
        )
        self.timing_log = declare_fixed(self, 'timing_log')
        duration = declare_option(self, 'duration')
        self.targets = full_targets(task, rate_hz, grasp_width(node_cloth_size(self)))
        # duration > 0: only the targets of the first `duration` seconds (short real-time checks).
        self.n_targets = (
            min(len(self.targets), int(duration * rate_hz) + 1)
            if duration > 0
            else len(self.targets)
        )
        tg = self.targets
        self.target_stamps = [tg.stamp_ns(k) for k in range(len(tg))]
        self.euler = np.stack([tg.roll, tg.pitch, tg.yaw], axis=1)  # per target: one row to read
        self.target_pub = self.create_publisher(PoseArray, 'targets', make_qos(10))
        self.clock_pub = self.create_publisher(Clock, '/clock', make_qos(10))
        self.state_subs = {
            engine: self.create_subscription(
                PointCloud2, f'{engine}/cloud', partial(self.on_state, engine), make_qos(10)
            )
            for engine in self.engines
        }
        self.k = -1
        self.reported: dict[str, int] = {}
        self.done = False
        self.pace_timer: Any = None  # a Timer while the real-time schedule runs
        # Realtime: the controller's view of each target (due, sent, state received), per engine.
        stamps = np.array(self.target_stamps[: self.n_targets], dtype=np.int64)
        self.timelines = {engine: TargetTimeline(stamps) for engine in self.engines}
        self.period_ns = round(1e9 / rate_hz)
        # Where publish serialises, one target message refilled before each send; the embedded
        # intra-process transport hands subscribers the object itself: a pool there.
        self.target_pool = MessagePool(self._new_target_msg, in_place=publish_serialises(self))
        self.wait_until_ns: int | None = None
        self.preroll_sent_ns: int | None = (
            None  # real time: when the start-up handshake's target 0 went out
        )
        self.sent_ns = 0  # lockstep: when the newest target went out (steady clock)
        self.resend_timer: Any = None  # a Timer in lockstep
        self.start_timer = self.create_timer(0.02, self.try_start)

    def graph_ready(self) -> bool:
        """
        Who is there, by node, not how many subscribers.

        For each engine a node that subscribes `targets` and publishes `<engine>/cloud`, matched
        both ways; the recorder (publishes real/cloud, follows /clock) with every /clock
        subscription matched; the evaluator (subscribes `targets`, publishes `metrics` once its
        inputs are matched); every `targets` subscription matched.
        """
        target_readers = node_keys(self.get_subscriptions_info_by_topic('targets'))
        for engine, sub in self.state_subs.items():
            simulators = target_readers & node_keys(
                self.get_publishers_info_by_topic(f'{engine}/cloud')
            )
            if not simulators or not publishers_matched(self, sub):
                return False
        if not all_subscriptions_matched(self, self.target_pub):
            return False
        if self.wait_for_recorder:
            clock_readers = node_keys(self.get_subscriptions_info_by_topic('/clock'))
            if not clock_readers & node_keys(self.get_publishers_info_by_topic('real/cloud')):
                return False
            if not all_subscriptions_matched(self, self.clock_pub):
                return False
        return not self.wait_for_evaluator or bool(
            target_readers & node_keys(self.get_publishers_info_by_topic('metrics'))
        )

    def try_start(self) -> None:
        """Start once the graph is complete (graph_ready); polled on a timer until then."""
        if not self.graph_ready():
            return
        if self.pacing == 'realtime':
            self.send_preroll()
            return
        self.destroy_timer(self.start_timer)
        self.publish_next()
        # Under DDS a first sample can be lost before a reader has matched; a lockstep graph would
        # then wait for ever. The newest target goes out again until its states are back (a
        # simulator answers a repeated target with its state, without a step).
        self.resend_timer = self.create_timer(
            LOCKSTEP_RESEND_S / 4, self.resend_if_stalled, clock=steady_clock()
        )

    def resend_if_stalled(self) -> None:
        """Lockstep: send target k and /clock again when nothing moved for LOCKSTEP_RESEND_S."""
        if self.done:
            self.destroy_timer(self.resend_timer)
            return
        if time.monotonic_ns() - self.sent_ns > LOCKSTEP_RESEND_S * 1e9:
            self.sent_ns = time.monotonic_ns()
            msg = self._target(self.k)
            self.clock_pub.publish(Clock(clock=msg.header.stamp))
            self.target_pub.publish(msg)

    @staticmethod
    def _new_target_msg() -> PoseArray:
        return PoseArray(header=Header(frame_id='world'), poses=[Pose(), Pose()])

    def _target(self, k: int) -> PoseArray:
        """Target k as a message (filled in place, or taken from the pool)."""
        msg = self.target_pool.take()
        msg.header.stamp = Time(nanoseconds=self.target_stamps[k]).to_msg()
        qx, qy, qz, qw = quaternion_xyz(*self.euler[k].tolist())
        for pose, position in zip(msg.poses, (self.targets.left[k], self.targets.right[k])):
            pose.position.x, pose.position.y, pose.position.z = position.tolist()
            pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w = (
                qx,
                qy,
                qz,
                qw,
            )
        return msg

    def publish_next(self) -> None:
        if self.k + 1 >= self.n_targets:
            self.done = True
            return
        self.k += 1
        msg = self._target(self.k)
        if self.pacing != 'realtime':
            self.sent_ns = time.monotonic_ns()
            self.clock_pub.publish(Clock(clock=msg.header.stamp))
            self.target_pub.publish(msg)
            return
        now = time.monotonic_ns()
        for timeline in self.timelines.values():
            timeline.sent[self.k] = now
        self.target_pub.publish(msg)
        self.clock_pub.publish(
            Clock(clock=msg.header.stamp)
        )  # after the target: /clock serves the observer

    # --- realtime: targets on the wall-clock schedule, as a controller sends them --------------

    def send_preroll(self) -> None:
        """
        Start-up handshake before the first deadline: target 0 until each simulator answers it.

        Target 0 is sent again every PREROLL_RESEND_S (first samples on new DDS readers and writers
        take milliseconds; a simulator answers a repeated target with its state, without a step).
        The answer starts the schedule (on_state -> start_realtime).
        """
        now = time.monotonic_ns()
        if self.preroll_sent_ns is None or now - self.preroll_sent_ns > PREROLL_RESEND_S * 1e9:
            self.preroll_sent_ns = now
            msg = self._target(0)
            self.target_pub.publish(msg)
            self.clock_pub.publish(Clock(clock=msg.header.stamp))

    def start_realtime(self) -> None:
        """
        Anchor the schedule now, when target 0's state is in: target k is due k / rate from here.

        Target 0 is the handshake's: sent, due and answered at the anchor (the initial state, not
        a deadline); target 1 goes out one period later.
        """
        # On the steady clock, as the schedule: a step of the system clock must not move a
        # deadline.
        self.pace_timer = self.create_timer(
            1.0 / self.targets.rate_hz, self.publish_due, clock=steady_clock()
        )
        now = time.monotonic_ns()
        for timeline in self.timelines.values():
            timeline.start(now)
            timeline.sent[0] = timeline.received[0] = now
        self.k = 0
        self.publish_due()

    def publish_due(self) -> None:
        """Send every target due by now, in order (a late tick catches up); then await states."""
        last = self.n_targets - 1
        if self.k < last:
            due = min(
                next(iter(self.timelines.values())).due_through(
                    time.monotonic_ns(), self.period_ns
                ),
                last,
            )
            while self.k < due:
                self.publish_next()
            if self.k == last:
                # The last states may take a while to come back; a state that never does is lost.
                self.wait_until_ns = time.monotonic_ns() + max(1_000_000_000, 100 * self.period_ns)
        waited = self.wait_until_ns is not None and time.monotonic_ns() > self.wait_until_ns
        if self.k == last and (self.all_states_back() or waited):
            self.finish_realtime()

    def all_states_back(self) -> bool:
        return all(t.received[-1] >= 0 for t in self.timelines.values())

    def finish_realtime(self) -> None:
        """Stop the schedule and write each engine's timeline (`timing_log` directory) if asked."""
        if self.pace_timer is not None:
            self.destroy_timer(self.pace_timer)
            self.pace_timer = None
        if self.timing_log:
            Path(self.timing_log).mkdir(parents=True, exist_ok=True)
            for engine, timeline in self.timelines.items():
                atomic_write_text(
                    Path(self.timing_log) / f'timeline_{engine}.csv', timeline.to_csv()
                )
        self.done = True

    def on_state(self, engine: str, msg: PointCloud2) -> None:
        self.reported[engine] = stamp_ns(msg.header.stamp)
        if self.pacing == 'realtime' and self.k < 0:
            if all(self.reported.get(e) == self.targets.stamp_ns(0) for e in self.engines):
                self.destroy_timer(self.start_timer)
                # every simulator answered the handshake: the schedule starts
                self.start_realtime()
            return
        if self.pacing == 'realtime':
            self.timelines[engine].mark_received(self.reported[engine], time.monotonic_ns())
            if self.k == self.n_targets - 1 and not self.done and self.all_states_back():
                self.finish_realtime()
            return
        if self.k < 0:
            return
        current = self.targets.stamp_ns(self.k)
        if all(self.reported.get(e, -1) >= current for e in self.engines):
            self.publish_next()


def main(args: list[str] | None = None) -> int:
    return run_node(TrajectoryPublisher, args)


if __name__ == '__main__':
    raise SystemExit(main())
