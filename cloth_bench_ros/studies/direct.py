"""
A study cell at the physics limit: engine, trajectory and evaluator called directly.

`run_direct` computes what `run_pipeline` (the node graph) computes for a lockstep run, with no
nodes and no messages: the recorder's replay plan, each engine stepped through the same targets
from the same start-up sequence as the simulator node, the states and real frames rounded to
float32 as a PointCloud2 carries them, and the evaluator's scoring and summary. Its metrics equal
the node graph's bit for bit (test/test_direct.py); step times are measured the same way, and a
state's latency is its step's own wall time, there being no transport.
"""

from __future__ import annotations

import json
from pathlib import Path
import time
from typing import Any

from cloth_bench_ros import validation
from cloth_bench_ros.core.cloth_mesh import (
    Cloth, cloth_faces, mesh_area, mesh_record, run_cloth,
)
from cloth_bench_ros.core.cloth_size import cloth_record, grasp_width
from cloth_bench_ros.core.evaluation import OnlineEvaluator
from cloth_bench_ros.core.pointcloud2 import as_carried, drop_nan
from cloth_bench_ros.core.run_files import write_run_report
from cloth_bench_ros.core.run_summary import run_summary
from cloth_bench_ros.core.scene import ClothGrid, REAL_FPS
from cloth_bench_ros.core.task_data import load_task
from cloth_bench_ros.core.trajectory import full_targets, GripperTargets, parse_primitive
from cloth_bench_ros.core.worst_frames import write_worst_frames
from cloth_bench_ros.data import BagReader
from cloth_bench_ros.data.alignment import reference_motion
from cloth_bench_ros.data.replay import plan_replay, replay_task, ReplayOptions
from cloth_bench_ros.data.trial import TrialInfo
from cloth_bench_ros.engines import make_engine
from cloth_bench_ros.engines.base import ClothEngine
from cloth_bench_ros.engines.presets import load_preset, sized_params
from cloth_bench_ros.engines.settle import FULL, Settler
from cloth_bench_ros.errors import InputError
from cloth_bench_ros.errors import user_path
from cloth_bench_ros.studies.run_config import RunConfig
import yaml


def _cloth(config: RunConfig) -> Cloth | None:
    """Return the cloth of a run, as the nodes build it (None: the engine's default grid)."""
    task = load_task(config.primitive, config.task)
    return run_cloth(
        config.grid, config.cloth_size, config.cloth_mesh, task, float(config.rate_hz)
    )


def _engine(config: RunConfig, name: str) -> ClothEngine:
    """Build an engine as the simulator node does: preset, then the overrides as YAML."""
    overrides = validation.parameter_mapping(
        yaml.safe_dump(config.engine_params.get(name, {})), f'simulator_{name}: engine_params'
    )
    preset = load_preset(
        name, config.cloth, config.primitive, config.presets_dir, overrides.get('model')
    )
    grid = _cloth(config)
    params = sized_params(name, {**preset, **overrides}, config.cloth_size, config.cloth_mass,
                          mesh_area(grid))
    return make_engine(name, float(config.rate_hz), params, grid)


def _step_engines(
    core: OnlineEvaluator,
    engines: dict[str, ClothEngine],
    targets: GripperTargets,
    seed: int,
    settle: str = FULL,
) -> None:
    """
    Step every engine through the targets in lockstep, as the simulator nodes do.

    The engines advance together so that the evaluator's bounded state buffers hold what the
    pending real frames need, as in the node graph.
    """
    left, right = targets.left[0], targets.right[0]
    first = {name: engine.start(seed, left, right) for name, engine in engines.items()}
    settlers = {name: Settler(engine, targets, settle) for name, engine in engines.items()}
    clock = time.perf_counter
    moves = zip(range(len(targets)), targets.left, targets.right)
    for k, left, right in moves:
        stamp = targets.stamp_ns(k)
        for name, engine in engines.items():
            start = clock()
            vertices = settlers[name].step(k, left, right) if k else first[name]
            step_time = clock() - start
            if settlers[name].stepped:  # a settle target answered without a step
                core.add_latency(name, step_time)
            core.add_state(name, stamp, as_carried(vertices))
            divergence = engine.divergence
            reason = 'ok' if divergence is None else (
                f'diverged at step {divergence.step}: {divergence.reason}'
            )
            if settlers[name].stepped:
                core.add_step(name, stamp, k, step_time, divergence is not None, reason)


_PLANS: dict[tuple, tuple[Any, str]] = {}  # a worker's replay plans, by bag and options
_PLANS_KEPT = 4


