"""
The repetitions of the motion in a recording, found without any simulation engine.

A recording of a robot doing the task a few times holds several trials, with rest between them.
`split_targets` finds them in the recorded gripper targets; `split_clouds` in the clouds alone:

- motion: a frame moves when its mean nearest-neighbour distance to the cloud a lag earlier
  (the time the task's grippers take to move `LAG_DISTANCE` at their mean speed, within
  `LAG_RANGE_S`: 0.07 s for the fling, 0.54 s for the slow drag) is more than `MOTION_FACTOR`
  times the recording's rest level (the median of its quietest fifth) and more than
  `MOTION_FLOOR` above it; moving frames separated by less than the task's
  longest still phase plus `MERGE_MARGIN_S` are one motion. A motion shorter than `MIN_MOTION_S`
  is a jump (the cloth put back by hand between takes, a glitch), not a trial.
- start: the task's gripper path is known (core.trajectory), so the start of each motion is
  fitted, not thresholded. In the clouds: the grasped corners move as the grippers do, so each
  corner (the mean of the `CORNER_POINTS` cloud points nearest a task's gripper, in the frames at
  rest) is moved along the grippers' path from a candidate start, and the start is the one that
  keeps them on the cloud: the least sum of squared distances (each at most `CORNER_CAP`) from
  the moved corners to each frame's cloud, over the rest before the motion and `CORNER_FIT_S`
  past the latest start searched. A gentle start is seen late (the clouds show a motion once
  the grippers are some 0.1 m from rest: 0.9 s into the fling, 3.9 s into the slow drag), so
  the start is searched from the time the task's grippers take to move `LEAD_DISTANCE` before
  the first moving frame (its `detection_lead`). A corner a few cm inside the cloth, not its
  edge point, because a corner moved within the cloth's own plane stays on the cloud: the edge
  point would let the drag's first second (straight down) pull the start 0.1-0.2 s early. In
  recorded targets: their mid-point's displacement from rest is least-squares fitted by the
  task's, over the whole motion. Either way the precision is where the sum of squares rises by
  one noise variance (a 1-sigma interval, at least half the fine step). On camera-like copies
  of the bundled towel (cleaned) the clouds' start is 9-12 ms late on the fling with 0-5 mm
  noise (the cloth by its corners lags the grippers during the fling's accelerations; stated
  1-sigma 2-3 ms) and 8-18 ms early on the drag with 0-2 mm (stated 1-sigma 11-18 ms; with
  5 mm its slow motion falls apart into pieces the task does not match); targets give it
  exactly.
- a motion is a usable trial only when it matches the task: the fit's RMS residual at most
  `MAX_RESIDUAL` (targets: `MAX_TARGET_RESIDUAL`), the targets' scale within `SCALE_RANGE`, its
  duration at least `MIN_DURATION_FRACTION` of the task's (targets: within
  `TARGET_DURATION_TOLERANCE`) and, for clouds, at most the task's plus `MAX_SETTLE_S`. Anything
  else is reported with its reason and left out, never guessed at.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from cloth_bench_ros.core.trajectory import sample_quintic, TaskLike
from cloth_bench_ros.data.alignment import StartTime
import numpy as np
from scipy.spatial import cKDTree

LAG_DISTANCE = 0.03  # m the grippers move, on average, between the frames compared for motion
LAG_RANGE_S = (0.05, 1.0)
MOTION_FACTOR = 2.5  # x the rest level
MOTION_FLOOR = 0.004  # m above the rest level
MERGE_MARGIN_S = 0.5  # s added to the task's longest still phase
MIN_MOTION_S = 0.2  # s: shorter motions are jumps, not trials
CORNER_FIT_S = 2.0  # s past the latest start searched that the cloud fit covers
CORNER_CAP = 0.05  # m: a corner further from the cloud than this counts as this far
CORNER_GAP = 0.1  # m: at rest the cloud's nearest point to a gripper is at most this far
CORNER_POINTS = 30  # cloud points nearest each gripper at rest whose mean is its corner
FIT_PRE_S = 1.0  # s of rest before the motion the fit covers (at most)
LEAD_DISTANCE = 0.2  # m from rest the grippers have moved, at most, when the clouds show motion
MAX_RESIDUAL = 0.025  # m RMS, clouds
MAX_TARGET_RESIDUAL = 0.005  # m RMS, recorded targets
SCALE_RANGE = (0.5, 2.0)
MIN_DURATION_FRACTION = 0.75
TARGET_DURATION_TOLERANCE = 0.1  # fraction of the task's duration
MAX_SETTLE_S = 3.0  # s the cloth may keep moving after the grippers stop
COARSE_STEP_S = 0.005
FINE_STEP_S = 0.0005
TEMPLATE_RATE = 1000.0


@dataclass
class FoundTrial:
    """One motion found in a recording: where, how its start was fitted, and whether it is used."""

    number: int  # 1-based, in the order found
    first_ns: int  # bag time of the motion's first moving frame (or target)
    last_ns: int  # bag time of its last one
    start: StartTime | None  # fitted start of the task's motion
    residual_m: float = float('nan')  # RMS of the start's fit
    scale: float = float('nan')
    duration_s: float = 0.0  # from the start to the last moving frame
    usable: bool = False
    reason: str = ''  # why it is left out
    frames: int = 0  # frames from the start to the end of the task's motion

    def as_dict(self) -> dict[str, Any]:
        return {
            'number': self.number,
            'first_ns': self.first_ns,
            'last_ns': self.last_ns,
            'start': self.start.as_dict() if self.start else None,
            'residual_m': _finite(self.residual_m),
            'scale': _finite(self.scale),
            'duration_s': self.duration_s,
            'usable': self.usable,
            'reason': self.reason,
            'frames': self.frames,
        }


@dataclass
class Split:
    """The trials of a recording and how they were found."""

    source: str  # 'targets topic <name>' or 'clouds'
    trials: list[FoundTrial] = field(default_factory=list)
    jumps: int = 0  # motions shorter than MIN_MOTION_S
    reason: str = ''  # why nothing was found, when nothing was
    origin_ns: int = 0  # bag time of the recording's first frame

    @property
    def usable(self) -> list[FoundTrial]:
        return [t for t in self.trials if t.usable]

    def as_dict(self) -> dict[str, Any]:
        return {
            'source': self.source,
            'trials': [t.as_dict() for t in self.trials],
            'jumps': self.jumps,
            'reason': self.reason,
            'origin_ns': self.origin_ns,
        }


def _finite(value: float) -> float | None:
    return float(value) if np.isfinite(value) else None


def settings() -> dict[str, Any]:
    """Return every threshold and step of the split (a split kept by rank is kept while equal)."""
    return {name: value for name, value in globals().items() if name.isupper()}


def task_displacement(primitive: TaskLike) -> tuple[np.ndarray, np.ndarray]:
    """(t, d): the grippers' mid-point displacement (n, 3) from its start over the task."""
    targets = sample_quintic(primitive, TEMPLATE_RATE)
    mid = (targets.left + targets.right) / 2
    return targets.t, mid - mid[0]


