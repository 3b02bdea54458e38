"""
A task as data: the grippers' motion, its settle phase and the window its metrics average over.

The paper's two tasks are the shipped files config/tasks/<primitive>.yaml; `--task FILE` names a
user's own in the same format (docs/own-recording.md, "A task file"). A recorded motion
(`--gripper-frames`, `--targets-topic`) is a task file too, of the grippers' samples instead of
quintic segments (data/recorded_motion.py writes it). `load_task` reads and checks a file once
per process while it is unchanged; a bad file is one InputError naming the file and the field.
"""

from __future__ import annotations

from dataclasses import dataclass
import hashlib
import math
from pathlib import Path
from typing import Any, Union

from cloth_bench_ros import validation
from cloth_bench_ros.core.quintic import QuinticChain, QuinticSegment
from cloth_bench_ros.errors import InputError, user_path
from cloth_bench_ros.paths import share_dir
from cloth_bench_ros.safe_io import load_yaml_bounded, read_text_bounded, UnsafeInputError
import numpy as np

SHIPPED = ('dynamic', 'quasi_static')  # config/tasks/<name>.yaml
WINDOWS = ('before_table_contact', 'whole_motion')
MAX_TASK_BYTES = 50_000_000  # a recorded motion: ~50 bytes a sample
MAX_SAMPLES = 500_000
MAX_SEGMENTS = 1000  # per chain
MAX_DURATION_S = 3600.0  # a segment, a settle phase
ARMS = ('left', 'right')
AXES = ('x', 'y', 'z')

Axis = Union[QuinticChain, float]  # a chain, or a value held for the whole motion


