"""
The trials of `cloth-bench rank`: found in a user's recordings without an engine, and their floor.

A recording with the project's trial metadata (the dataset importer's bags, the bundled ones) is
one trial as it is. Any other recording is read as `run` reads it (its cloud topic moved into
world and cleaned) and split into the repetitions of the task (data.trials: from its gripper
targets when it has them, else from the clouds); each usable repetition is written as a bag of
the project's layout (stamps from the start of the motion, the change of phase found in its
clouds), which identification and scoring then read as they read any trial. A recording with a
recorded motion (its task file, `cli.run_command.recorded_motion`) is one trial from its first
cloud, as `run` scores it; its bag carries that task file (objective.TASK_IN_BAG), which the
engines follow on it. The floor is the distance between two real trials of one cloth and task,
as an engine's is measured.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
import json
from pathlib import Path
import shutil
from typing import Any, Sequence

from cloth_bench_ros.core.metrics import RealCloud
from cloth_bench_ros.core.phase import first_table_contact
from cloth_bench_ros.core.scene import REAL_FPS
from cloth_bench_ros.core.trajectory import full_targets
from cloth_bench_ros.data import BagReader, BagWriter
from cloth_bench_ros.data.alignment import AlignmentError
from cloth_bench_ros.data.bag_layout import locate
from cloth_bench_ros.data.errors import BagError
from cloth_bench_ros.data.replay import (
    mismatch_error, plan_replay, read_frames, replay_task, ReplayOptions, split_recording,
)
from cloth_bench_ros.data.trial import CLOUD_TOPIC, TrialInfo
from cloth_bench_ros.data.trials import settings as split_settings
from cloth_bench_ros.identify.objective import bag_clouds, TASK_IN_BAG
from cloth_bench_ros.rank.errors import RankInputError
import numpy as np

FLOOR_SEED = 0
# The bundled synthetic references' own numerical error in the units of a score (CD, m), as
# measured by `cloth-bench converge` (bags/README.md, "How converged the references are"): the
# MuJoCo-made bags carry a resolution error of about 1-3 mm, the Newton VBD ones (2400 Hz) moved
# the presets' scores by 0.4-7 mm from 2400 to 4800 Hz.
REFERENCE_ERRORS = {'mujoco': 0.003, 'newton vbd': 0.007}
REFERENCE_ERROR_SOURCE = 'bags/README.md, "How converged the references are"'


@dataclass
class RankTrial:
    """One usable trial: its cloth and task, the bag it is scored from, and where it came from."""

    name: str  # unique: <recording>, or <recording>_trial<N>
    cloth: str
    primitive: str
    bag: str
    recording: str
    number: int  # the repetition in its recording (0: the recording is one trial)
    source: str  # 'metadata', or how the start was found
    start_precision_s: float
    frames: int
    change_of_phase: int | None
    task: str = ''  # the task file the engines follow on this trial; '': the shipped one
    task_sha256: str = ''

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def recordings_of(paths: Sequence[str]) -> list[Path]:
    """Return the bags given: each path a bag, or a folder of bags (its direct sub-folders)."""
    bags: list[Path] = []
    for text in paths:
        path = Path(text)
        if not path.exists():
            raise RankInputError(f'recording {path} does not exist')
        try:
            locate(path)
            bags.append(path)
            continue
        except BagError:
            pass
        inner = []
        for sub in sorted(p for p in path.iterdir() if p.is_dir()):
            try:
                locate(sub)
                inner.append(sub)
            except BagError:
                continue
        if not inner:
            raise RankInputError(f'recording {path} is neither a rosbag2 bag nor a folder of bags')
        bags.extend(inner)
    return bags


def _identity(path: Path) -> list:
    files = sorted(path.iterdir()) if path.is_dir() else [path]
    return [[f.name, f.stat().st_size, f.stat().st_mtime_ns] for f in files if f.is_file()]


def prepare_trials(
    recordings: Sequence[Path], options: ReplayOptions, out: Path, say: Any = print,
    tasks: Sequence[str] = (),
) -> list[RankTrial]:
    """
    Return every usable trial of the recordings; say one line per trial found or left out.

    `tasks`: each recording's task file ('' or none: the options'), e.g. its recorded motion.
    Split recordings are written under `out` once (kept while the recording, the options, the
    task file and the split's thresholds are the same: a rerun reads them back).
    """
    trials: list[RankTrial] = []
    names: set[str] = set()
    for i, path in enumerate(recordings):
        base = path.name
        while base in names:
            base += '_'
        names.add(base)
        own = replace(options, task=tasks[i]) if i < len(tasks) and tasks[i] else options
        with BagReader(path) as reader:
            if reader.trial is None:
                trials.extend(_split_one(reader, path, base, own, out / base, say))
                continue
            t = reader.trial
            frames = reader.message_counts.get(reader.cloud_topic(), 0)
        trials.append(
            RankTrial(base, t.cloth, t.primitive, str(path), str(path), 0, 'metadata', 0.0,
                      frames, t.change_of_phase_frame)
        )
        say(f'{path}: one trial ({t.cloth} {t.primitive}, trial metadata)')
    return trials


def reference_error(trials: Sequence[RankTrial]) -> dict[str, Any] | None:
    """
    Return the bundled reference all the trials were made by and its numerical error, or None.

    Read from each bag's trial metadata (`source: synthetic: reference <name> ...`); None where any
    trial is a recording, or the trials come from different references.
    """
    found = set()
    for t in trials:
        if t.source != 'metadata':
            return None
        with BagReader(Path(t.bag)) as reader:
            source = reader.trial.source if reader.trial is not None else ''
        prefix = 'synthetic: reference '
        name = next((n for n in REFERENCE_ERRORS if source.startswith(prefix + n)), None)
        if name is None:
            return None
        found.add(name)
    if len(found) != 1:
        return None
    (name,) = found
    return {'reference': name, 'error_m': REFERENCE_ERRORS[name],
            'source': REFERENCE_ERROR_SOURCE}


def _split_one(
    reader: BagReader, path: Path, base: str, options: ReplayOptions, out: Path, say: Any
) -> list[RankTrial]:
    """Split one plain recording into trials written as bags under `out`."""
    task = replay_task(options)
    stamp = {'recording': _identity(path), 'options': repr(options), 'split': split_settings(),
             'task_sha256': task.sha256}
    done = out / 'trials.json'
    if done.exists():
        try:
            kept = json.loads(done.read_text())
            if kept.get('stamp') == json.loads(json.dumps(stamp)):
                for line in kept['lines']:
                    say(line)
                return [RankTrial(**t) for t in kept['trials']]
        except (ValueError, TypeError, KeyError):
            pass  # damaged: split again
    if task.recorded is not None or options.start_time:
        lines, found = _one_trial(reader, path, base, options, out)
        for line in lines:
            say(line)
        done.write_text(json.dumps(
            {'stamp': stamp, 'lines': lines, 'trials': [f.as_dict() for f in found]}, indent=1
        ))
        return found
    rec = read_frames(reader, options)
    split = split_recording(reader, options, rec.stamps, rec.clouds)
    if split.trials and not split.usable and options.motion != 'task':
        raise AlignmentError(mismatch_error(split, options))  # as `run` refuses it
    targets = full_targets(options.primitive, options.rate_hz)
    end_ns = targets.stamp_ns(len(targets) - 1) - int(round(targets.quintic_start * 1e9))
    lines, found = [], []
    if not split.trials:
        lines.append(f'{path}: no trial found ({split.source}): {split.reason}; left out')
    for t in split.trials:
        first = ((t.start.bag_ns if t.start else t.first_ns) - split.origin_ns) / 1e9
        last = (t.last_ns - split.origin_ns) / 1e9
        where = f'{path}: trial {t.number}: bag time {first:.1f}-{last:.1f} s'
        if not t.usable or t.start is None:
            lines.append(f'{where}, left out: {t.reason}')
            continue
        frames = [
            (s - t.start.bag_ns, c)
            for s, c in zip(rec.stamps, rec.clouds)
            if 0 <= s - t.start.bag_ns <= end_ns and len(c)
        ]
        cop = None
        if options.primitive == 'dynamic':
            contact = first_table_contact(c for _, c in frames).index
            cop = None if contact is None else int(round(frames[contact][0] * REAL_FPS / 1e9))
        info = TrialInfo(
            cloth=options.cloth,
            trial=t.number,
            primitive=options.primitive,
            change_of_phase_frame=cop,
            source=f'repetition {t.number} of {path.name} ({t.start.method})',
            fps=REAL_FPS,
        )
        bag = out / f'trial{t.number}'
        with BagWriter(bag, info, overwrite=True) as writer:
            for t_ns, points in frames:
                writer.write_cloud(CLOUD_TOPIC, t_ns, points)
        cop_text = f'change of phase at frame {cop}, detected' if cop is not None else (
            'no change of phase' if options.primitive == 'dynamic' else 'scored over its length'
        )
        lines.append(
            f'{where}, {len(frames)} frames, start +/- {t.start.precision_s * 1e3:.1f} ms '
            f'({split.source}), {cop_text}'
        )
        found.append(
            RankTrial(f'{base}_trial{t.number}', options.cloth, options.primitive, str(bag),
                      str(path), t.number, split.source, t.start.precision_s, len(frames), cop)
        )
    for line in lines:
        say(line)
    out.mkdir(parents=True, exist_ok=True)
    done.write_text(json.dumps(
        {'stamp': stamp, 'lines': lines, 'trials': [f.as_dict() for f in found]}, indent=1
    ))
    return found


def _one_trial(
    reader: BagReader, path: Path, base: str, options: ReplayOptions, out: Path
) -> tuple[list[str], list[RankTrial]]:
    """
    Write a recording of a recorded motion, or one given --start-time, as one trial bag.

    The bag carries the task file it was recorded along (a recorded motion, a --task).
    """
    plan = plan_replay(reader, options)  # the start is the recorded motion's or given: no engine
    cop = plan.change_of_phase['frame']
    info = TrialInfo(cloth=options.cloth, trial=0, primitive=options.primitive,
                     change_of_phase_frame=cop, fps=REAL_FPS,
                     source=f'recorded motion of {path.name} ({plan.start.method})')
    bag = out / 'trial0'
    with BagWriter(bag, info, overwrite=True) as writer:
        for t_ns, points in plan.frames:
            writer.write_cloud(CLOUD_TOPIC, t_ns, points)
    task = replay_task(options)
    if options.task:
        shutil.copyfile(options.task, bag / TASK_IN_BAG)
    cop_text = ('no change of phase' if cop is None
                else f'change of phase at frame {cop}, {plan.change_of_phase["source"]}')
    along = (f'its recorded motion ({task.recorded.source}' if task.recorded
             else f'the task {task.name} ({plan.start.method}')
    line = (f'{path}: one trial along {along}, {task.duration:.2f} s), {len(plan.frames)} '
            f'frames, {cop_text}')
    trial = RankTrial(base, options.cloth, options.primitive, str(bag), str(path), 0,
                      plan.start.method, plan.start.precision_s, len(plan.frames), cop,
                      str(bag / TASK_IN_BAG) if options.task else '',
                      task.sha256 if options.task else '')
    return [line], [trial]


def _window(bag: str, primitive: str) -> list[tuple[int, np.ndarray]]:
    """Return a trial bag's frames (t ns from the start, points) of the scored window."""
    cut, frames = bag_clouds(bag)
    return [
        (s, p)
        for s, p, _ in frames
        if len(p) and (primitive != 'dynamic' or cut is None or round(s / 1e9 * REAL_FPS) < cut)
    ]


def floor_distance(bag_a: str, bag_b: str, primitive: str, vertices: int) -> float:
    """
    Return the one-sided L1 CD from trial A's clouds to trial B's, frame by frame in time.

    Each frame of A's window is paired with B's frame nearest in time (from the start of the
    motion); A's cloud is subsampled to `vertices` points (seed FLOOR_SEED) so that the figure
    compares with an engine's mesh of that many vertices; the mean over A's frames.
    """
    a, b = _window(bag_a, primitive), _window(bag_b, primitive)
    if not a or not b:
        return float('nan')
    rng = np.random.default_rng(FLOOR_SEED)
    b_times = np.array([s for s, _ in b])
    values = []
    for s, points in a:
        j = int(np.argmin(np.abs(b_times - s)))
        pick = rng.choice(len(points), min(vertices, len(points)), replace=False)
        values.append(RealCloud(b[j][1]).chamfer_hausdorff(points[pick])[0])
    return float(np.mean(values))


def floor(trials: Sequence[RankTrial], vertices: int) -> dict[str, Any]:
    """Return the floor of a group: every ordered pair's distance, their mean, min and max."""
    pairs: list[tuple[str, str, float]] = []
    for a in trials:
        for b in trials:
            if a is not b:
                pairs.append((a.name, b.name, floor_distance(a.bag, b.bag, a.primitive, vertices)))
    values = np.array([v for _, _, v in pairs if np.isfinite(v)])
    return {
        'pairs': pairs,
        'mean': float(values.mean()) if len(values) else None,
        'min': float(values.min()) if len(values) else None,
        'max': float(values.max()) if len(values) else None,
        'vertices': vertices,
        'seed': FLOOR_SEED,
    }
