"""The node graph of DESIGN.md composed in one process: what `cloth-bench run` executes."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import yaml

from cloth_bench_ros.nodes.common import close_nodes
from cloth_bench_ros.nodes.evaluator import Evaluator
from cloth_bench_ros.nodes.recorder import Recorder
from cloth_bench_ros.nodes.simulator import Simulator
from cloth_bench_ros.nodes.trajectory_publisher import TrajectoryPublisher
from cloth_bench_ros.runtime import EMBEDDED, Parameter, SingleThreadedExecutor, rclpy


@dataclass
class RunConfig:
    bag: Path
    engines: list[str] = field(default_factory=lambda: ["mujoco"])
    rate_hz: float = 100.0
    cloth: str = "towel"
    primitive: str = "dynamic"
    seed: int = 0
    pacing: str = "lockstep"
    output_dir: Path | None = None
    engine_params: dict[str, dict] = field(default_factory=dict)  # engine -> parameter overrides
    grid: tuple[int, int] | None = None  # (nx, nz) vertices; None: the engine's default
    presets_dir: Path | None = None  # directory of <engine>.yaml presets; None: config/presets


def _params(**values) -> list:
    return [Parameter(k, value=v) for k, v in values.items()]


def run_pipeline(config: RunConfig) -> dict:
    """Run trajectory publisher, one simulator per engine, recorder and evaluator to the end."""
    context = rclpy.Context()
    # Composed in one process on the intra-process transport, whatever CLOTH_BENCH_TRANSPORT says
    # (that switch is for the node console scripts): deterministic, and parallel sweeps stay apart.
    rclpy.init(args=[], context=context, **({"transport": "intra"} if EMBEDDED else {}))
    common = dict(primitive=config.primitive, rate_hz=float(config.rate_hz), use_sim_time=True)
    nodes = []
    try:
        nodes.append(TrajectoryPublisher(context=context, parameter_overrides=_params(
            primitive=config.primitive, rate_hz=float(config.rate_hz), engines=config.engines,
            pacing=config.pacing)))
        # The evaluator subscribes to the targets before the simulators do: the embedded runtime
        # delivers a message to its subscribers in subscription order, so the evaluator notes a
        # target's send time before a simulator steps on it (else latency would miss the step).
        evaluator = Evaluator(context=context, parameter_overrides=_params(
            engines=config.engines, output_dir=str(config.output_dir or ""), cloth=config.cloth,
            seed=int(config.seed), pacing=config.pacing, **common))
        nodes.append(evaluator)
        for engine in config.engines:
            nx, nz = config.grid or (0, 0)
            nodes.append(Simulator(node_name=f"simulator_{engine}", context=context, parameter_overrides=_params(
                engine=engine, cloth=config.cloth, seed=int(config.seed), grid_nx=nx, grid_nz=nz,
                presets_dir=str(config.presets_dir or ""),
                engine_params=yaml.safe_dump(config.engine_params.get(engine, {})), **common)))
        nodes.append(Recorder(context=context, parameter_overrides=_params(bag=str(config.bag), use_sim_time=True)))
        executor = SingleThreadedExecutor(context=context)
        for node in nodes:
            executor.add_node(node)
        while context.ok() and not evaluator.done:
            executor.spin_once(timeout_sec=0.1)
        return evaluator.summary
    finally:
        close_nodes(nodes)
        rclpy.shutdown(context=context)
