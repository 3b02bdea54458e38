"""`cloth-bench run`, `trajectory`, `motion` and `engines` as they run (parsers: cli/run.py)."""

from __future__ import annotations

import argparse
from pathlib import Path
import sys
import time

from cloth_bench_ros import validation
from cloth_bench_ros.cli import bag_inputs, common
from cloth_bench_ros.cli.common import UserError
from cloth_bench_ros.core.cloth_size import targets_grasp_text
from cloth_bench_ros.core.evaluation import accounting_line
from cloth_bench_ros.core.surface_metrics import compile_kernels
from cloth_bench_ros.core.task_data import load_task
from cloth_bench_ros.core.trajectory import sample_quintic, to_csv
from cloth_bench_ros.data import bag_reader, recorded_motion as motion
from cloth_bench_ros.data.recorded_motion import parse_gripper_frames, table_line
from cloth_bench_ros.engines import engine_class, known_engines
from cloth_bench_ros.engines.presets import fitted_device, fitted_elsewhere, load_preset
from cloth_bench_ros.options import OPTIONS
from cloth_bench_ros.paths import bundled_bag
from cloth_bench_ros.report.run_report import result_table
from cloth_bench_ros.safe_io import check_output_dir
from cloth_bench_ros.studies.cloth import cloth_choice, cloth_lines, engine_masses, mesh_choice
from cloth_bench_ros.studies.errors import ProcessRunError
from cloth_bench_ros.studies.processes import run_processes
from cloth_bench_ros.studies.run_pipeline import run_pipeline, RunConfig


def _write_motion(args: argparse.Namespace, bag: Path, path: Path) -> tuple[Path, dict]:
    """Write the recorded grippers (--gripper-frames, else --targets-topic) as a task file."""
    with bag_reader.BagReader(bag) as reader:
        doc = motion.recorded_task(reader, args.topic or '',
                                   motion.parse_gripper_frames(args.gripper_frames),
                                   args.targets_topic or '', args.table_z)
    path.parent.mkdir(parents=True, exist_ok=True)
    return motion.write_task(path, doc), doc


def recorded_motion(args: argparse.Namespace, bag: Path, out: Path) -> tuple[str, list[str]]:
    """
    Return the task file of the recorded grippers the run follows ('' : none) and its lines.

    --gripper-frames or --targets-topic name them, unless --motion task; the task file is
    written into the report directory.
    """
    follow = args.motion != 'task' and (
        parse_gripper_frames(args.gripper_frames) or args.targets_topic
    )
    if not follow:
        if args.table_z is not None:
            raise UserError('--table-z: only with a recorded motion (--gripper-frames or '
                            '--targets-topic)')
        return '', (["motion: the task's, as --motion task asks (the recording's own is not "
                     'followed)'] if args.motion == 'task' else [])
    if args.task:
        raise UserError('--task and a recorded motion (--gripper-frames or --targets-topic): '
                        'give one')
    path, doc = _write_motion(args, bag, out / 'motion.yaml')
    rec = doc['recorded']
    lines = [
        f'motion: the recorded grippers ({rec["source"]}, {len(rec["t"])} samples over '
        f'{rec["t"][-1]:.2f} s from the first cloud; in the frame of the clouds, {rec["frame"]}, '
        f'turned into the scene), written to {path}',
        table_line(doc),
    ]
    return str(path), lines


def recordings_motions(
    args: argparse.Namespace, bags: list[Path], out: Path
) -> tuple[list[str], list[str]]:
    """
    Return each recording's recorded-motion task file ('': none), as `run` makes it, and lines.

    identify and rank: written under `out`/motions/<n>_<recording>/motion.yaml.
    """
    tasks: list[str] = []
    lines: list[str] = []
    for i, bag in enumerate(bags):
        task, said = recorded_motion(args, bag, out / 'motions' / f'{i + 1}_{bag.name}')
        tasks.append(task)
        lines.extend(f'{bag}: {line}' for line in said)
    return tasks, lines[:1] if not any(tasks) else lines


def _print_real(summary: dict) -> None:
    real = summary['real']
    acc = real['accounting']
    print(accounting_line(acc))
    for line in trials_lines(real.get('trials')):
        print(line)
    start = real.get('alignment') or {}
    if start:
        print(
            f'start of the motion: bag time {start["bag_ns"] / 1e9:.3f} s, {start["method"]}, '
            f'precision +/- {start["precision_s"] * 1e3:.1f} ms'
        )

    size = tuple(summary['run'].get('cloth_size') or ()) or None
    grasp = targets_grasp_text(real.get('targets_grasp_m'), size)  # type: ignore[arg-type]
    if grasp:
        print(grasp)
    window = window_line(summary)
    if window:
        print(window)
    print(
        f'real points: {real["nan_points_dropped"]} NaN points dropped, '
        f'{real["irregular_intervals"]} intervals not at 30 Hz'
        + (f', frames from {real["frames_from"]}' if real.get('frames_from') else '')
    )
    if acc['scored'] == 0:
        raise UserError(
            f'bag: no frame was scored ({accounting_line(acc)[len("real frames: ") :]}); '
            'check --start-time/--topic/--primitive'
        )