def motion_lag(primitive: TaskLike) -> float:
    """Return the time (s) the task's grippers take to move LAG_DISTANCE at their mean speed."""
    t, d = task_displacement(primitive)
    path = float(np.sum(np.linalg.norm(np.diff(d, axis=0), axis=1)))
    return float(np.clip(LAG_DISTANCE * t[-1] / path, *LAG_RANGE_S))


def detection_lead(primitive: TaskLike) -> float:
    """Return how long (s) the clouds' first moving frame may follow the task's start."""
    t, d = task_displacement(primitive)
    return float(t[np.argmax(np.linalg.norm(d, axis=1) >= LEAD_DISTANCE)])


def longest_still(primitive: TaskLike) -> float:
    """Return the longest phase (s) in which the task's grippers do not move."""
    t, d = task_displacement(primitive)
    still = np.abs(np.diff(d, axis=0)).max(axis=1) < 1e-7
    longest = run = 0
    for flag in still:
        run = run + 1 if flag else 0
        longest = max(longest, run)
    return longest / TEMPLATE_RATE


def _template_at(t_ref: np.ndarray, d_ref: np.ndarray, tau: np.ndarray) -> np.ndarray:
    out = np.empty((len(tau), 3))
    for axis in range(3):
        out[:, axis] = np.interp(tau, t_ref, d_ref[:, axis], left=0.0, right=d_ref[-1, axis])
    return out