def _bag_identity(bag: Path) -> tuple:
    """Return what tells a changed bag from the one planned: its path, sizes and times."""
    with user_path(bag):  # a bag that is not there is bad input, named in one line
        files = sorted(bag.iterdir()) if bag.is_dir() else [bag]
        stats = [(f.name, f.stat().st_size, f.stat().st_mtime_ns) for f in files]
    return (str(bag.resolve()), *stats)


def _replay(config: RunConfig, cut: int | None) -> tuple[Any, dict[str, Any]]:
    """
    Return the replay plan of the bag and its accounting, as the recorder sends them.

    A worker plans a bag once for every cell on it (the plan depends on the bag and the options).
    """
    options = ReplayOptions(
        cloth=config.cloth,
        primitive=config.primitive,
        task=config.task,
        change_of_phase_frame=cut,
        rate_hz=float(config.rate_hz),
        align_engine=config.engines[0],
    )
    size, mass = config.cloth_size, config.cloth_mass
    cloth = _cloth(config)
    task = replay_task(options).sha256  # a task file changed in place plans again
    key = (_bag_identity(Path(config.bag)), options, task, config.grid, size, mass,
           str(mesh_record(cloth)))
    if key not in _PLANS:

        def motion(seconds: float) -> Any:
            preset = load_preset(options.align_engine, options.cloth, options.primitive)
            engine = make_engine(
                options.align_engine,
                options.rate_hz,
                sized_params(options.align_engine, preset, size, mass, mesh_area(cloth)),
                cloth,
            )
            try:
                return reference_motion(
                    engine, replay_task(options), options.rate_hz, seconds,
                    width=grasp_width(size),
                )
            finally:
                engine.close()

        with BagReader(config.bag) as reader:
            plan = plan_replay(reader, options, motion)
        while len(_PLANS) >= _PLANS_KEPT:
            _PLANS.pop(next(iter(_PLANS)))
        _PLANS[key] = (plan, json.dumps(plan.accounting()))
    plan, accounting = _PLANS[key]
    return plan, json.loads(accounting)  # as the trial message carries it


def run_direct(config: RunConfig) -> dict[str, Any]:
    """Run one lockstep cell without the node graph; the evaluator's summary of it."""
    if config.pacing != 'lockstep' or config.replay or config.record_comparison:
        raise InputError(
            'the direct study path runs lockstep cells of bundled-style bags only: '
            'realtime pacing, replay options and comparison outputs need the node graph'
        )
    primitive = parse_primitive(config.primitive)
    task = load_task(primitive.value, config.task)
    rate_hz = validation.rate_hz(config.rate_hz)
    cut = config.change_of_phase_frame
    start = time.monotonic_ns()
    plan, replay = _replay(config, cut)
    trial = TrialInfo.from_strings(plan.trial.to_strings())
    offset_ns = int(round(task.settle_duration * 1e9))
    grid = _cloth(config) or ClothGrid()
    faces = cloth_faces(grid) if config.all_metrics else None  # None: CD/HD only
    core = OnlineEvaluator(list(config.engines), task, offset_ns, cut, REAL_FPS, faces=faces)
    if core.change_of_phase_frame is None:
        core.change_of_phase_frame = trial.change_of_phase_frame
    targets = full_targets(task, rate_hz, grasp_width(config.cloth_size))
    final_stamp = targets.stamp_ns(len(targets) - 1)
    for t, points in plan.frames:  # pending until the engines' states reach them
        if t + offset_ns <= final_stamp:
            kept, dropped = drop_nan(as_carried(points))
            core.add_real(t + offset_ns, kept, dropped)
    engines = {name: _engine(config, name) for name in config.engines}
    try:
        _step_engines(core, engines, targets, int(config.seed), config.settle)
    finally:
        for engine in engines.values():
            engine.close()
    wall_s = (time.monotonic_ns() - start) / 1e9
    run = {
        'primitive': primitive.value,
        **task.record(),
        'rate_hz': rate_hz,
        'engines': list(config.engines),
        'cloth': config.cloth,
        'seed': int(config.seed),
        'settle': config.settle,
        **cloth_record(config.cloth_size, config.cloth_mass),
        **mesh_record(grid),
        'devices': {name: engine.device for name, engine in engines.items()},
        'models': {name: str(engine.config.get('model', '')) for name, engine in engines.items()},
        'trial': trial.to_dict(),
    }
    summary = run_summary(core, replay, run, 1.0 / rate_hz, wall_s, final_stamp)
    if config.output_dir:
        write_run_report(config.output_dir, summary, core.scores)
        write_worst_frames(config.output_dir, core.worst)
    return summary