@dataclass(frozen=True, eq=False)
class RecordedMotion:
    """The grippers' recorded positions, in the scene's frame, from the motion's start."""

    source: str  # e.g. 'tf frames left_gripper,right_gripper' or 'targets topic /targets'
    frame: str  # the clouds' frame, which the grippers were resolved into
    start_ns: int  # bag stamp of t = 0
    to_scene: tuple[float, ...]  # 16 numbers, row-major: that frame -> the scene's
    table_z: float | None  # m, the table top in that frame; None: no table
    table_source: str  # where table_z comes from
    t: np.ndarray  # (n,) s from the start, increasing
    left: np.ndarray  # (n, 3) m, in the scene's frame
    right: np.ndarray

    def at(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return left and right (n, 3) at times t: linear between samples, held outside."""
        def axes(p: np.ndarray) -> np.ndarray:
            return np.stack([np.interp(t, self.t, p[:, i]) for i in range(3)], axis=1)
        return axes(self.left), axes(self.right)


@dataclass(frozen=True)
class Task:
    """One task: settle phase, grasp pose, per-arm motion (absolute), orientation, window."""

    name: str  # the shipped task's name, or the file's stem
    path: str  # the file it was read from
    sha256: str  # of the file's bytes
    settle: tuple[float, float, float]  # s: hold at the start, linear move, hold at the grasp
    grasp: tuple[tuple[float, ...], tuple[float, ...]]  # m: left, right position at the start
    left: tuple[Axis, Axis, Axis]  # x, y, z in metres
    right: tuple[Axis, Axis, Axis]
    roll: Axis  # radians
    pitch: float  # radians
    yaw: float  # radians
    window: str  # one of WINDOWS
    # followed instead of the axes (which then hold its first positions)
    recorded: RecordedMotion | None = None

    @property
    def settle_duration(self) -> float:
        """Return the seconds from the run's start to the motion's."""
        return self.settle[0] + self.settle[1] + self.settle[2]

    @property
    def duration(self) -> float:
        """Return the motion's length in seconds: its longest chain, or the recording's."""
        if self.recorded is not None:
            return float(self.recorded.t[-1])
        chains = [a for a in (*self.left, *self.right, self.roll) if isinstance(a, QuinticChain)]
        return max((c.duration for c in chains), default=0.0)

    @property
    def suffix(self) -> str:
        """Return the metrics' suffix: d (scored before the table contact) or q (throughout)."""
        return 'd' if self.window == 'before_table_contact' else 'q'

    def record(self) -> dict[str, Any]:
        """Return what summary.json and cache keys hold of the task."""
        out: dict[str, Any] = {
            'task': self.name, 'task_file': self.path, 'task_sha256': self.sha256
        }
        if self.recorded is not None:
            out['motion'] = {
                'source': self.recorded.source,
                'frame': self.recorded.frame,
                'table_z': self.recorded.table_z,
                'table_source': self.recorded.table_source,
                'to_scene': list(self.recorded.to_scene),
            }
        return out


def task_file(name: str) -> Path:
    """Return the shipped file of task `name`."""
    return share_dir('config') / 'tasks' / f'{name}.yaml'


def _number(value: Any, where: str, low: float | None = None, high: float | None = None) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise InputError(f'{where}: expected a number, got {value!r}')
    if (low is not None and value < low) or (high is not None and value > high):
        raise InputError(f'{where}: {value!r} is outside [{low:g}, {high:g}]')
    return float(value)


def _triple(value: Any, where: str) -> tuple[float, float, float]:
    if not isinstance(value, list) or len(value) != 3:
        raise InputError(f'{where}: expected a list of 3 numbers, got {value!r}')
    a, b, c = (_number(v, f'{where}[{i}]') for i, v in enumerate(value))
    return a, b, c


def _mapping(value: Any, where: str, keys: tuple[str, ...]) -> dict:
    if not isinstance(value, dict):
        raise InputError(f'{where}: expected a mapping with keys {", ".join(keys)}')
    missing = [k for k in keys if k not in value]
    if missing:
        raise InputError(f'{where}: missing key {missing[0]}')
    unknown = [k for k in value if k not in keys]
    if unknown:
        raise InputError(f'{where}: unknown key {unknown[0]!r} (valid: {", ".join(keys)})')
    return value


def _axis(value: Any, where: str, origin: float) -> Axis:
    """Return a chain or a held value, its positions `origin + p`."""
    if not isinstance(value, list):
        return origin + _number(value, where)
    if not 1 <= len(value) <= MAX_SEGMENTS:
        raise InputError(f'{where}: expected 1 to {MAX_SEGMENTS} segments, got {len(value)}')
    segments = []
    for i, seg in enumerate(value):
        at = f'{where}[{i}]'
        seg = _mapping(seg, at, ('duration', 'start', 'end'))
        duration = _number(seg['duration'], f'{at}.duration', 0.0, MAX_DURATION_S)
        if duration <= 0.0:
            raise InputError(f'{at}.duration: must be more than 0 s')
        ends = []
        for key in ('start', 'end'):
            p, v, a = _triple(seg[key], f'{at}.{key}')
            ends.append((origin + p, v, a))
        segments.append(QuinticSegment(duration, ends[0], ends[1]))
    return QuinticChain(tuple(segments))


def _degrees(value: Any, where: str) -> Axis:
    """Return an angle axis given in degrees, in radians (each of p, v, a as math.radians)."""
    if not isinstance(value, list):
        return math.radians(_number(value, where))
    chain = _axis(value, where, 0.0)
    assert isinstance(chain, QuinticChain)
    r = math.radians
    return QuinticChain(tuple(
        QuinticSegment(s.duration, (r(s.start[0]), r(s.start[1]), r(s.start[2])),
                       (r(s.end[0]), r(s.end[1]), r(s.end[2])))
        for s in chain.segments
    ))


def _samples(value: Any, where: str, width: int) -> np.ndarray:
    """Return a list of numbers (width 1) or of `width`-lists as a finite float array."""
    if not isinstance(value, list) or not 2 <= len(value) <= MAX_SAMPLES:
        raise InputError(f'{where}: expected a list of 2 to {MAX_SAMPLES} samples')
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f'{where}: expected numbers only') from None
    shape = (len(value),) if width == 1 else (len(value), width)
    if array.shape != shape or not np.isfinite(array).all():
        raise InputError(f'{where}: expected {"numbers" if width == 1 else "[x, y, z] lists"}, '
                         'finite')
    return array


RECORDED_KEYS = ('source', 'frame', 'start_ns', 'to_scene', 'table_z', 'table_source', 't',
                 'left', 'right')