def _fit_cost(
    times: np.ndarray,
    position: np.ndarray,
    t_ref: np.ndarray,
    d_ref: np.ndarray,
    t0: float,
) -> tuple[float, float]:
    """
    (sum of squares, scale): position - rest against the template(times - t0) moved rigidly.

    The held part moves as the grippers do (scale 1); `scale` is the least-squares one, which
    tells a motion of another size or direction.
    """
    before = (times < t0) & (times >= t0 - FIT_PRE_S)
    disp = position - (position[before].mean(axis=0) if before.any() else position[0])
    g = _template_at(t_ref, d_ref, times - t0)
    gg = float(np.sum(g * g))
    scale = float(np.sum(g * disp) / gg) if gg > 0 else 0.0
    return float(np.sum((disp - g) ** 2)), scale


def fit_start(
    times: np.ndarray,
    position: np.ndarray,
    primitive: TaskLike,
    low: float,
    high: float,
) -> tuple[float, float, float, float]:
    """
    Fit the task's start time in [low, high] (s) to positions (n, 3) sampled at `times`.

    The displacement fitted is from the mean position in the FIT_PRE_S before the start; every
    sample given enters the fit. Returns (start, 1-sigma precision, RMS residual, scale).
    """
    t_ref, d_ref = task_displacement(primitive)
    coarse = np.arange(low, high + COARSE_STEP_S / 2, COARSE_STEP_S)
    costs = [_fit_cost(times, position, t_ref, d_ref, t0)[0] for t0 in coarse]
    best = float(coarse[int(np.argmin(costs))])
    reach = 8 * COARSE_STEP_S
    fine = best + np.arange(-reach, reach + FINE_STEP_S / 2, FINE_STEP_S)
    fine_costs = np.array([_fit_cost(times, position, t_ref, d_ref, t0)[0] for t0 in fine])
    i = int(np.argmin(fine_costs))
    start = float(fine[i])
    sse, scale = _fit_cost(times, position, t_ref, d_ref, start)
    n = len(times)
    # 1 sigma: the sum of squares rises by one noise variance (sse / (n - 2)) from its least.
    within = fine[fine_costs <= sse * (1.0 + 1.0 / max(1, n - 2))]
    half = (within.max() - within.min()) / 2 if len(within) else 0.0
    return start, max(half, FINE_STEP_S / 2), float(np.sqrt(sse / n)), scale


def _motion_runs(moving: np.ndarray, times: np.ndarray, gap_s: float) -> list[tuple[int, int]]:
    """Return [first, last] index pairs of moving runs, merged over still gaps below gap_s."""
    runs: list[list[int]] = []
    for i in np.nonzero(moving)[0]:
        if runs and times[i] - times[runs[-1][1]] <= gap_s:
            runs[-1][1] = int(i)
        else:
            runs.append([int(i), int(i)])
    return [(a, b) for a, b in runs]


def _check(trial: FoundTrial, task_s: float, targets: bool) -> None:
    """Mark the trial usable, or give the first reason it does not match the task."""
    limit = MAX_TARGET_RESIDUAL if targets else MAX_RESIDUAL
    low, high = SCALE_RANGE
    if targets:
        ok_duration = abs(trial.duration_s - task_s) <= TARGET_DURATION_TOLERANCE * task_s
        expected = f'{task_s:.2f} s +/- {TARGET_DURATION_TOLERANCE:.0%}'
    else:
        ok_duration = MIN_DURATION_FRACTION * task_s <= trial.duration_s <= task_s + MAX_SETTLE_S
        expected = f'{MIN_DURATION_FRACTION * task_s:.2f}-{task_s + MAX_SETTLE_S:.2f} s'
    if not ok_duration:
        trial.reason = (
            f'its motion lasts {trial.duration_s:.2f} s, the task {expected}: does not match'
        )
    elif not trial.residual_m <= limit:
        trial.reason = (
            f'its start fits the task with a residual of {trial.residual_m * 1e3:.1f} mm RMS '
            f'(at most {limit * 1e3:g} mm): does not match'
        )
    elif np.isfinite(trial.scale) and not low <= trial.scale <= high:
        trial.reason = (
            f'it moves {trial.scale:.2f} x as far as the task ({low:g}-{high:g} x): does not match'
        )
    else:
        trial.usable = True


