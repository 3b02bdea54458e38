"""
Steps one cloth engine per target and publishes the mesh vertices as PointCloud2.

The step path (`on_target`) is the critical path of hardware in the loop: its two outgoing
messages are built once and refilled (in place, or from a pool where subscribers get the objects
themselves), the gripper targets go into a preallocated array,
and start-up work (model compilation, a throwaway step, the reset at the first target) is done
in the constructor, before the first deadline. Optionally the process is pinned to a core, asks
for SCHED_FIFO and freezes its start-up heap (`cpu`, `realtime_priority`, `freeze_gc`).
"""

from __future__ import annotations

from pathlib import Path
import time

from cloth_bench_ros import validation
from cloth_bench_ros.core import realtime_process
from cloth_bench_ros.core.cloth_mesh import mesh_area, run_cloth
from cloth_bench_ros.core.cloth_size import grasp_width
from cloth_bench_ros.core.pointcloud2 import create_cloud_xyz32
from cloth_bench_ros.core.trajectory import full_targets
from cloth_bench_ros.engines import make_engine
from cloth_bench_ros.engines.presets import load_preset, sized_params
from cloth_bench_ros.errors import InputError
from cloth_bench_ros.nodes.common import (
    NAMESPACE,
    node_cloth,
    node_cloth_mesh,
    node_grid,
    node_task,
    publish_serialises,
    run_node,
)
from cloth_bench_ros.nodes.message_pool import MessagePool
from cloth_bench_ros.runtime import (
    declare_fixed,
    declare_option,
    DiagnosticArray,
    DiagnosticStatus,
    Header,
    KeyValue,
    make_qos,
    Node,
    PointCloud2,
    PointField,
    PoseArray,
    serialize_message,
    stamp_ns,
)
import numpy as np


class StateMessages:
    """
    The simulator's cloud and step status; `fill` writes a step into them.

    Over a transport that serialises on publish (`in_place`), one pair of messages is refilled
    every step. The intra-process transport hands subscribers the objects themselves: there a
    MessagePool refills a pair only when no queue or subscriber holds it any more.
    """

    STATUS_KEYS = ('step', 'step_time', 'diverged', 'diverged_at_step', 'skipped_targets')

    def __init__(self, engine_name: str, n_vertices: int, in_place: bool) -> None:
        self.engine_name, self.n_vertices = engine_name, n_vertices
        parts = lambda m: (m[0], m[0].data, m[2])  # noqa: E731 - what a subscriber may keep
        self.pool = MessagePool(self._build, parts, in_place=in_place)

    def _build(self) -> tuple[PointCloud2, np.ndarray, DiagnosticArray]:
        header = Header(frame_id='world')
        cloud = create_cloud_xyz32(header, np.zeros((self.n_vertices, 3)), PointCloud2, PointField)
        if isinstance(cloud.data, np.ndarray):  # the embedded runtime's: a read-only view of bytes
            cloud.data = cloud.data.copy()
        xyz = np.frombuffer(cloud.data, dtype=np.float32).reshape(self.n_vertices, 3)
        values = [KeyValue(key=k, value='') for k in self.STATUS_KEYS]
        status = DiagnosticStatus(
            level=DiagnosticStatus.OK,
            name=f'cloth_bench/{self.engine_name}',
            message='ok',
            hardware_id=self.engine_name,
            values=values,
        )
        return cloud, xyz, DiagnosticArray(header=header, status=[status])

    def fill(
        self, stamp, vertices: np.ndarray, step: int, step_time: float, divergence, skipped: int
    ) -> tuple[PointCloud2, DiagnosticArray]:
        """Return the two messages of one step (the float32 conversion is the one copy)."""
        cloud, xyz, status = self.pool.take()
        cloud.header.stamp = stamp
        np.copyto(xyz, vertices, casting='same_kind')
        values = status.status[0].values
        values[0].value = str(step)
        values[1].value = repr(step_time)
        values[4].value = str(skipped)
        if divergence is not None:
            cloud.is_dense = bool(np.isfinite(xyz).all())
            s = status.status[0]
            s.level, s.message = (
                DiagnosticStatus.ERROR,
                f'diverged at step {divergence.step}: {divergence.reason}',
            )
            values[2].value, values[3].value = 'true', str(divergence.step)
        else:
            values[2].value = 'false'
        return cloud, status