def trials_lines(split: dict | None) -> list[str]:
    """Return the repetitions found in a recording, one line each, and which one is scored."""
    if not split:
        return []
    found = split['trials']
    usable = [t['number'] for t in found if t['usable']]
    head = (
        f'recording: {len(found)} trials found in the {split["source"]}'
        f' ({len(usable)} usable'
        + (f', {split["jumps"]} jumps between rests ignored' if split['jumps'] else '')
        + ')'
    )
    if split.get('scored'):
        head += f'; scoring trial {split["scored"]} (--trial N chooses)'
    elif split.get('reason'):
        head += f': {split["reason"]}'
    return [head] + [f'  {trial_line(t, split.get("origin_ns", 0))}' for t in found]


def trial_line(t: dict, origin_ns: int = 0) -> str:
    """
    One trial: `trial 2: bag time 41.3-46.2 s, 147 frames, start +/- 0.4 ms, ...`.

    Bag times are seconds from the recording's first frame (`origin_ns`).
    """
    start = t.get('start')
    first = ((start['bag_ns'] if start else t['first_ns']) - origin_ns) / 1e9
    last = (t['last_ns'] - origin_ns) / 1e9
    text = f'trial {t["number"]}: bag time {first:.1f}-{last:.1f} s'
    if start:
        text += f', {t.get("frames", 0)} frames, start +/- {start["precision_s"] * 1e3:.1f} ms'
    if t.get('residual_m') is not None:
        text += f', fit residual {t["residual_m"] * 1e3:.1f} mm'
    return text + (', usable' if t['usable'] else f', left out: {t["reason"]}')


def window_line(summary: dict) -> str:
    """Return which frames CD_d/HD_d cover and why (the change of phase and its source)."""
    if summary['run'].get('primitive') != 'dynamic':
        return ''
    cop = summary['real'].get('change_of_phase') or {}
    frame = cop.get('frame')
    if frame is None:
        return (
            f'CD_d/HD_d over every frame: no change of phase ({cop.get("reason", "not given")}); '
            'give --change-of-phase-frame N to score the dynamics only'
        )
    source = {
        'detected': f'detected ({cop.get("reason")}, t = {cop.get("t_s", 0.0):.2f} s)',
        'metadata': "from the bag's metadata",
        'option': 'given by --change-of-phase-frame',
    }
    return (
        f'CD_d/HD_d over frames 0-{frame - 1}: change of phase at frame {frame}, '
        f'{source.get(str(cop.get("source")), cop.get("reason", ""))}'
    )


def _checked_output(path: Path, option: str) -> Path:
    """Return an output directory that can be written, checked before the work starts."""
    try:
        return check_output_dir(path)
    except common.ClothBenchError as exc:
        raise UserError(f'{option} {exc}') from None


