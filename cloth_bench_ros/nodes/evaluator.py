"""Scores every real frame against each simulator's state of the same stamp, online."""

from __future__ import annotations

from functools import partial
import json
from pathlib import Path
import time
from typing import Any

from cloth_bench_ros import validation
from cloth_bench_ros.core.cloth_mesh import cloth_faces, ClothMesh, mesh_record, run_cloth
from cloth_bench_ros.core.cloth_size import cloth_record, grasp_width
from cloth_bench_ros.core.evaluation import accounting_line, OnlineEvaluator
from cloth_bench_ros.core.pointcloud2 import drop_nan, read_xyz
from cloth_bench_ros.core.run_files import write_run_report
from cloth_bench_ros.core.run_summary import run_summary
from cloth_bench_ros.core.scene import ClothGrid, REAL_FPS
from cloth_bench_ros.core.trajectory import full_targets, parse_primitive
from cloth_bench_ros.core.worst_frames import write_worst_frames
from cloth_bench_ros.data.trial import trial_from_message
from cloth_bench_ros.engines.settle import FULL
from cloth_bench_ros.nodes.common import (
    NAMESPACE,
    node_cloth,
    node_cloth_mesh,
    node_grid,
    node_task,
    publishers_matched,
    replay_stamps,
    run_node,
)
from cloth_bench_ros.nodes.comparison import write_comparison
from cloth_bench_ros.nodes.error_topics import declare_live_parameters, ErrorTopics
from cloth_bench_ros.runtime import (
    declare_fixed,
    declare_float,
    declare_option,
    DiagnosticArray,
    DiagnosticStatus,
    KeyValue,
    make_qos,
    Node,
    PointCloud2,
    PoseArray,
    stamp_ns,
    steady_clock,
)
from cloth_bench_ros.safe_io import check_output_dir, UnsafeInputError


def _values(msg: DiagnosticArray) -> dict[str, str]:
    return {kv.key: kv.value for status in msg.status for kv in status.values}