class Simulator(Node):
    """One engine: reset on the first target, one step per further target."""

    def __init__(self, **kwargs) -> None:
        super().__init__(
            kwargs.pop('node_name', 'simulator'),
            namespace=kwargs.pop('namespace', NAMESPACE),
            **kwargs,
        )
        self.engine_name = declare_option(self, 'engine')
        rate_hz = declare_option(self, 'rate_hz')
        cloth = declare_option(self, 'cloth')
        task = node_task(self)
        primitive = self.get_parameter('primitive').value
        self.seed = declare_option(self, 'seed')
        declare_fixed(self, 'engine_params')
        nx, nz = node_grid(self)
        size, mass = node_cloth(self)
        presets_dir = declare_fixed(self, 'presets_dir')
        declare_option(self, 'device')  # '' : engine_params' device, else the engine's
        # Every value through the one validation layer; an error names the node and parameter.
        checked = validation.node_parameters(
            self,
            {
                'engine_params': validation.parameter_mapping,
                'device': lambda v, n: validation.device(v, n) if v != '' else '',
            },
        )
        overrides = checked['engine_params']
        if mass is not None and 'mass' in overrides:
            raise InputError(
                f'{self.get_name()}: parameters cloth_mass and engine_params mass both give the '
                "cloth's mass; give one"
            )
        targets = full_targets(task, rate_hz, grasp_width(size))
        grid = run_cloth((nx, nz) if nx and nz else None, size, node_cloth_mesh(self), task,
                         rate_hz)
        preset = load_preset(  # the model that runs first, then its entry of the set
            self.engine_name,
            cloth,
            primitive,
            Path(presets_dir) if presets_dir else None,
            overrides.get('model'),
        )
        params = sized_params(
            self.engine_name, {**preset, **overrides}, size, mass, mesh_area(grid))
        if checked['device']:  # the engine refuses it if it has no such parameter or device
            params['device'] = checked['device']
        self.engine = make_engine(self.engine_name, rate_hz, params, grid)
        self.cloud_pub = self.create_publisher(
            PointCloud2, f'{self.engine_name}/cloud', make_qos(10)
        )
        self.status_pub = self.create_publisher(
            DiagnosticArray, f'{self.engine_name}/step_time', make_qos(10)
        )
        self.step = -1
        self.skipped = 0
        self.reported_divergence = False
        self.targets = targets
        self.stamps = np.array(
            [self.targets.stamp_ns(k) for k in range(len(self.targets))], dtype=np.int64
        )
        self.stamp_list = self.stamps.tolist()
        self.last_k = -1
        self.last_cloud: PointCloud2 | None = (
            None  # the state of target last_k, sent again on a repeat
        )
        self.step_times = np.full(len(self.stamps), np.nan)  # s per step, kept for a HIL report
        self.grippers = np.zeros((2, 3))
        self.left, self.right = self.grippers[0], self.grippers[1]
        self.messages = StateMessages(
            self.engine_name, len(self.engine.grid.vertices()), publish_serialises(self)
        )
        self.prepared: np.ndarray | None = self.warm_up()
        self.realtime = realtime_process.apply(
            int(declare_fixed(self, 'cpu')),
            int(declare_fixed(self, 'realtime_priority')),
            bool(declare_fixed(self, 'freeze_gc')),
        )
        # Subscribed last, once start-up is done, so the first target finds the engine ready.
        # Keep-last 1, as a controller's command topic: a simulator that falls behind steps to the
        # newest target and counts the ones it never saw (every transport keeps only the newest).
        self.create_subscription(PoseArray, 'targets', self.on_target, make_qos(1))
        self.get_logger().info(f'{self.engine_name} ready; ' + '; '.join(self.realtime.lines()))

    def warm_up(self) -> np.ndarray:
        """
        Do the start-up work before the first deadline; the vertices answer target 0.

        The reset at the trajectory's first target, one throwaway step (first-call costs), the
        reset again.
        """
        vertices = self.engine.start(self.seed, self.targets.left[0], self.targets.right[0])
        cloud, status = self.messages.fill(
            Header().stamp, vertices, 0, 0.0, None, 0
        )
        serialize_message(cloud)  # the serialisers are generated on first use
        serialize_message(status)
        return vertices

    def on_target(self, msg: PoseArray) -> None:
        """Step to this target; targets dropped while the engine was busy are skipped."""
        p, g = msg.poses, self.grippers
        g[0, 0], g[0, 1], g[0, 2] = p[0].position.x, p[0].position.y, p[0].position.z
        g[1, 0], g[1, 1], g[1, 2] = p[1].position.x, p[1].position.y, p[1].position.z
        stamp = stamp_ns(msg.header.stamp)
        k = self.last_k + 1  # the next target, as a rule; else looked up
        if not (k < len(self.stamp_list) and self.stamp_list[k] == stamp):
            k = int(np.searchsorted(self.stamps, stamp))
        known = k < len(self.stamp_list) and self.stamp_list[k] == stamp
        if known and k == self.last_k and self.last_cloud is not None:
            # The newest target again (a controller's start-up handshake): its state again, no
            # step.
            self.cloud_pub.publish(self.last_cloud)
            return
        if known and k > self.last_k:
            self.skipped += k - self.last_k - 1
            self.last_k = k
        self.step += 1
        start = time.perf_counter()
        if self.step == 0:
            vertices = self.first_state()
        else:
            vertices = self.engine.step(self.left, self.right)
        step_time = time.perf_counter() - start
        if self.step < len(self.step_times):
            self.step_times[self.step] = step_time
        cloud, status = self.messages.fill(
            msg.header.stamp, vertices, self.step, step_time, self.engine.divergence, self.skipped
        )
        self.cloud_pub.publish(cloud)
        self.status_pub.publish(status)
        self.last_cloud = cloud
        if self.realtime.frozen:
            realtime_process.collect_young()  # after the state went out: off this step's deadline
        d = self.engine.divergence
        if d is not None and not self.reported_divergence:
            self.reported_divergence = True
            self.get_logger().error(f'{self.engine_name} diverged at step {d.step}: {d.reason}')

    def first_state(self) -> np.ndarray:
        """Return the state at the first target (prepared by warm_up for the trajectory's own)."""
        if self.prepared is not None and np.array_equal(
            self.grippers, [self.targets.left[0], self.targets.right[0]]
        ):
            vertices, self.prepared = self.prepared, None
            return vertices
        return self.engine.reset(self.seed, self.left, self.right)

    def close(self) -> None:
        self.engine.close()
        realtime_process.release(self.realtime)


def main(args: list[str] | None = None) -> int:
    return run_node(Simulator, args)


if __name__ == '__main__':
    raise SystemExit(main())