def split_targets(
    stamps_ns: list[int], positions: list[np.ndarray], topic: str, primitive: TaskLike
) -> Split:
    """Find the repetitions of the task in recorded gripper targets (PoseArray positions)."""
    split = Split(f'targets topic {topic}')
    if len(stamps_ns) < 3:
        split.reason = f'targets topic {topic} holds {len(stamps_ns)} messages'
        return split
    if len({p.shape for p in positions}) != 1:
        split.reason = f'targets topic {topic}: messages with different numbers of poses'
        return split
    times = (np.asarray(stamps_ns, dtype=np.int64) - stamps_ns[0]) / 1e9
    mids = np.array([p.mean(axis=0) for p in positions])
    step = np.abs(np.diff(mids, axis=0)).max(axis=1)
    moving = np.concatenate([[False], step > 1e-9])

    def fit(first: int, low: float, high: float, last: int) -> Any:
        window = (times >= low) & (times <= times[last])
        if np.count_nonzero(window & (times < times[first])) < 2:
            return 'no rest before its motion to fit its start to'
        return fit_start(times[window], mids[window], primitive, low, high)

    return _split(split, times, fit, moving, stamps_ns[0], primitive)


def split_clouds(stamps_ns: list[int], clouds: list[np.ndarray], primitive: TaskLike) -> Split:
    """Find the repetitions of the task in world clouds (cleaned: the cloth, little else)."""
    split = Split('clouds')
    keep = [i for i, c in enumerate(clouds) if len(c) >= 10]
    if len(keep) < 10:
        split.reason = f'{len(keep)} frames hold a cloud of 10 points or more'
        return split
    times = (np.asarray([stamps_ns[i] for i in keep], dtype=np.int64) - stamps_ns[keep[0]]) / 1e9
    fps = (len(times) - 1) / max(times[-1] - times[0], 1e-9)
    lag_s = motion_lag(primitive)
    lag = max(1, int(round(lag_s * fps)))
    trees = [cKDTree(clouds[i]) for i in keep]
    change = np.full(len(keep), np.nan)
    for j in range(lag, len(keep)):
        change[j] = float(trees[j - lag].query(clouds[keep[j]])[0].mean())
    quiet = np.sort(change[np.isfinite(change)])
    rest = float(np.median(quiet[: max(1, len(quiet) // 5)]))
    threshold = max(MOTION_FACTOR * rest, rest + MOTION_FLOOR)
    # A frame `lag` after the last move still differs from the one before it: shift back.
    moved = np.nan_to_num(change, nan=0.0) > threshold
    moving = np.zeros(len(keep), bool)
    for j in np.nonzero(moved)[0].tolist():
        moving[max(0, j - lag + 1):j + 1] = True
    split.reason = '' if moving.any() else (
        f'no motion: no frame differs from the one {lag_s:.2f} s before by more than '
        f'{threshold * 1e3:.1f} mm (rest level {rest * 1e3:.1f} mm)'
    )
    corners = _CornerFit(trees, times, primitive)
    return _split(split, times, corners, moving, stamps_ns[keep[0]], primitive)


class _CornerFit:
    """The start fitted to where the cloud's grasped corners are: they move as the grippers do."""

    def __init__(self, trees: list[cKDTree], times: np.ndarray, primitive: TaskLike) -> None:
        self.trees, self.times = trees, times
        self.t_ref, self.d_ref = task_displacement(primitive)
        task = sample_quintic(primitive, TEMPLATE_RATE)
        self.grippers = np.array([task.left[0], task.right[0]])
        self.lead = detection_lead(primitive)

    def _patch_centres(self, frame: int) -> np.ndarray:
        """Return the mean of the CORNER_POINTS cloud points nearest each gripper (2, 3)."""
        tree = self.trees[frame]
        _, index = tree.query(self.grippers, [*range(1, min(CORNER_POINTS, tree.n) + 1)])
        return tree.data[index].mean(axis=1)

    def _sse(self, frames: np.ndarray, corners: np.ndarray, starts: np.ndarray) -> np.ndarray:
        """Return the sum of squared corner distances for each candidate start."""
        total = np.zeros(len(starts))
        for f in frames:
            shift = _template_at(self.t_ref, self.d_ref, self.times[f] - starts)
            where = (corners[None, :, :] + shift[:, None, :]).reshape(-1, 3)
            d = np.minimum(self.trees[f].query(where)[0], CORNER_CAP).reshape(len(starts), -1)
            total += np.sum(d * d, axis=1)
        return total

    def __call__(
        self, first: int, low: float, high: float, last: int
    ) -> tuple[float, float, float, float] | str:
        """Return (start, 1-sigma precision, RMS residual, NaN scale), or why it cannot fit."""
        times = self.times
        frames = np.nonzero((times >= low) & (times <= high + CORNER_FIT_S))[0]
        before = frames[times[frames] < times[first]]
        if len(before) < 2:
            return 'no rest before its motion to fit its start to'
        # The corners at rest: the frames a lead before the first moving one, else the first two.
        rest = before[times[before] < times[first] - self.lead]
        rest = rest if len(rest) >= 2 else before[:2]
        gap = float(np.mean([self.trees[f].query(self.grippers)[0] for f in rest]))
        if gap > CORNER_GAP:
            return (
                f"the cloud is {gap * 1e3:.0f} mm from the task's grippers at rest "
                f'(at most {CORNER_GAP * 1e3:g} mm): not the task (or the cloud not in world)'
            )
        corners = np.mean([self._patch_centres(f) for f in rest], axis=0)
        coarse = np.arange(low, high + COARSE_STEP_S / 2, COARSE_STEP_S)
        best = float(coarse[int(np.argmin(self._sse(frames, corners, coarse)))])
        reach = 4 * COARSE_STEP_S
        fine = best + np.arange(-reach, reach + FINE_STEP_S / 2, FINE_STEP_S)
        costs = self._sse(frames, corners, fine)
        i = int(np.argmin(costs))
        n = 2 * len(frames)
        within = fine[costs <= costs[i] * (1.0 + 1.0 / max(1, n - 1))]
        half = (within.max() - within.min()) / 2
        return float(fine[i]), max(half, FINE_STEP_S / 2), float(np.sqrt(costs[i] / n)), np.nan


def _split(
    split: Split,
    times: np.ndarray,
    fit: Any,
    moving: np.ndarray,
    base_ns: int,
    primitive: TaskLike,
) -> Split:
    """Turn moving samples into trials, each with its start from `fit(first, low, high)`."""
    t_ref, _ = task_displacement(primitive)
    task_s = float(t_ref[-1])
    targets = split.source.startswith('targets')
    runs = _motion_runs(moving, times, longest_still(primitive) + MERGE_MARGIN_S)
    previous_end = -np.inf
    for first, last in runs:
        if times[last] - times[first] < MIN_MOTION_S:
            split.jumps += 1
            previous_end = times[last]
            continue
        number = len(split.trials) + 1
        trial = FoundTrial(number, base_ns + _ns(times[first]), base_ns + _ns(times[last]), None)
        split.trials.append(trial)
        # Targets move from the start on; the clouds show a motion up to a lead after it.
        lead = 0.0 if targets else detection_lead(primitive)
        low = max(times[first] - lead - FIT_PRE_S, previous_end)
        previous_end = times[last]
        # The first moving sample is after the start; clouds flag a move up to a lag early.
        fitted = fit(first, low, times[first] + (0.0 if targets else motion_lag(primitive)), last)
        if isinstance(fitted, str):
            trial.reason = fitted
            continue
        start, precision, residual, scale = fitted
        trial.start = StartTime(
            base_ns + _ns(start), f'{split.source}, fitted to the task', precision
        )
        trial.residual_m, trial.scale = residual, scale
        trial.duration_s = float(times[last] - start)
        _check(trial, task_s, targets)
    if not split.trials and not split.reason:
        jumps = f' ({split.jumps} shorter jumps)' if split.jumps else ''
        split.reason = f'no motion longer than {MIN_MOTION_S:g} s{jumps}'
    return split


def _ns(seconds: float) -> int:
    return int(round(seconds * 1e9))
