"""The node graph composed in one process: what `cloth-bench run` executes."""

from __future__ import annotations

import gc
import os
from pathlib import Path
import random

from cloth_bench_ros.engines import engine_device, engine_model
from cloth_bench_ros.engines.presets import load_preset
from cloth_bench_ros.engines.settle import FULL
from cloth_bench_ros.errors import InputError
from cloth_bench_ros.nodes.common import close_nodes
from cloth_bench_ros.nodes.evaluator import Evaluator
from cloth_bench_ros.nodes.recorder import Recorder
from cloth_bench_ros.nodes.simulator import Simulator
from cloth_bench_ros.nodes.trajectory_publisher import TrajectoryPublisher
from cloth_bench_ros.runtime import EMBEDDED, Node, Parameter, rclpy, SingleThreadedExecutor
from cloth_bench_ros.studies.run_config import RunConfig
import yaml


def _params(values: dict) -> list:
    return [Parameter(k, value=v) for k, v in values.items()]


def _cut(config: RunConfig) -> int:
    return -1 if config.change_of_phase_frame is None else int(config.change_of_phase_frame)


def run_devices(config: RunConfig) -> dict[str, str]:
    """Return the device each engine of the run runs on (its overrides' device, or its default)."""
    params = config.engine_params
    return {name: engine_device(name, params.get(name, {})) for name in config.engines}


def run_models(config: RunConfig) -> dict[str, str]:
    """Return the model each engine of the run runs ('' for an engine without models)."""
    models = {}
    for name in config.engines:
        overrides = config.engine_params.get(name, {})
        preset = load_preset(
            name, config.cloth, config.primitive, config.presets_dir, overrides.get('model')
        )
        models[name] = engine_model(name, {**preset, **overrides})
    return models


def node_parameters(config: RunConfig, output_dir: Path | None = None) -> dict[str, dict]:
    """{node name: parameters} of every node of the graph; the one source for both kinds of run."""
    out = config.output_dir if output_dir is None else output_dir
    common = {
        'primitive': config.primitive,
        'task': config.task,
        'rate_hz': float(config.rate_hz),
        'use_sim_time': True,
    }
    nx, nz = config.grid or (0, 0)
    cloth = {  # the nodes' cloth_size and cloth_mass ('' and 0: the benchmark's, the preset's)
        'cloth_size': ','.join(f'{v:.17g}' for v in config.cloth_size or ()),
        'cloth_mass': float(config.cloth_mass or 0.0),
        'cloth_mesh': str(config.cloth_mesh or ''),
    }
    nodes = {
        'trajectory_publisher': {
            'primitive': config.primitive,
            'task': config.task,
            'rate_hz': float(config.rate_hz),
            'cloth_size': cloth['cloth_size'],
            'engines': list(config.engines),
            'pacing': config.pacing,
        },
        'evaluator': {
            **common,
            'engines': list(config.engines),
            'output_dir': str(out or ''),
            'cloth': config.cloth,
            'seed': int(config.seed),
            'pacing': config.pacing,
            'record_comparison': str(config.record_comparison or ''),
            'comparison_figures': config.comparison_figures,
            'change_of_phase_frame': _cut(config),
            'grid_nx': nx,
            'grid_nz': nz,
            **cloth,
            **config.live,
            'devices': ','.join(run_devices(config).values()),
            'models': ','.join(run_models(config).values()),
        },
    }
    for engine in config.engines:
        nodes[f'simulator_{engine}'] = {
            **common,
            'engine': engine,
            'cloth': config.cloth,
            'seed': int(config.seed),
            'grid_nx': nx,
            'grid_nz': nz,
            **cloth,
            'presets_dir': str(config.presets_dir or ''),
            'engine_params': yaml.safe_dump(config.engine_params.get(engine, {})),
        }
    nodes['recorder'] = {
        **common,
        'bag': str(config.bag),
        'cloth': config.cloth,
        'change_of_phase_frame': _cut(config),
        'align_engine': config.engines[0],
        'grid_nx': nx,
        'grid_nz': nz,
        **cloth,
        **config.replay,
    }
    return nodes


def isolated_domain() -> int:
    """Return a ROS domain for one in-process run under real rclpy: random in 1-101."""
    taken = os.environ.get('ROS_DOMAIN_ID', '0')
    choices = [d for d in range(1, 102) if str(d) != taken]
    return random.SystemRandom().choice(choices)


def run_pipeline(config: RunConfig) -> dict | None:
    """Run trajectory publisher, one simulator per engine, recorder and evaluator to the end."""
    if config.settle != FULL:
        raise InputError('the node graph settles in full: the fast settle runs on the direct '
                         'study path (lockstep cells)')
    context = rclpy.Context()
    # Composed in one process on the intra-process transport, whatever CLOTH_BENCH_TRANSPORT says
    # (that switch is for the node console scripts): deterministic, and parallel sweeps stay apart.
    # Under real rclpy the nodes talk DDS even in one process: a domain of its own keeps two runs
    # (or a sweep's workers) from hearing each other.
    rclpy.init(
        args=[],
        context=context,
        **({'transport': 'intra'} if EMBEDDED else {'domain_id': isolated_domain()}),
    )
    params = node_parameters(config)
    nodes: list[Node] = []
    try:
        nodes.append(
            TrajectoryPublisher(
                context=context, parameter_overrides=_params(params['trajectory_publisher'])
            )
        )
        # The evaluator subscribes to the targets before the simulators do: the embedded runtime
        # delivers a message to its subscribers in subscription order, so the evaluator notes a
        # target's send time before a simulator steps on it (else latency would miss the step).
        evaluator = Evaluator(context=context, parameter_overrides=_params(params['evaluator']))
        evaluator.graph_started = False
        nodes.append(evaluator)
        for engine in config.engines:
            name = f'simulator_{engine}'
            nodes.append(
                Simulator(
                    node_name=name, context=context, parameter_overrides=_params(params[name])
                )
            )
        nodes.append(Recorder(context=context, parameter_overrides=_params(params['recorder'])))
        evaluator.graph_started = True
        executor = SingleThreadedExecutor(context=context)
        for node in nodes:
            executor.add_node(node)
        # The start-up heap (engines, bag, nodes) out of the collector's way: per-step garbage is
        # young, and full collections would otherwise walk every start-up object again.
        gc.freeze()
        while context.ok() and not evaluator.done:
            executor.spin_once(timeout_sec=0.1)
        return evaluator.summary
    finally:
        gc.unfreeze()
        close_nodes(nodes)
        rclpy.shutdown(context=context)
