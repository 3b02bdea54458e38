"""
What the recorder replays from a bag: every frame of the topic, accounted for.

`plan_replay` reads the cloud topic once: decodes each cloud (organized, with rgb and NaNs or
not), moves it from its frame_id to `world` (the bag's /tf_static and /tf, or a fixed 4x4),
cleans it, finds the start of the quintic part in bag time, and sorts every frame into exactly
one of: before the start, after the trajectory, empty (after cleaning), or to send. The counts
add up to the frames on the topic; the evaluator then accounts for those it was sent.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from typing import Any

from cloth_bench_ros.core import pointcloud2
from cloth_bench_ros.core.cleaning import clean, CleaningConfig, CleaningStats, scene_cleaning
from cloth_bench_ros.core.phase import first_table_contact
from cloth_bench_ros.core.task_data import load_task, Task
from cloth_bench_ros.core.trajectory import full_targets
from cloth_bench_ros.data import alignment, trials
from cloth_bench_ros.data.bag_reader import BagReader, decode_cloud, IRREGULAR_TOLERANCE
from cloth_bench_ros.data.errors import BagError
from cloth_bench_ros.data.messages import POSE_ARRAY
from cloth_bench_ros.data.tf_buffer import apply, TF_MESSAGE, TF_TOPICS, TfBuffer, TransformError
from cloth_bench_ros.data.trial import TARGETS_TOPIC, TrialInfo
from cloth_bench_ros.errors import InputError
from cloth_bench_ros.options import OPTIONS
import numpy as np

WORLD = 'world'
CLEAN_MODES = OPTIONS['clean'].choices
TABLE_MODES = OPTIONS['table_plane'].choices


@dataclass(frozen=True)
class ReplayOptions:
    """What the bag does not say, and how to treat it (CLI options / recorder parameters)."""

    cloth: str = OPTIONS['cloth'].default
    primitive: str = OPTIONS['primitive'].default
    task: str = ''  # a task file; '': the shipped task of `primitive`
    # recorded: refuse a recording whose motion does not match the task; task: score it anyway
    motion: str = OPTIONS['motion'].default
    change_of_phase_frame: int | None = None
    # "": the project's cloud topic, else the only PointCloud2 topic
    topic: str = OPTIONS['topic'].default
    # "": targets topic, bag stamps (project bags) or automatic
    start_time: str = OPTIONS['start_time'].default
    targets_topic: str = OPTIONS['targets_topic'].default  # "": TARGETS_TOPIC when the bag has it
    transform: tuple | None = None  # 16 numbers, row-major: replaces tf for every cloud
    clean: str = OPTIONS['clean'].default  # auto: on for bags without project metadata
    voxel: float = OPTIONS['voxel'].default
    # remove, keep, or auto: remove for dynamic (scored before contact), keep for quasi_static
    table_plane: str = OPTIONS['table_plane'].default
    rate_hz: float = OPTIONS['rate_hz'].default
    align_engine: str = OPTIONS['align_engine'].default
    search: alignment.SearchSettings = alignment.SearchSettings()
    # the repetition to score (1-based); 0: the only one, else the first usable
    trial: int = OPTIONS['trial'].default
    # a cloud-only start: 'simulation' (align_engine) or 'onset'
    align: str = OPTIONS['align'].default


@dataclass
class ReplayPlan:
    """Frames to send (t_ns from the quintic part's start, world points) and the accounting."""

    trial: TrialInfo
    topic: str
    frames_in_bag: int
    start: alignment.StartTime
    frames: list[tuple[int, np.ndarray]] = field(default_factory=list)
    counts: dict[str, int] = field(default_factory=dict)
    cleaning: CleaningStats | None = None
    cleaning_config: CleaningConfig | None = None
    frames_source: str = ''
    nan_points_dropped: int = 0
    irregular_intervals: int = 0  # stamp steps off 1/fps by more than IRREGULAR_TOLERANCE
    change_of_phase: dict[str, Any] = field(default_factory=dict)  # see `change_of_phase`
    split: trials.Split | None = None  # the repetitions found (recordings without a start)
    trial_scored: int = 0  # which of them is scored (0: the recording as one trial)
    targets_grasp_m: float | None = None  # x distance of the recorded grippers at their start

    def accounting(self) -> dict[str, Any]:
        """Return the recorder's share of the frame accounting, for the summary."""
        return {
            'topic': self.topic,
            'frames_in_bag': self.frames_in_bag,
            **self.counts,
            'start': self.start.as_dict(),
            'frames': self.frames_source,
            'change_of_phase': self.change_of_phase,
            'targets_grasp_m': self.targets_grasp_m,
            'nan_points_dropped': self.nan_points_dropped,
            'irregular_intervals': self.irregular_intervals,
            'trials': None if self.split is None else {
                **self.split.as_dict(), 'scored': self.trial_scored
            },
            'cleaning': (
                None
                if self.cleaning is None
                else {
                    **self.cleaning.as_dict(),
                    'settings': asdict(self.cleaning_config) if self.cleaning_config else None,
                }
            ),
        }


def _trial(reader: BagReader, options: ReplayOptions, topic: str) -> TrialInfo:
    if reader.trial is not None:
        return reader.trial
    return TrialInfo(
        cloth=options.cloth,
        trial=0,
        primitive=options.primitive,
        change_of_phase_frame=options.change_of_phase_frame,
        source=f'plain rosbag2 recording {reader.path}, topic {topic}',
    )


def _to_world(reader: BagReader, options: ReplayOptions) -> tuple[Any, str]:
    """Return a function (frame_id, stamp_ns) -> 4x4 into world, and where it comes from."""
    recorded = replay_task(options).recorded
    if recorded is not None and options.transform is not None:
        raise InputError('--transform and a recorded motion: the recorded motion sets the frame')
    if options.transform is not None:
        fixed = np.asarray(options.transform, dtype=float).reshape(4, 4)
        return (lambda frame, stamp: fixed), '--transform matrix applied to every cloud'
    buffer = TfBuffer()
    tf_topics = [t for t in TF_TOPICS if reader.topics.get(t) == TF_MESSAGE]
    if tf_topics:
        buffer.add_messages((topic, msg) for topic, _, msg in reader.messages(tf_topics))
    source = f'tf from {", ".join(tf_topics)}' if tf_topics else 'clouds already in world'
    if recorded is not None:  # into the grippers' frame, then turned into the scene's
        to_scene = np.asarray(recorded.to_scene).reshape(4, 4)
        return (
            lambda frame, stamp: to_scene @ buffer.lookup(recorded.frame, frame, stamp)
        ), f"{recorded.frame} turned into the scene (the recorded grippers' start)"
    return (lambda frame, stamp: buffer.lookup(WORLD, frame, stamp)), source


def _targets(reader: BagReader, topic: str) -> tuple[list[int], list[np.ndarray]]:
    stamps, positions = [], []
    for _, stamp, msg in reader.messages([topic]):
        stamps.append(stamp)
        positions.append(np.array([[p.position.x, p.position.y, p.position.z] for p in msg.poses]))
    return stamps, positions


def cleaning_config(options: ReplayOptions, project_bag: bool) -> CleaningConfig | None:
    """Return the cleaning of a replay, or None when off (project bags are cleaned already)."""
    if options.clean not in CLEAN_MODES:
        raise InputError(f'clean mode {options.clean!r} is not one of {", ".join(CLEAN_MODES)}')
    if options.clean == 'off' or (options.clean == 'auto' and project_bag):
        return None
    if options.table_plane not in TABLE_MODES:
        raise InputError(
            f'table plane mode {options.table_plane!r} is not one of {", ".join(TABLE_MODES)}'
        )
    # Removing the plane also removes cloth lying flat on the table, which the quasi-static drag
    # scores.
    task = replay_task(options)
    remove = options.table_plane == 'remove' or (
        options.table_plane == 'auto' and task.window == 'before_table_contact'
    )
    return replace(scene_cleaning((task,), options.voxel), table_plane=remove)


@dataclass
class RecordedFrames:
    """Every frame of a bag's cloud topic in world, cleaned where asked, with how."""

    topic: str
    trial: TrialInfo
    project_bag: bool
    stamps: list[int]
    clouds: list[np.ndarray]
    frames_source: str
    config: CleaningConfig | None
    stats: CleaningStats | None
    nan_dropped: int


def read_frames(reader: BagReader, options: ReplayOptions) -> RecordedFrames:
    """Read, transform and clean every frame of the cloud topic (BagError on a bad frame)."""
    topic = reader.cloud_topic(options.topic or None)
    project_bag = reader.trial is not None
    trial = _trial(reader, options, topic)
    to_world, frames_source = _to_world(reader, options)
    config = cleaning_config(options, project_bag)
    stats = CleaningStats() if config is not None else None
    stamps, clouds, nan_dropped = [], [], 0
    for index, (_, _, stamp, cdr) in enumerate(reader.raw_messages([topic])):
        points, frame_id = decode_cloud(reader.path, topic, index, stamp, cdr)
        try:
            matrix = to_world(frame_id, stamp)
        except TransformError as exc:
            raise BagError(f'bag {reader.path}: frame {index} on {topic}: {exc}') from None
        points = (
            apply(matrix, points.reshape(-1, 3)) if not np.allclose(matrix, np.eye(4)) else points
        )
        if config is not None:
            points = clean(points, config, stats)
        else:
            points, dropped = pointcloud2.drop_nan(points)
            nan_dropped += dropped
        stamps.append(stamp)
        clouds.append(points)
    if not stamps:
        raise BagError(f'bag {reader.path}: topic {topic} holds no message')
    return RecordedFrames(
        topic, trial, project_bag, stamps, clouds, frames_source, config, stats, nan_dropped
    )


def plan_replay(reader: BagReader, options: ReplayOptions, reference=None) -> ReplayPlan:
    """
    Read, transform, clean, align and sort every frame of the topic (see module doc).

    `reference` is a callable (seconds) -> (t, vertices) of the reference simulation, needed
    only when the start must be searched automatically.
    """
    rec = read_frames(reader, options)
    topic, trial, project_bag = rec.topic, rec.trial, rec.project_bag
    stamps, clouds, stats, config = rec.stamps, rec.clouds, rec.stats, rec.config
    frames_source, nan_dropped = rec.frames_source, rec.nan_dropped
    recorded = replay_task(options).recorded is not None
    split = None if project_bag or options.start_time or recorded else split_recording(
        reader, options, stamps, clouds
    )
    start, chosen, region = _start(
        reader, options, project_bag, stamps, clouds, reference, split
    )
    targets = full_targets(replay_task(options), options.rate_hz)
    end_ns = targets.stamp_ns(len(targets) - 1) - int(round(targets.quintic_start * 1e9))
    plan = ReplayPlan(
        trial,
        topic,
        len(stamps),
        start,
        cleaning=stats,
        cleaning_config=config,
        frames_source=frames_source,
        nan_points_dropped=nan_dropped if stats is None else stats.non_finite,
        split=split,
        trial_scored=chosen,
    )
    targets_topic = options.targets_topic or ('' if project_bag else TARGETS_TOPIC)
    if targets_topic and reader.topics.get(targets_topic) == POSE_ARRAY:
        plan.targets_grasp_m = recorded_grasp(reader, targets_topic)
    counts = {'before_start': 0, 'after_trajectory': 0, 'empty_after_cleaning': 0, 'to_send': 0}
    if chosen:
        counts['other_trials'] = 0
    # A frame within the start's precision of it is at the start (not before it).
    tolerance = max(
        int(round(start.precision_s * 1e9)), 1000
    )  # 1 us: stamps given in decimal seconds
    for stamp, points in zip(stamps, clouds):
        t_ns = stamp - start.bag_ns
        t_ns = 0 if -tolerance <= t_ns < 0 else t_ns
        if chosen and not region[0] < stamp < region[1]:
            counts['other_trials'] += 1
        elif t_ns < 0:
            counts['before_start'] += 1
        elif t_ns > end_ns:
            counts['after_trajectory'] += 1
        elif len(points) == 0:
            counts['empty_after_cleaning'] += 1
        else:
            counts['to_send'] += 1
            plan.frames.append((t_ns, points))
    plan.counts = counts
    plan.change_of_phase = change_of_phase(trial, options, project_bag, plan.frames)
    trial.change_of_phase_frame = plan.change_of_phase['frame']
    period = 1e9 / trial.fps
    steps = np.diff(np.asarray(stamps, dtype=np.int64))
    off = np.abs(steps.astype(np.float64) - period)
    plan.irregular_intervals = int(np.sum(off > IRREGULAR_TOLERANCE * period))
    return plan


def replay_task(options: ReplayOptions) -> Task:
    """Return the task the recording is replayed for: its file's, else the shipped one."""
    return load_task(options.primitive, options.task)


def recorded_grasp(reader: BagReader, topic: str) -> float | None:
    """Return the x distance between the first two poses of a recording's first gripper targets."""
    messages = reader.messages([topic])
    first = next(messages, None)
    close = getattr(messages, 'close', None)
    if close is not None:  # a generator: its file is let go now
        close()
    if first is None or len(first[2].poses) < 2:
        return None
    poses = first[2].poses
    return abs(poses[1].position.x - poses[0].position.x)


def change_of_phase(
    trial: TrialInfo,
    options: ReplayOptions,
    project_bag: bool,
    frames: list[tuple[int, np.ndarray]],
) -> dict[str, Any]:
    """
    Return the frame that ends a dynamic trial's scored window, and where it comes from.

    In order: the option (`--change-of-phase-frame`), the bag's trial metadata, else the first
    table contact found in `frames` ((t_ns from the start, world points) in time order). The
    quasi-static task has none: it is scored over its whole length.
    """
    if replay_task(options).window != 'before_table_contact':
        return {
            'frame': None,
            'source': 'none',
            'reason': f'the {replay_task(options).name} task is scored over its whole length',
        }
    if options.change_of_phase_frame is not None:
        return {
            'frame': options.change_of_phase_frame,
            'source': 'option',
            'reason': '--change-of-phase-frame',
        }
    if project_bag and trial.change_of_phase_frame is not None:
        return {
            'frame': trial.change_of_phase_frame,
            'source': 'metadata',
            'reason': "the bag's trial metadata",
        }
    found = first_table_contact(points for _, points in frames)
    if found.index is None:
        return {'frame': None, 'source': 'none', 'reason': found.reason}
    t_ns = frames[found.index][0]
    return {
        'frame': int(round(t_ns * trial.fps / 1e9)),
        'source': 'detected',
        'reason': found.reason,
        't_s': t_ns / 1e9,
    }


def split_recording(
    reader: BagReader, options: ReplayOptions, stamps: list[int], clouds: list[np.ndarray]
) -> trials.Split:
    """Return the repetitions of the task in a recording: from its targets topic, else clouds."""
    topic = options.targets_topic or TARGETS_TOPIC
    if reader.topics.get(topic) == POSE_ARRAY:
        split = trials.split_targets(*_targets(reader, topic), topic, replay_task(options))
    else:
        split = trials.split_clouds(stamps, clouds, replay_task(options))
    split.origin_ns = min(stamps)
    targets = full_targets(replay_task(options), options.rate_hz)
    end_ns = targets.stamp_ns(len(targets) - 1) - int(round(targets.quintic_start * 1e9))
    at = np.asarray(stamps, dtype=np.int64)
    for found in split.trials:
        if found.start is not None:
            since = at - found.start.bag_ns
            found.frames = int(np.count_nonzero((since >= 0) & (since <= end_ns)))
    return split


def mismatch_error(split: trials.Split, options: ReplayOptions) -> str:
    """Return the one line that refuses a recording whose motion does not match the task."""
    reasons = '; '.join(f'{t.number}: {t.reason}' for t in split.trials)
    return (
        f"the recording's motion does not match the task {replay_task(options).name} "
        f'({split.source}: {reasons}): give the motion it holds with --gripper-frames '
        "LEFT,RIGHT or --targets-topic T (or --motion task to score the task's motion "
        'anyway)'
    )


def choose_trial(split: trials.Split, number: int) -> trials.FoundTrial:
    """Return trial `number` (1-based) of a split, or the first usable; AlignmentError if none."""
    found = ', '.join(str(t.number) for t in split.usable) or 'none'
    if number:
        match = [t for t in split.trials if t.number == number]
        if not match:
            raise alignment.AlignmentError(
                f'--trial {number}: the recording holds {len(split.trials)} trials '
                f'(usable: {found})'
            )
        if not match[0].usable:
            raise alignment.AlignmentError(
                f'--trial {number} is left out: {match[0].reason} (usable: {found})'
            )
        return match[0]
    if not split.usable:
        raise alignment.AlignmentError(
            f'no trial of the task in the recording ({split.source}): '
            + (split.reason or '; '.join(f'{t.number}: {t.reason}' for t in split.trials))
        )
    return split.usable[0]


def _start(
    reader: BagReader,
    options: ReplayOptions,
    project_bag: bool,
    stamps: list[int],
    clouds: list[np.ndarray],
    reference,
    split: trials.Split | None,
) -> tuple[alignment.StartTime, int, tuple[float, float]]:
    """Return the start, the trial scored (0: the recording as one) and that trial's region."""
    everything = (-np.inf, np.inf)
    recorded = replay_task(options).recorded
    if recorded is not None:
        method = f"the recorded motion's start ({recorded.source}: the first cloud)"
        return alignment.StartTime(recorded.start_ns, method, 0.0), 0, everything
    if options.start_time:
        return alignment.given_start(options.start_time, min(stamps)), 0, everything
    if split is not None and split.trials and not split.usable and options.motion != 'task':
        raise alignment.AlignmentError(mismatch_error(split, options))
    if options.align not in ('simulation', 'onset'):
        raise alignment.AlignmentError(f'align {options.align!r} is not simulation or onset')
    if split is not None and (options.trial or len(split.trials) > 1):
        chosen = choose_trial(split, options.trial)
        others = [t for t in split.trials if t is not chosen]
        low = max([t.last_ns for t in others if t.number < chosen.number], default=-np.inf)
        later = [t for t in others if t.number > chosen.number]
        high = min([t.start.bag_ns if t.start else t.first_ns for t in later], default=np.inf)
        assert chosen.start is not None  # a usable trial has its fitted start
        start = chosen.start
        if options.align == 'simulation' and not split.source.startswith('targets'):
            if reference is None:
                raise alignment.AlignmentError('automatic alignment needs a reference simulation')
            inside = [(st, c) for st, c in zip(stamps, clouds) if low < st < high]
            t_ref, states = reference(options.search.window)
            start = alignment.search_start(
                [st for st, _ in inside], [c for _, c in inside], t_ref, states, options.search
            )
        return start, chosen.number, (low, high)
    targets_topic = options.targets_topic or (TARGETS_TOPIC if not project_bag else '')
    if options.targets_topic and reader.topics.get(targets_topic) != POSE_ARRAY:
        raise BagError(f'bag {reader.path} has no {POSE_ARRAY} topic {targets_topic}')
    if targets_topic and reader.topics.get(targets_topic) == POSE_ARRAY:
        start = alignment.targets_start(*_targets(reader, targets_topic), targets_topic)
        return start, 0, everything
    if project_bag:
        return alignment.StartTime(
            0, "bag stamps (the project's bags count from the start of the motion)", 0.0
        ), 0, everything
    if options.align == 'onset' and not (options.motion == 'task' and split and not split.usable):
        assert split is not None
        return choose_trial(split, 0).start or alignment.StartTime(0, '', 0.0), 0, everything
    if reference is None:
        raise alignment.AlignmentError('automatic alignment needs a reference simulation')
    t_ref, states = reference(options.search.window)
    return alignment.search_start(stamps, clouds, t_ref, states, options.search), 0, everything