class Evaluator(Node):
    """Publishes per-frame CD/HD and the final summary on `metrics`; writes JSON and CSV."""

    def __init__(self, **kwargs) -> None:
        super().__init__('evaluator', namespace=kwargs.pop('namespace', NAMESPACE), **kwargs)
        declare_fixed(self, 'engines')
        self.task = node_task(self)
        # False while a composed graph is still being built: a node that fails to start then
        # says why in one line, and this one has nothing to add
        self.graph_started = True
        self.primitive = parse_primitive(self.get_parameter('primitive').value)
        rate_hz = declare_option(self, 'rate_hz')
        declare_float(self, 'time_offset', self.task.settle_duration)
        cut = declare_option(self, 'change_of_phase_frame')
        self.output_dir = declare_fixed(self, 'output_dir')
        self.comparison_bag = declare_option(self, 'record_comparison')
        declare_fixed(self, 'comparison_figures')
        cloth = declare_option(self, 'cloth')
        seed = declare_option(self, 'seed')
        # the simulators' grid (0: the default), whose triangles the surface metrics are on
        nx, nz = node_grid(self)
        size, mass = node_cloth(self)  # recorded in the summary; the mesh's extent
        # The engines' devices, comma-separated in the order of `engines` ('' : not recorded).
        devices = str(declare_fixed(self, 'devices'))
        models = str(declare_fixed(self, 'models'))  # the engines' models, likewise
        # Every value through the one validation layer; an error names the node and parameter.
        p = validation.node_parameters(
            self,
            {
                'time_offset': validation.time_offset,
                'engines': validation.unique,
                'comparison_figures': validation.boolean,
            },
        )
        targets = full_targets(self.task, rate_hz, grasp_width(size))
        grid = run_cloth((nx, nz) if nx and nz else None, size, node_cloth_mesh(self),
                         self.task, rate_hz) or ClothGrid()
        self.engines, offset = p['engines'], p['time_offset']
        self.comparison_figures = p['comparison_figures']
        self.run_info = {
            'primitive': self.primitive.value,
            **self.task.record(),
            'rate_hz': rate_hz,
            'engines': self.engines,
            'cloth': cloth,
            'seed': seed,
            'settle': FULL,  # the simulator nodes step every target (engines/settle.py)
            **cloth_record(size, mass),
            **mesh_record(grid),
        }
        for key, text in (('devices', devices), ('models', models)):
            if not text:
                continue
            names = text.split(',')
            if key == 'devices':
                names = [validation.device(d, 'parameter devices') for d in names]
            if len(names) != len(self.engines):
                raise validation.InputError(
                    f'evaluator: parameter {key}: {len(names)} {key} for'
                    f' {len(self.engines)} engines'
                )
            self.run_info[key] = dict(zip(self.engines, names))
        if self.output_dir:  # an unwritable report directory is found now, not after the run
            try:
                check_output_dir(self.output_dir)
            except UnsafeInputError as exc:
                raise validation.InputError(f'evaluator: parameter output_dir: {exc}') from None
        self.final_stamp = targets.stamp_ns(len(targets) - 1)
        self.core = OnlineEvaluator(
            self.engines,
            self.task,
            int(round(offset * 1e9)),
            cut,
            REAL_FPS,
            keep_pairs=bool(self.comparison_bag or self.comparison_figures),
            faces=cloth_faces(grid),
        )
        # the cloth's triangles for the comparison outputs and the live view (None: the grid's)
        self.faces = cloth_faces(grid) if isinstance(grid, ClothMesh) else None
        self.replay: dict = {}  # the recorder's frame accounting, from the trial message
        self.expected_real_frames: int | None = None  # as announced by the recorder
        # Inputs keep every sample until taken: a slow evaluator delays, never loses, a frame.
        data_qos = make_qos(100, keep_all=True)
        self.inputs = [
            self.create_subscription(PointCloud2, 'real/cloud', self.on_real, data_qos),
            self.create_subscription(
                DiagnosticArray, 'real/trial', self.on_trial, make_qos(1, latched=True)
            ),
        ]
        for engine in self.engines:
            self.inputs.append(
                self.create_subscription(
                    PointCloud2, f'{engine}/cloud', partial(self.on_state, engine), data_qos
                )
            )
            self.inputs.append(
                self.create_subscription(
                    DiagnosticArray, f'{engine}/step_time', partial(self.on_step, engine), data_qos
                )
            )
        # Ready (the `metrics` publisher appears, which the trajectory publisher waits for) once
        # every input is matched with a publisher and the recorder's trial (and replay)
        # announcement is in.
        self.metrics_pub: Any = None  # a Publisher once the inputs are matched
        self.trial_received = False
        self.expected_real: set[int] | None = None  # announced stamps up to the last target
        self.received_real: set[int] = set()
        self.ready_timer = self.create_timer(0.02, self.check_ready, clock=steady_clock())
        # Latency: lockstep measures from each target's arrival; realtime from the wall-clock
        # schedule the targets should have kept (first target + sim time), so a simulator that
        # falls behind shows its queueing delay too.
        self.realtime = declare_option(self, 'pacing') == 'realtime'
        self.create_subscription(PoseArray, 'targets', self.on_target, make_qos(100))
        self.period_s = 1.0 / rate_hz
        self.target_sent: dict[int, int] = {}  # stamp -> monotonic ns when the target arrived
        self.first_target_ns: int | None = None
        self.schedule_known = False  # real time: the schedule read off a target after the first
        self.first_target_stamp = 0
        self.trial: dict = {}
        self.published_scores = 0
        self.summary: dict | None = None
        self.done = False
        self.exit_status = 0  # 1: the frame accounting does not add up (main() returns it)
        # Error cloud, frame and step metrics on the graph's topics and the live view (last: a
        # live view's port in use is one line, and nothing after it can fail).
        self.error_topics = ErrorTopics(
            self,
            self.engines,
            self.task,
            rate_hz,
            self.core.quintic_start_ns,
            self.realtime,
            declare_live_parameters(self),
            self.faces,
        )
        self.core.listeners.append(self.error_topics.scored)

    def check_ready(self) -> None:
        if (
            self.trial_received
            and all(publishers_matched(self, sub) for sub in self.inputs)
            and self.error_topics.ready_to_start()
        ):
            self.destroy_timer(self.ready_timer)
            self.metrics_pub = self.create_publisher(DiagnosticArray, 'metrics', make_qos(100))
            self.publish_scores()

    def on_trial(self, msg: DiagnosticArray) -> None:
        self.trial_received = True
        stamps = replay_stamps(msg)
        if stamps is not None:
            self.expected_real = {s for s in stamps if s <= self.final_stamp}
        values = _values(msg)
        if 'replay' in values:
            self.replay = json.loads(values['replay'])
        if 'frames_to_send' in values:
            self.expected_real_frames = int(values['frames_to_send'])
        trial = trial_from_message(msg)
        if trial is None:
            return
        self.trial = trial.to_dict()
        if self.core.change_of_phase_frame is None:
            self.core.change_of_phase_frame = trial.change_of_phase_frame
        if trial.primitive != self.primitive.value:
            self.get_logger().warning(
                f'bag holds a {trial.primitive} trial, scored as {self.primitive.value}'
            )

    def on_real(self, msg: PointCloud2) -> None:
        points, dropped = drop_nan(read_xyz(msg))
        self.core.add_real(stamp_ns(msg.header.stamp), points, dropped)
        self.received_real.add(stamp_ns(msg.header.stamp))
        self.publish_scores()
        self.finish_if_complete()

    def on_target(self, msg: PoseArray) -> None:
        now, stamp = time.monotonic_ns(), stamp_ns(msg.header.stamp)
        if self.first_target_ns is None or (self.realtime and stamp == self.first_target_stamp):
            self.first_target_ns, self.first_target_stamp = now, stamp
        elif self.realtime and not self.schedule_known:
            # The first target may be a start-up handshake, sent well before the schedule starts:
            # the schedule is read off the second target.
            self.first_target_ns, self.schedule_known = (
                now - (stamp - self.first_target_stamp),
                True,
            )
        elif self.realtime:
            # The schedule starts at the earliest arrival less its sim time: a target that reached
            # this node late must not shift every later deadline (negative latencies).
            self.first_target_ns = min(
                self.first_target_ns, now - (stamp - self.first_target_stamp)
            )
        if not self.realtime:
            self.target_sent[stamp] = now

    def on_state(self, engine: str, msg: PointCloud2) -> None:
        stamp = stamp_ns(msg.header.stamp)
        if self.realtime and self.first_target_ns is not None:
            due = self.first_target_ns + (stamp - self.first_target_stamp)
            latency = (time.monotonic_ns() - due) / 1e9
            self.core.add_latency(engine, latency)
            self.error_topics.state_latency(engine, stamp, latency)
        elif stamp in self.target_sent:
            latency = (time.monotonic_ns() - self.target_sent[stamp]) / 1e9
            self.core.add_latency(engine, latency)
            self.error_topics.state_latency(engine, stamp, latency)
            if len(self.engines) == 1:
                del self.target_sent[stamp]
        self.core.add_state(engine, stamp, read_xyz(msg))
        self.publish_scores()
        self.finish_if_complete()

    def on_step(self, engine: str, msg: DiagnosticArray) -> None:
        v = _values(msg)
        self.core.add_step(
            engine,
            stamp_ns(msg.header.stamp),
            int(v['step']),
            float(v['step_time']),
            v['diverged'] == 'true',
            msg.status[0].message,
            int(v.get('skipped_targets') or 0),
        )
        self.error_topics.step(engine, stamp_ns(msg.header.stamp), float(v['step_time']))
        self.finish_if_complete()

    def finish_if_complete(self) -> None:
        """
        Finish once every engine's last state and step and every announced real frame are in.

        DDS gives no order across topics: they may arrive in any order.
        """
        expected = self.expected_real
        frames_in = expected is None or (  # the size first: a subset test per state is not free
            len(expected) <= len(self.received_real) and expected <= self.received_real
        )
        if frames_in and self.core.complete(self.final_stamp):
            self.finish()

    def publish_scores(self) -> None:
        if self.metrics_pub is None:  # not ready yet: published once it is
            return
        new = self.core.scores[self.published_scores:]
        self.published_scores = len(self.core.scores)
        for s in new:
            status = DiagnosticStatus(
                level=DiagnosticStatus.ERROR if s.diverged else DiagnosticStatus.OK,
                name=f'cloth_bench/{s.engine}/frame',
                message=f'frame {s.frame}',
                hardware_id=s.engine,
                values=[
                    KeyValue(key=k, value=repr(v))
                    for k, v in (
                        ('frame', s.frame),
                        ('t', s.t),
                        ('cd', s.cd),
                        ('hd', s.hd),
                        ('in_window', s.in_window),
                    )
                ],
            )
            self.metrics_pub.publish(DiagnosticArray(status=[status]))

    def waiting_for(self) -> list[str]:
        """Return what the run still waits for before it can end (empty once it can)."""
        missing = []
        if not self.trial_received:
            missing.append("the recorder's trial announcement")
        elif self.expected_real is not None and not self.expected_real <= self.received_real:
            lost = self.expected_real - self.received_real
            missing.append(
                f'{len(lost)} of {len(self.expected_real)} announced real frames'
                f' (the first at {min(lost) / 1e9:.3f} s)'
            )
        for name, e in self.core.engines.items():
            if min(e.last_stamp, e.last_step_stamp) < self.final_stamp:
                missing.append(
                    f"{name}'s state and step at the last target (so far"
                    f' {max(e.last_stamp, 0) / 1e9:.3f} s and'
                    f' {max(e.last_step_stamp, 0) / 1e9:.3f} s of {self.final_stamp / 1e9:.3f} s)'
                )
        return missing

    def close(self) -> None:
        """Say what the run was waiting for when it is stopped before its end (signal or hang)."""
        self.error_topics.close()
        if not self.done and self.graph_started:
            waiting = '; '.join(self.waiting_for()) or 'nothing more'
            self.get_logger().warning(f'stopped before the run ended, waiting for {waiting}')

    def finish(self) -> None:
        """Close the run: summary on `metrics`, report files, done."""
        if self.done:
            return
        if self.metrics_pub is None:
            self.destroy_timer(self.ready_timer)
            self.metrics_pub = self.create_publisher(DiagnosticArray, 'metrics', make_qos(100))
            self.publish_scores()
        wall_s = (
            (time.monotonic_ns() - self.first_target_ns) / 1e9 if self.first_target_ns else None
        )
        run = {**self.run_info, 'trial': self.trial}
        self.summary = run_summary(
            self.core, self.replay, run, self.period_s, wall_s, self.final_stamp
        )
        accounting = self.summary['real']['accounting']
        if not accounting[
            'adds_up'
        ]:  # frames from another graph, or lost ones: the run is not valid
            self.exit_status = 1
            self.get_logger().error(accounting_line(accounting))
        statuses = []
        for engine, m in self.summary['engines'].items():
            flat = {k: v for k, v in m.items() if not isinstance(v, dict)}
            for group in ('step_time', 'latency'):
                flat.update({f'{group}_{k}': v for k, v in m[group].items()})
            statuses.append(
                DiagnosticStatus(
                    level=DiagnosticStatus.ERROR if m['diverged'] else DiagnosticStatus.OK,
                    name=f'cloth_bench/{engine}/summary',
                    message='diverged' if m['diverged'] else 'ok',
                    hardware_id=engine,
                    values=[KeyValue(key=k, value=str(v)) for k, v in flat.items()],
                )
            )
        self.metrics_pub.publish(DiagnosticArray(status=statuses))
        if self.comparison_bag or (self.comparison_figures and self.output_dir):
            self.summary['comparison'] = write_comparison(
                self.core.pairs,
                self.summary,
                Path(self.comparison_bag) if self.comparison_bag else None,
                Path(self.output_dir) if self.comparison_figures and self.output_dir else None,
                self.task,
                self.faces,
            )
        if self.output_dir:
            write_run_report(Path(self.output_dir), self.summary, self.core.scores)
            write_worst_frames(Path(self.output_dir), self.core.worst)
            self.get_logger().info(f'report written to {self.output_dir}')
        self.done = True


def main(args: list[str] | None = None) -> int:
    return run_node(Evaluator, args)


if __name__ == '__main__':
    raise SystemExit(main())
