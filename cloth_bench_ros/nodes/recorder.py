"""
Replays a rosbag2 MCAP bag's PointCloud2 topic in simulation time, or records topics to a bag.

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

import errno
from functools import partial
import json
import shutil
import time

from cloth_bench_ros import validation
from cloth_bench_ros.core.cloth_mesh import mesh_area, run_cloth
from cloth_bench_ros.core.cloth_size import grasp_width
from cloth_bench_ros.core.pointcloud2 import create_cloud_xyz32
from cloth_bench_ros.data import BagReader, BagWriter
from cloth_bench_ros.data.alignment import reference_motion, SearchSettings
from cloth_bench_ros.data.replay import plan_replay, replay_task, ReplayOptions
from cloth_bench_ros.data.trial import TRIAL_STATUS_NAME
from cloth_bench_ros.engines import make_engine
from cloth_bench_ros.engines.presets import load_preset, sized_params
from cloth_bench_ros.errors import ClothBenchError
from cloth_bench_ros.errors import InputError
from cloth_bench_ros.nodes.common import (
    NAMESPACE,
    node_cloth,
    node_cloth_mesh,
    node_grid,
    REPLAY_STATUS_NAME,
    run_node,
)
from cloth_bench_ros.options import REPLAY_OPTIONS
from cloth_bench_ros.runtime import (
    Clock,
    declare_fixed,
    declare_float,
    declare_option,
    DiagnosticArray,
    DiagnosticStatus,
    Header,
    KeyValue,
    make_qos,
    message_type,
    Node,
    PointCloud2,
    PointField,
    serialize_message,
    stamp_ns,
    steady_clock,
    Time,
)

MAX_RATE_FACTOR = 1e6  # wall-clock replay speed
# Record mode on a filling disk: stop while the open chunk (<= 1 MiB), the summary and
# metadata.yaml still fit; a small reserve file keeps room for metadata.yaml if another
# process fills the disk first.
DISK_MARGIN_BYTES = 4 * 1024 * 1024
DISK_CHECK_EVERY_BYTES = 256 * 1024
RESERVE_NAME = '.cloth_bench_reserve'
RESERVE_BYTES = 64 * 1024


class RecordingStopped(ClothBenchError, ValueError):
    """A recording that cannot go on (disk full, write error); str() is one line naming the bag."""


class Recorder(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__('recorder', namespace=kwargs.pop('namespace', NAMESPACE), **kwargs)
        self.mode = declare_fixed(self, 'mode')
        self.done = False
        self.writer: BagWriter | None = None
        self.bag: BagReader | None = None  # replay: closed by close()
        if self.mode == 'record':
            self.start_recording()
        elif self.mode == 'replay':
            self.start_replay()
        else:
            raise InputError(f'recorder: unknown mode {self.mode!r} (valid: replay, record)')

    # --- replay ------------------------------------------------------------------------------

    def start_replay(self) -> None:
        path = declare_fixed(self, 'bag')
        if not path:
            raise InputError("recorder: parameter 'bag' is empty (path to a rosbag2 MCAP bag)")
        options = self.replay_options()
        # Frames are stamped from the start of the task's motion; the run starts with its settle
        # phase.
        declare_float(self, 'time_offset', replay_task(options).settle_duration)
        clock = declare_fixed(self, 'clock')
        declare_float(self, 'rate_factor')
        declare_float(self, 'start_offset')
        declare_fixed(self, 'loop')
        # Every value through the one validation layer; an error names the node and parameter.
        p = validation.node_parameters(
            self,
            {
                'time_offset': validation.time_offset,
                'start_offset': validation.time_offset,
                'rate_factor': lambda v, n: validation.positive(v, n, MAX_RATE_FACTOR),
                'loop': validation.boolean,
            },
        )
        self.offset_ns = int(round(p['time_offset'] * 1e9))
        self.start_offset_ns = int(round(p['start_offset'] * 1e9))
        self.rate_factor, self.loop = p['rate_factor'], p['loop']
        if clock not in ('sim', 'wall'):
            raise InputError(f'recorder: unknown clock {clock!r} (valid: sim, wall)')
        self.bag = BagReader(path)
        nx, nz = node_grid(self)  # 0, 0: the preset's grid
        # the size, mass and mesh of the alignment's reference cloth
        cloth = (*node_cloth(self), node_cloth_mesh(self))
        try:
            self.plan = plan_replay(
                self.bag, options, partial(self.reference_motion, options, nx, nz, cloth)
            )
        except BaseException:
            self.bag.close()  # a node that fails to start is never closed by its main
            raise
        self.topic = self.plan.topic
        self.plan_bag = self.bag.path
        self.published = 0
        # Keep-all, as the evaluator's reader: a keep-last writer drops the frames a slow reader
        # has not acknowledged yet (DDS), and the evaluator waits for every announced frame.
        self.cloud_pub = self.create_publisher(
            PointCloud2, 'real/cloud', make_qos(100, keep_all=True)
        )
        self.trial_pub = self.create_publisher(
            DiagnosticArray, 'real/trial', make_qos(1, latched=True)
        )
        self.rewind()
        trial = self.trial_message()
        if clock == 'sim':
            trial.status.append(self.replay_status())
        self.trial_pub.publish(trial)
        if clock == 'sim':
            self.create_subscription(Clock, '/clock', self.on_clock, make_qos(10))
        else:
            self.wall_start_ns = time.monotonic_ns()
            self.wall_timer = self.create_timer(
                0.001, self.on_wall_tick, clock=steady_clock()
            )  # not sim time

    def replay_options(self) -> ReplayOptions:
        """Return what the bag does not say, from the node's parameters."""
        transform = list(declare_fixed(self, 'transform'))
        if transform != [0.0] and len(transform) != 16:
            raise InputError(
                f'recorder: transform needs 16 numbers (a 4x4 matrix), got {len(transform)}'
            )
        p = {name: declare_option(self, name) for name in (*REPLAY_OPTIONS, 'rate_hz')}
        search = SearchSettings(window=p['align_window'], coarse_step=p['align_step'])
        return ReplayOptions(
            cloth=declare_option(self, 'cloth'),
            primitive=declare_option(self, 'primitive'),
            task=declare_option(self, 'task'),
            motion=p['motion'],
            change_of_phase_frame=p['change_of_phase_frame'],
            topic=p['topic'],
            start_time=p['start_time'],
            targets_topic=p['targets_topic'],
            transform=tuple(transform) if len(transform) == 16 else None,
            clean=p['clean'],
            voxel=p['voxel'],
            table_plane=p['table_plane'],
            rate_hz=p['rate_hz'],
            align_engine=declare_option(self, 'align_engine'),
            search=search,
            trial=p['trial'],
            align=p['align'],
        )

    @staticmethod
    def reference_motion(
        options: ReplayOptions, nx: int, nz: int, cloth: tuple, seconds: float
    ) -> tuple:
        """Return the reference simulation the automatic alignment compares the bag with."""
        size, mass, mesh = cloth
        preset = load_preset(options.align_engine, options.cloth, options.primitive)
        grid = run_cloth((nx, nz) if nx and nz else None, size, mesh, replay_task(options),
                         options.rate_hz)
        engine = make_engine(
            options.align_engine, options.rate_hz,
            sized_params(options.align_engine, preset, size, mass, mesh_area(grid)), grid,
        )
        try:
            return reference_motion(
                engine, replay_task(options), options.rate_hz, seconds, width=grasp_width(size)
            )
        finally:
            engine.close()

    @property
    def frames_to_send(self) -> int:
        """How many real frames this replay publishes (the evaluator waits for as many)."""
        return len(self.plan.frames)

    def rewind(self) -> None:
        skipped = sum(1 for t, _ in self.plan.frames if t < self.start_offset_ns)
        self.plan.counts['skipped_by_start_offset'] = skipped
        self.frames = iter([f for f in self.plan.frames if f[0] >= self.start_offset_ns])
        self.next_frame = next(self.frames, None)
        self.done = self.next_frame is None

    def trial_message(self) -> DiagnosticArray:
        """Return the trial (cloth, primitive, change of phase) and the replay's accounting."""
        info = self.plan.trial.to_strings()
        info['replay'] = json.dumps(self.plan.accounting())
        info['frames_to_send'] = str(
            self.frames_to_send - self.plan.counts['skipped_by_start_offset']
        )
        values = [KeyValue(key=k, value=v) for k, v in info.items()]
        status = DiagnosticStatus(
            level=DiagnosticStatus.OK,
            name=TRIAL_STATUS_NAME,
            message=str(self.plan_bag),
            hardware_id='recorder',
            values=values,
        )
        return DiagnosticArray(status=[status])

    def replay_status(self) -> DiagnosticStatus:
        """Return the run-time stamps of every frame the sim-clock replay will send."""
        stamps = [t + self.offset_ns for t, _ in self.plan.frames if t >= self.start_offset_ns]
        return DiagnosticStatus(
            level=DiagnosticStatus.OK,
            name=REPLAY_STATUS_NAME,
            hardware_id='recorder',
            message=f'{len(stamps)} frames, sent as /clock reaches their stamps',
            values=[
                KeyValue(key='frames', value=str(len(stamps))),
                KeyValue(key='stamps_ns', value=','.join(map(str, stamps))),
            ],
        )

    def publish_until(self, t_ns: int, restamp_offset_ns: int) -> None:
        """Publish every frame at or before t_ns (from the motion's start), restamped."""
        while self.next_frame is not None:
            frame_t, points = self.next_frame
            if frame_t > t_ns:
                break
            header = Header(
                stamp=Time(nanoseconds=frame_t + restamp_offset_ns).to_msg(), frame_id='world'
            )
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
        output = declare_fixed(self, 'output')
        entries = list(declare_fixed(self, 'record_topics'))
        if not output:
            raise InputError(
                "recorder: parameter 'output' is empty (bag directory to record into)"
            )
        topics = [e.rsplit(':', 1) for e in entries if e]
        if not topics or any(len(t) != 2 for t in topics):
            raise InputError("recorder: record_topics needs entries 'topic:package/msg/Type'")
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
            self.create_subscription(
                msg_type, topic, partial(self.on_record, name, typename), make_qos(1000)
            )
        self.get_logger().info(f'recording {", ".join(t for t, _ in topics)} to {output}')

    def on_record(self, topic: str, typename: str, msg) -> None:
        self.received += 1
        if self.stopped:
            return  # counted as received, not written
        cdr = serialize_message(msg)
        writer = self.writer
        assert writer is not None  # on_record is subscribed only when recording
        self.unchecked_bytes += len(cdr)
        if self.unchecked_bytes >= DISK_CHECK_EVERY_BYTES:
            self.unchecked_bytes = 0
            free = shutil.disk_usage(writer.path).free
            if free < DISK_MARGIN_BYTES:  # stop while the bag can still be finished cleanly
                self.stop_recording(
                    OSError(errno.ENOSPC, f'disk nearly full, {free} bytes left'), False
                )
        try:
            # As rosbag2 records: log time is the receive time, the header stamp stays in the
            # message.
            writer.write(
                topic, typename, 0, cdr, log_time_ns=self.get_clock().now().nanoseconds
            )
        except OSError as exc:
            self.stop_recording(exc, failed_write=True)

    def stop_recording(self, exc: OSError, failed_write: bool) -> None:
        """
        End the recording on a full disk or write error.

        What is on disk is finalised, then one error line.

        After a failed write the MCAP writer's state no longer matches the file, so the bag is
        kept as written (`BagWriter.abandon`) instead of finished over the gap.
        """
        self.stopped = True
        self.reserve.unlink(missing_ok=True)
        writer = self.writer
        assert writer is not None  # stopped only while recording
        if failed_write:
            writer.abandon()
        else:
            self.close_writer()
        reason = exc.strerror or str(exc)
        raise RecordingStopped(
            f'recorder: bag {writer.path}: {reason}; recording stopped, the bag keeps '
            f'the {writer.written} messages written before'
        )

    def close_writer(self) -> None:
        """Finalise the bag; if finishing it fails (disk full), keep what is on disk."""
        writer = self.writer
        assert writer is not None  # closed only when recording
        if not writer.closed:
            try:
                writer.close()
            except OSError:
                writer.abandon()
        self.reserve.unlink(missing_ok=True)

    def close(self) -> None:
        """Close the replayed bag; finalise a recording and report received and written counts."""
        if self.bag is not None:
            self.bag.close()
        if self.writer is not None and not getattr(self, 'reported', False):
            self.reported = True
            self.close_writer()
            report = f'recorder: received {self.received} messages, wrote {self.writer.written}'
            if (
                self.received != self.writer.written and not self.stopped
            ):  # a stop has said so already
                self.get_logger().error(report + ' (some were lost)')
            print(report, flush=True)


def main(args: list[str] | None = None) -> int:
    return run_node(Recorder, args)


if __name__ == '__main__':
    raise SystemExit(main())
