"""`cloth-bench identify` as it runs: the spec from its flags, the study (parser: identify.py)."""

from __future__ import annotations

import argparse
from pathlib import Path

from cloth_bench_ros.cli import bag_inputs, common
from cloth_bench_ros.cli.common import UserError
from cloth_bench_ros.cli.run_command import recordings_motions
from cloth_bench_ros.core.task_data import load_task
from cloth_bench_ros.data import BagReader
from cloth_bench_ros.engines.presets import load_preset
from cloth_bench_ros.identify.spec import IdentifySpec
from cloth_bench_ros.identify.study import identify, JOURNAL_FILE, TRIALS_FILE
from cloth_bench_ros.paths import bundled_bag
from cloth_bench_ros.rank.trials import prepare_trials
from cloth_bench_ros.studies.cloth import cloth_choice, cloth_lines, engine_masses, mesh_choice
from cloth_bench_ros.studies.errors import StudyInterrupted


def _budget_text(budget: dict) -> str:
    """How an automatic budget ended, e.g. ' (budget: the doubling 32 -> 64 improved 1.2 %)'."""
    if not budget.get('doublings'):
        return ''
    before, after, gain = budget['doublings'][-1]
    verdict = '' if budget['reached'] else '; cap reached, not converged'
    return f' (budget: the doubling {before} -> {after} improved {gain:.1%}{verdict})'


def _trial_bag(bag: Path, args: argparse.Namespace, out: Path, task: str) -> Path:
    """
    Return the bag to fit: a project bag as it is, else a trial of the recording (--trial N).

    A plain recording is split as `rank` splits it, without an engine (a recorded motion, `task`,
    or a --start-time: the recording is one trial); the trial is written under `out`.
    """
    with BagReader(bag) as reader:
        if reader.trial is not None:
            return bag
    found = prepare_trials([bag], bag_inputs.replay_options(args), out / 'trials', tasks=[task])
    chosen = [t for t in found if t.number == args.trial] if args.trial else found
    if not chosen:
        raise UserError(f'identify: bag {bag} holds no usable trial of the task'
                        + (f' numbered {args.trial} (--trial)' if args.trial else '')
                        + ' (above)')
    print(f'identify: fitting trial {chosen[0].number} of {bag} ({chosen[0].bag})')
    return Path(chosen[0].bag)


def cmd_identify(args: argparse.Namespace) -> int:
    """Identify, validate on held-out seeds, write the preset and print the outcome."""
    load_task(args.primitive, args.task)  # a bad task file: one line, before the work
    common.check_split_without_engine(args, 'identify')
    bag = Path(args.bag) if args.bag else bundled_bag(args.cloth, args.primitive)
    bag_inputs.check_bag(bag, args.topic or None)
    fixed = common.engine_overrides(args.set, [args.engine]).get(args.engine, {})
    size, mass = cloth_choice(args.cloth_size, args.cloth_mass, {args.engine: fixed})
    preset = {**load_preset(args.engine, args.cloth, args.primitive), **fixed}
    # a mesh read as `run` reads it (the task's grippers' start); a recorded motion's own start
    # is the objective's, per trial
    follows = args.motion != 'task' and (args.gripper_frames or args.targets_topic)
    mesh = None if follows else mesh_choice(
        args.cloth_mesh, args.grid, size, load_task(args.primitive, args.task), args.rate)
    masses = engine_masses({args.engine: preset}, size, mass, mesh.area if mesh else None)
    out = (
        Path(args.output)
        if args.output
        else (Path('results') / 'identify' / f'{args.engine}_{args.cloth}_{args.primitive}')
    )
    (motion,), motion_lines = recordings_motions(args, [bag], out)
    bag = _trial_bag(bag, args, out, motion)
    spec = IdentifySpec(
        args.engine,
        args.cloth,
        args.primitive,
        bag,
        out,
        args.sampler,
        args.trials,
        args.objective,
        list(args.params or []),
        args.seed,
        args.rate,
        args.grid,
        fixed,
        args.span,
        args.max_frames,
        args.batch,
        args.validate_seeds,
        Path(args.bag_dir) if args.bag_dir else None,
        fidelity=args.fidelity,
        cloth_size=size,
        cloth_mass=mass,
        settle=args.settle,
        task=args.task or '',
        cloth_mesh=args.cloth_mesh or '',
        gripper_frames=args.gripper_frames or '',
        table_z=args.table_z,
    )
    print(
        f'cloth-bench identify: {args.engine}, {args.cloth} {args.primitive},'
        f' {args.objective.upper()}, sampler {args.sampler},'
        f' {args.trials or "auto (doubling)"} trials each, {args.settle} settle; bag {bag};'
        f' output {out}',
        flush=True,
    )
    for line in motion_lines:
        print(line)
    for line in cloth_lines(masses, size, mass, args.grid, mesh):
        print(line)
    if mass is not None and 'mass' not in spec.params:
        print(f"mass: {mass:g} kg, the cloth's own (--cloth-mass): not fitted")
    try:
        outcome = identify(spec, args.scheduler, args.workers, progress=not args.no_progress)
    except KeyboardInterrupt:
        trials = out / TRIALS_FILE
        kept = (
            sum(1 for line in trials.read_text().splitlines() if line.strip())
            if trials.exists()
            else 0
        )
        raise StudyInterrupted(
            f'identify interrupted: {kept} finished trials are in {out / TRIALS_FILE} '
            f'(study: {out / JOURNAL_FILE}); run the same command again to resume'
        ) from None
    s = outcome.summary
    for name, result in s['per_sampler'].items():
        print(
            f'{name:<6} best {args.objective.upper()} {result["value"]:.5f} m after'
            f' {result["trials"]} trials'
            + (f' ({result["pruned"]} pruned)' if result.get('pruned') else '')
            + _budget_text(result.get('budget', {}))
        )
    print(
        f'identified ({s["best_sampler"]}): '
        + ', '.join(f'{k}={v:.6g}' for k, v in s['params'].items())
    )
    print(
        f'{args.objective.upper()} on seed {args.seed}: preset {s["preset_value"]:.5f} m ->'
        f' identified {s["value"]:.5f} m'
    )
    for v in s['validation']:
        print(
            f'held-out seeds, {Path(v["bag"]).name}: preset {v["preset"]["mean"]:.5f} ±'
            f' {v["preset"]["std"]:.5f} m, identified {v["identified"]["mean"]:.5f} ±'
            f' {v["identified"]["std"]:.5f} m ({v["identified"]["ok"]} of {v["identified"]["n"]}'
            ' runs ok)'
        )
    print(
        f'preset: {outcome.preset_file} (use: cloth-bench run --presets {out}); '
        f'{outcome.wall_s:.0f} s; report: cloth-bench report {out}'
    )
    return 0
