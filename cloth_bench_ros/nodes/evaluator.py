"""Scores every real frame against each simulator's state of the same stamp, online."""

from __future__ import annotations

import time
from functools import partial
from pathlib import Path

from cloth_bench_ros import validation
from cloth_bench_ros.data.bag import trial_from_message
from cloth_bench_ros.core.evaluation import OnlineEvaluator
from cloth_bench_ros.nodes.common import NAMESPACE, run_node
from cloth_bench_ros.core.pointcloud2 import drop_nan, read_xyz
from cloth_bench_ros.report.run_report import write_run_report
from cloth_bench_ros.safe_io import check_output_dir
from cloth_bench_ros.runtime import (
    DiagnosticArray, DiagnosticStatus, KeyValue, Node, PointCloud2, PoseArray, make_qos, stamp_ns,
)
from cloth_bench_ros.core.scene import REAL_FPS, SETTLE_DURATION
from cloth_bench_ros.core.trajectory import full_targets, parse_primitive


def _values(msg: DiagnosticArray) -> dict[str, str]:
    return {kv.key: kv.value for status in msg.status for kv in status.values}


class Evaluator(Node):
    """Publishes per-frame CD/HD and the final summary on `metrics`; writes JSON and CSV."""

    def __init__(self, **kwargs) -> None:
        super().__init__("evaluator", namespace=kwargs.pop("namespace", NAMESPACE), **kwargs)
        self.engines = list(self.declare_parameter("engines", ["mujoco"]).value)
        self.primitive = parse_primitive(self.declare_parameter("primitive", "dynamic").value)
        rate_hz = float(self.declare_parameter("rate_hz", 100.0).value)
        offset = float(self.declare_parameter("time_offset", SETTLE_DURATION).value)
        cut = int(self.declare_parameter("change_of_phase_frame", -1).value)
        self.output_dir = self.declare_parameter("output_dir", "").value
        self.run_info = {"primitive": self.primitive.value, "rate_hz": rate_hz, "engines": self.engines,
                         "cloth": self.declare_parameter("cloth", "towel").value,
                         "seed": int(self.declare_parameter("seed", 0).value)}
        # Every value through the one validation layer; an error names the node and parameter.
        validation.node_parameters(self, {
            "rate_hz": validation.rate_hz, "time_offset": validation.time_offset, "seed": validation.seed,
            "engines": validation.unique,
            "change_of_phase_frame": lambda v, n: validation.frame_index(v, n, unset=-1)})
        if self.output_dir:  # an unwritable report directory is found now, not after the run
            try:
                check_output_dir(self.output_dir)
            except ValueError as exc:
                raise validation.InputError(f"evaluator: parameter output_dir: {exc}") from None
        targets = full_targets(self.primitive, rate_hz)
        self.final_stamp = targets.stamp_ns(len(targets) - 1)
        self.core = OnlineEvaluator(self.engines, self.primitive, int(round(offset * 1e9)),
                                    cut if cut >= 0 else None, REAL_FPS)
        self.metrics_pub = self.create_publisher(DiagnosticArray, "metrics", make_qos(100))
        self.create_subscription(PointCloud2, "real/cloud", self.on_real, make_qos(100))
        self.create_subscription(DiagnosticArray, "real/trial", self.on_trial, make_qos(1, latched=True))
        for engine in self.engines:
            self.create_subscription(PointCloud2, f"{engine}/cloud", partial(self.on_state, engine), make_qos(100))
            self.create_subscription(DiagnosticArray, f"{engine}/step_time", partial(self.on_step, engine),
                                     make_qos(100))
        # Latency: lockstep measures from each target's arrival; realtime from the wall-clock
        # schedule the targets should have kept (first target + sim time), so a simulator that
        # falls behind shows its queueing delay too.
        self.realtime = self.declare_parameter("pacing", "lockstep").value == "realtime"
        self.create_subscription(PoseArray, "targets", self.on_target, make_qos(100))
        self.period_s = 1.0 / rate_hz
        self.target_sent: dict[int, int] = {}  # stamp -> monotonic ns when the target arrived
        self.first_target_ns: int | None = None
        self.first_target_stamp = 0
        self.trial: dict = {}
        self.published_scores = 0
        self.summary: dict | None = None
        self.done = False

    def on_trial(self, msg: DiagnosticArray) -> None:
        trial = trial_from_message(msg)
        if trial is None:
            return
        self.trial = trial.to_dict()
        if self.core.change_of_phase_frame is None:
            self.core.change_of_phase_frame = trial.change_of_phase_frame
        if trial.primitive != self.primitive.value:
            self.get_logger().warning(f"bag holds a {trial.primitive} trial, scored as {self.primitive.value}")

    def on_real(self, msg: PointCloud2) -> None:
        points, dropped = drop_nan(read_xyz(msg))
        self.core.add_real(stamp_ns(msg.header.stamp), points, dropped)
        self.publish_scores()

    def on_target(self, msg: PoseArray) -> None:
        now, stamp = time.monotonic_ns(), stamp_ns(msg.header.stamp)
        if self.first_target_ns is None:
            self.first_target_ns, self.first_target_stamp = now, stamp
        if not self.realtime:
            self.target_sent[stamp] = now

    def on_state(self, engine: str, msg: PointCloud2) -> None:
        stamp = stamp_ns(msg.header.stamp)
        if self.realtime and self.first_target_ns is not None:
            due = self.first_target_ns + (stamp - self.first_target_stamp)
            self.core.add_latency(engine, (time.monotonic_ns() - due) / 1e9)
        elif stamp in self.target_sent:
            self.core.add_latency(engine, (time.monotonic_ns() - self.target_sent[stamp]) / 1e9)
            if len(self.engines) == 1:
                del self.target_sent[stamp]
        self.core.add_state(engine, stamp, read_xyz(msg))
        self.publish_scores()
        if self.core.complete(self.final_stamp):
            self.finish()

    def on_step(self, engine: str, msg: DiagnosticArray) -> None:
        v = _values(msg)
        self.core.add_step(engine, stamp_ns(msg.header.stamp), int(v["step"]), float(v["step_time"]),
                           v["diverged"] == "true", msg.status[0].message)
        if self.core.complete(self.final_stamp):
            self.finish()

    def publish_scores(self) -> None:
        new = self.core.scores[self.published_scores :]
        self.published_scores = len(self.core.scores)
        for s in new:
            status = DiagnosticStatus(
                level=DiagnosticStatus.ERROR if s.diverged else DiagnosticStatus.OK,
                name=f"cloth_bench/{s.engine}/frame", message=f"frame {s.frame}", hardware_id=s.engine,
                values=[KeyValue(key=k, value=repr(v)) for k, v in
                        (("frame", s.frame), ("t", s.t), ("cd", s.cd), ("hd", s.hd), ("in_window", s.in_window))],
            )
            self.metrics_pub.publish(DiagnosticArray(status=[status]))

    def finish(self) -> None:
        """Close the run: summary on `metrics`, report files, done."""
        if self.done:
            return
        self.core.finish()
        wall_s = (time.monotonic_ns() - self.first_target_ns) / 1e9 if self.first_target_ns else None
        engines = self.core.summary(self.period_s, wall_s, self.final_stamp / 1e9)
        self.summary = {"run": {**self.run_info, "trial": self.trial, "wall_time": wall_s},
                        "real": self.core.real_summary(), "engines": engines}
        statuses = []
        for engine, m in self.summary["engines"].items():
            flat = {k: v for k, v in m.items() if not isinstance(v, dict)}
            for group in ("step_time", "latency"):
                flat.update({f"{group}_{k}": v for k, v in m[group].items()})
            statuses.append(DiagnosticStatus(
                level=DiagnosticStatus.ERROR if m["diverged"] else DiagnosticStatus.OK,
                name=f"cloth_bench/{engine}/summary", message="diverged" if m["diverged"] else "ok",
                hardware_id=engine, values=[KeyValue(key=k, value=str(v)) for k, v in flat.items()]))
        self.metrics_pub.publish(DiagnosticArray(status=statuses))
        if self.output_dir:
            write_run_report(Path(self.output_dir), self.summary, self.core.scores)
            self.get_logger().info(f"report written to {self.output_dir}")
        self.done = True


def main(args: list[str] | None = None) -> int:
    return run_node(Evaluator, args)


if __name__ == "__main__":
    raise SystemExit(main())