def _recorded(value: Any) -> RecordedMotion:
    """Return the recorded motion of a task file's `recorded` mapping."""
    rec = _mapping(value, 'recorded', RECORDED_KEYS)
    t = _samples(rec['t'], 'recorded.t', 1)
    if not (np.diff(t) > 0).all():
        raise InputError('recorded.t: the times must increase')
    if t[0] != 0.0:
        raise InputError('recorded.t: the first time must be 0 (the start of the motion)')
    left, right = (_samples(rec[k], f'recorded.{k}', 3) for k in ('left', 'right'))
    if len(left) != len(t) or len(right) != len(t):
        raise InputError('recorded.left, recorded.right: one sample per time in recorded.t')
    to_scene = _samples(rec['to_scene'], 'recorded.to_scene', 1)
    if len(to_scene) != 16:
        raise InputError('recorded.to_scene: expected 16 numbers (a row-major 4x4 matrix)')
    start = rec['start_ns']
    if isinstance(start, bool) or not isinstance(start, int) or start < 0:
        raise InputError(f'recorded.start_ns: expected a bag stamp in ns, got {start!r}')
    table = None if rec['table_z'] is None else _number(rec['table_z'], 'recorded.table_z')
    return RecordedMotion(
        str(rec['source']), str(rec['frame']), start, tuple(float(v) for v in to_scene), table,
        str(rec['table_source']), t, left, right,
    )


def _settle(value: Any) -> tuple[float, float, float]:
    settle = _mapping(value, 'settle', ('hold_start', 'move', 'hold_end'))
    a, b, c = (
        _number(settle[k], f'settle.{k}', 0.0, MAX_DURATION_S)
        for k in ('hold_start', 'move', 'hold_end')
    )
    return a, b, c


def parse_task(doc: Any, name: str, path: str, sha256: str) -> Task:
    """Return the Task of a parsed task file; InputError naming `path` and the field if bad."""
    try:
        if isinstance(doc, dict) and 'recorded' in doc:
            top = _mapping(doc, 'the file', ('settle', 'recorded', 'window'))
            rec = _recorded(top['recorded'])
            first_left, first_right = tuple(rec.left[0]), tuple(rec.right[0])
            return Task(
                name, path, sha256, _settle(top['settle']), (first_left, first_right),
                (first_left[0], first_left[1], first_left[2]),
                (first_right[0], first_right[1], first_right[2]), 0.0, 0.0, 0.0,
                validation.choice(top['window'], 'window', WINDOWS), rec,
            )
        top = _mapping(doc, 'the file', ('settle', 'grasp', 'motion', 'window'))
        phases = _settle(top['settle'])
        grasp = _mapping(top['grasp'], 'grasp', ARMS)
        left_at, right_at = (_triple(grasp[arm], f'grasp.{arm}') for arm in ARMS)
        motion = _mapping(top['motion'], 'motion', (*ARMS, 'roll', 'pitch', 'yaw'))
        arms = []
        for arm, origin in zip(ARMS, (left_at, right_at)):
            axes = _mapping(motion[arm], f'motion.{arm}', AXES)
            arms.append(tuple(
                _axis(axes[k], f'motion.{arm}.{k}', origin[i]) for i, k in enumerate(AXES)
            ))
        window = validation.choice(top['window'], 'window', WINDOWS)
        task = Task(
            name, path, sha256, (phases[0], phases[1], phases[2]), (left_at, right_at),
            arms[0], arms[1],  # type: ignore[arg-type]
            _degrees(motion['roll'], 'motion.roll'),
            math.radians(_number(motion['pitch'], 'motion.pitch')),
            math.radians(_number(motion['yaw'], 'motion.yaw')),
            window,
        )
    except InputError as exc:
        raise InputError(f'task file {path}: {exc}') from None
    if task.duration <= 0.0:
        raise InputError(f'task file {path}: motion: no axis has a segment (the motion is empty)')
    return task


_TASKS: dict[tuple, Task] = {}  # parsed task files, by path, size and modification time


def load_task(primitive: str, path: str | Path | None = None) -> Task:
    """
    Return the task of a file (`--task`), else the shipped task `primitive`.

    Parsed once per process while the file is unchanged.
    """
    shown = str(path or '')
    if not path:
        if primitive not in SHIPPED:
            raise InputError(f'unknown primitive {primitive!r} (valid: {", ".join(SHIPPED)})')
        path, shown = task_file(primitive), f'config/tasks/{primitive}.yaml'
    path = Path(path)
    with user_path(path):
        st = path.stat()
    key = (str(path.resolve()), st.st_size, st.st_mtime_ns)
    if key not in _TASKS:
        try:
            text = read_text_bounded(path, MAX_TASK_BYTES)
            doc = load_yaml_bounded(text, f'task file {shown}')
        except UnsafeInputError as exc:
            raise InputError(str(exc)) from None
        sha = hashlib.sha256(text.encode('utf-8')).hexdigest()
        if len(_TASKS) >= 64:
            _TASKS.clear()
        _TASKS[key] = parse_task(doc, path.stem, shown, sha)
    return _TASKS[key]