def cmd_run(args: argparse.Namespace) -> int:
    """Run the node graph on a bag and print the result table."""
    engines = validation.unique(args.engine or [OPTIONS['engine'].default], '--engine')
    for name in engines:
        engine_class(name)
    presets = common.preset_set(args).directory
    overrides = common.engine_overrides(args.set, engines)
    # The model that runs first (--set E.model=M, else the shipped preset's), then its entry of
    # the set: a missing set or entry, malformed preset file or bad value fails here, one line.
    params = {
        name: {
            **load_preset(
                name, args.cloth, args.primitive, presets, overrides.get(name, {}).get('model')
            ),
            **overrides.get(name, {}),
        }
        for name in engines
    }

    task = load_task(args.primitive, args.task)  # a bad task file: one line, before the run
    bag = Path(args.bag) if args.bag else bundled_bag(args.cloth, args.primitive)
    bag_inputs.check_bag(bag, args.topic)
    size, mass = cloth_choice(args.cloth_size, args.cloth_mass, overrides)
    replay = common.replay_params(args)
    replay.pop('change_of_phase_frame')  # passed to every node by the pipeline
    out = (
        Path(args.output)
        if args.output
        else (
            Path('results') / f'{args.cloth}_{args.primitive}_{int(args.rate)}hz_seed{args.seed}'
        )
    )
    _checked_output(
        out, '--output'
    )  # an unwritable or occupied --output is found before the run, not after it
    task_file, motion_lines = recorded_motion(args, bag, out)
    if task_file:
        task = load_task(args.primitive, task_file)
    # the mesh in the task's frame, grasped at its grippers' start; the start checked
    mesh = mesh_choice(args.cloth_mesh, args.grid, size, task, args.rate)
    # an engine without a mass fails here, one line
    masses = engine_masses(params, size, mass, mesh.area if mesh else None)
    config = RunConfig(
        bag=bag,
        engines=engines,
        rate_hz=args.rate,
        cloth=args.cloth,
        primitive=args.primitive,
        task=task_file or args.task or '',
        seed=args.seed,
        pacing=args.pacing,
        output_dir=out,
        engine_params=overrides,
        grid=args.grid,
        cloth_size=size,
        cloth_mass=mass,
        cloth_mesh=args.cloth_mesh or None,
        presets_dir=presets,
        replay=replay,
        change_of_phase_frame=args.change_of_phase_frame,
        record_comparison=Path(args.record_comparison) if args.record_comparison else None,
        comparison_figures=args.figures,
        live=common.live_parameters(args),
    )
    if config.record_comparison is not None:  # checked before the run, not after it
        if config.record_comparison.exists() and any(config.record_comparison.iterdir()):
            raise UserError(
                f'comparison bag {config.record_comparison} already exists (not empty)'
            )
        _checked_output(config.record_comparison, '--record-comparison')
    summary: dict | None
    if args.processes:
        try:
            summary = run_processes(config)
        except ProcessRunError as exc:
            raise UserError(f'run --processes: {exc}') from None
    else:
        summary = run_pipeline(config)
    if summary is None:
        raise RuntimeError('the node graph ended before the evaluator finished')
    devices = summary['run'].get('devices', {})
    models = summary['run'].get('models', {})
    on = ''.join(
        f', {name}{f" ({models[name]})" if models.get(name) else ""} on {device}'
        for name, device in devices.items()
    )
    print(
        f'cloth-bench run: {args.cloth} {args.primitive} at {args.rate:g} Hz, seed {args.seed},'
        f' bag {bag}{on}'
    )
    if args.task:
        print(f'task: {task.path} (sha256 {task.sha256[:12]}), {task.duration:.2f} s of motion')
    for line in motion_lines:
        print(line)
    for name, device in devices.items():
        model = params[name].get('model')
        note = fitted_elsewhere(
            name, device, [fitted_device(name, args.cloth, args.primitive, presets, model)])
        if note:
            print(note)
    for line in cloth_lines(masses, size, mass, args.grid, mesh):
        print(line)
    print(result_table(summary, realtime=args.pacing == 'realtime'))
    _print_real(summary)
    print(f'report: {out}/summary.json, {out}/frames.csv')
    for key in ('bag', 'figure', 'animation'):
        if key in summary.get('comparison', {}):
            print(f'comparison {key}: {summary["comparison"][key]}')
    if not summary['real']['accounting']['adds_up']:
        print(
            'cloth-bench: error: the frame accounting does not add up: frames were lost, or'
            ' another graph on the same ROS domain published into this run; the metrics are not'
            ' valid',
            file=sys.stderr,
        )
        return 1
    return 0


def cmd_trajectory(args: argparse.Namespace) -> int:
    """Print a task's motion (--task, else the shipped one of --primitive) as CSV."""
    sys.stdout.write(to_csv(sample_quintic(load_task(args.primitive, args.task), args.rate)))
    return 0


def cmd_motion(args: argparse.Namespace) -> int:
    """Write a recording's gripper motion as a task file."""
    if not parse_gripper_frames(args.gripper_frames) and not args.targets_topic:
        raise UserError('motion: give the grippers with --gripper-frames LEFT,RIGHT or '
                        '--targets-topic T')
    bag_inputs.check_bag(Path(args.bag), args.topic)
    path, doc = _write_motion(args, Path(args.bag), Path(args.output))
    print(f'task file: {path} ({doc["recorded"]["source"]}, {doc["recorded"]["t"][-1]:.2f} s)')
    print(table_line(doc))
    return 0


def cmd_engines(args: argparse.Namespace) -> int:
    """List the engines; with --warm, compile what makes their first run slow."""
    print(f'{"engine":<10} {"available":<10} {"version":<10} reason')
    for info in known_engines():
        print(
            f'{info.name:<10} {"yes" if info.available else "no":<10} {info.version or "-":<10}'
            f' {info.reason}'
        )
    devices = [
        f'{info.name} {", ".join(engine_class(info.name).devices())}'
        for info in known_engines()
        if info.available
    ]
    print(f'devices: {"; ".join(devices)}')
    if args.warm:
        for info in known_engines():
            if info.available:
                start = time.perf_counter()
                engine_class(info.name).warm()  # on every device the engine has here
                on = ', '.join(engine_class(info.name).devices())
                print(f'warmed {info.name} on {on} in {time.perf_counter() - start:.1f} s')
        start = time.perf_counter()
        compile_kernels()
        print(f'compiled the metric kernels in {time.perf_counter() - start:.1f} s')
    return 0
