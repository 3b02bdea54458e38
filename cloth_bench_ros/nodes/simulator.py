"""Steps one cloth engine per target and publishes the mesh vertices as PointCloud2."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from cloth_bench_ros import validation
from cloth_bench_ros.engines import make_engine
from cloth_bench_ros.engines.presets import load_preset
from cloth_bench_ros.nodes.common import NAMESPACE, run_node
from cloth_bench_ros.core.pointcloud2 import create_cloud_xyz32
from cloth_bench_ros.runtime import (
    DiagnosticArray, DiagnosticStatus, Header, KeyValue, Node, PointCloud2, PointField, PoseArray,
    declare_float, make_qos,
)
from cloth_bench_ros.core.scene import ClothGrid


def _grid_side(value: object, name: str) -> int:
    """0 (the engine's default) or 2..MAX_GRID_SIDE vertices."""
    n = validation.integer(value, name, 0, validation.MAX_GRID_SIDE)
    if n == 1:
        raise validation.InputError(f"{name}: 1 vertex per side is no cloth (0 keeps the engine's default, else >= 2)")
    return n


def _xyz(pose) -> np.ndarray:
    return np.array([pose.position.x, pose.position.y, pose.position.z])


class Simulator(Node):
    """One engine: reset on the first target, one step per further target."""

    def __init__(self, **kwargs) -> None:
        super().__init__(kwargs.pop("node_name", "simulator"),
                         namespace=kwargs.pop("namespace", NAMESPACE), **kwargs)
        self.engine_name = self.declare_parameter("engine", "mujoco").value
        rate_hz = declare_float(self, "rate_hz", 100.0)
        cloth = self.declare_parameter("cloth", "towel").value
        primitive = self.declare_parameter("primitive", "dynamic").value
        self.seed = int(self.declare_parameter("seed", 0).value)
        self.declare_parameter("engine_params", "{}")
        self.declare_parameter("grid_nx", 0)
        self.declare_parameter("grid_nz", 0)
        presets_dir = self.declare_parameter("presets_dir", "").value
        # Every value through the one validation layer; an error names the node and parameter.
        checked = validation.node_parameters(self, {
            "rate_hz": validation.rate_hz, "seed": validation.seed, "engine_params": validation.parameter_mapping,
            "grid_nx": _grid_side, "grid_nz": _grid_side})
        overrides, nx, nz = checked["engine_params"], checked["grid_nx"], checked["grid_nz"]
        if (nx == 0) != (nz == 0):
            raise validation.InputError(f"{self.get_name()}: parameters grid_nx and grid_nz: set both or neither "
                                        f"(got {nx} and {nz})")
        grid = ClothGrid(nx, nz) if nx and nz else None
        preset = load_preset(self.engine_name, cloth, primitive, Path(presets_dir) if presets_dir else None)
        params = {**preset, **overrides}
        self.engine = make_engine(self.engine_name, rate_hz, params, grid)
        self.cloud_pub = self.create_publisher(PointCloud2, f"{self.engine_name}/cloud", make_qos(10))
        self.status_pub = self.create_publisher(DiagnosticArray, f"{self.engine_name}/step_time", make_qos(10))
        self.create_subscription(PoseArray, "targets", self.on_target, make_qos(10))
        self.step = -1
        self.reported_divergence = False

    def on_target(self, msg: PoseArray) -> None:
        left, right = _xyz(msg.poses[0]), _xyz(msg.poses[1])
        self.step += 1
        start = time.perf_counter()
        if self.step == 0:
            vertices = self.engine.reset(self.seed, left, right)
        else:
            vertices = self.engine.step(left, right)
        step_time = time.perf_counter() - start
        header = Header(stamp=msg.header.stamp, frame_id="world")
        self.cloud_pub.publish(create_cloud_xyz32(header, vertices, PointCloud2, PointField))
        self.status_pub.publish(self.status(header, step_time))
        if self.engine.diverged and not self.reported_divergence:
            self.reported_divergence = True
            d = self.engine.divergence
            self.get_logger().error(f"{self.engine_name} diverged at step {d.step}: {d.reason}")

    def status(self, header: Header, step_time: float) -> DiagnosticArray:
        d = self.engine.divergence
        status = DiagnosticStatus(
            level=DiagnosticStatus.ERROR if d else DiagnosticStatus.OK,
            name=f"cloth_bench/{self.engine_name}",
            message=f"diverged at step {d.step}: {d.reason}" if d else "ok",
            hardware_id=self.engine_name,
            values=[
                KeyValue(key="step", value=str(self.step)),
                KeyValue(key="step_time", value=repr(step_time)),
                KeyValue(key="diverged", value=str(d is not None).lower()),
                KeyValue(key="diverged_at_step", value=str(d.step) if d else ""),
            ],
        )
        return DiagnosticArray(header=header, status=[status])

    def close(self) -> None:
        self.engine.close()


def main(args: list[str] | None = None) -> int:
    return run_node(Simulator, args)


if __name__ == "__main__":
    raise SystemExit(main())
