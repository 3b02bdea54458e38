"""
Where the quintic part starts in a bag's time: given, read from recorded targets, or searched.

The automatic search simulates the reference (an engine, the run's cloth and primitive) from the
settle phase to `window` s into the motion and finds the bag time whose real frames, from `pre`
s before to `window` s after it, are closest to the simulated cloth (mean one-sided L1 Chamfer).
A coarse grid over the whole bag is refined around its best point; the precision stated is half
the fine step.
"""

from __future__ import annotations

from dataclasses import dataclass
from decimal import Decimal, InvalidOperation

from cloth_bench_ros.core.metrics import RealCloud
from cloth_bench_ros.core.trajectory import full_targets, TaskLike
from cloth_bench_ros.errors import ClothBenchError
from cloth_bench_ros.options import OPTIONS
import numpy as np

EPOCH_THRESHOLD_S = (
    1e9  # a --start-time this large is an absolute stamp, else seconds from the first message
)
MOTION_THRESHOLD = 0.001  # m: a gripper target this far from its first position has moved


class AlignmentError(ClothBenchError, ValueError):
    """No start of the motion can be found; str() says why."""


@dataclass(frozen=True)
class StartTime:
    """The bag time (ns) of the start of the quintic part and how it was found."""

    bag_ns: int
    method: str  # "bag stamps", "--start-time", "targets topic <name>", "automatic"
    precision_s: float  # half-width of the interval the start is known to lie in

    def as_dict(self) -> dict:
        return {'bag_ns': self.bag_ns, 'method': self.method, 'precision_s': self.precision_s}


@dataclass(frozen=True)
class SearchSettings:
    """The automatic search: the window compared and the grid (tests use a reduced one)."""

    window: float = OPTIONS['align_window'].default  # s of motion compared
    pre: float = 0.5  # s of rest before the motion compared
    coarse_step: float = OPTIONS['align_step'].default  # s
    fine_steps: int = 8  # the fine step is coarse_step / fine_steps
    min_coverage: float = 0.6  # fraction of the window's frames a candidate must have


def given_start(text: str, first_ns: int) -> StartTime:
    """`--start-time`: an absolute stamp (>= 1e9 s) or seconds from the bag's first message."""
    try:
        value = Decimal(text.strip())  # exact: an epoch stamp in float64 loses its nanoseconds
    except InvalidOperation:
        raise AlignmentError(f'start time {text!r} is not a number of seconds') from None
    if not value.is_finite():
        raise AlignmentError(f'start time {text!r} is not finite')
    ns = int((value * 1_000_000_000).to_integral_value())
    if value >= EPOCH_THRESHOLD_S:
        return StartTime(ns, '--start-time (absolute stamp)', 0.0)
    return StartTime(first_ns + ns, '--start-time (seconds from the first message)', 0.0)


def targets_start(stamps_ns: list[int], positions: list[np.ndarray], topic: str) -> StartTime:
    """Return the first recorded target at which a gripper has left its first position."""
    if not stamps_ns:
        raise AlignmentError(f'targets topic {topic} holds no message')
    first = positions[0]
    for k, (stamp, pos) in enumerate(zip(stamps_ns, positions)):
        if pos.shape != first.shape:
            raise AlignmentError(
                f'targets topic {topic}: message {k} has {len(pos)} poses, the first {len(first)}'
            )
        if np.abs(pos - first).max() > MOTION_THRESHOLD:
            # The motion began between the last target at rest and this one.
            period = (stamp - stamps_ns[k - 1]) / 1e9 if k > 0 else 0.0
            return StartTime(
                stamps_ns[k - 1] if k > 0 else stamp, f'targets topic {topic}', period / 2
            )
    raise AlignmentError(
        f'targets topic {topic}: the grippers never move more than {MOTION_THRESHOLD * 1e3:g} mm'
    )


def reference_motion(
    engine, primitive: TaskLike, rate_hz: float, seconds: float, seed: int = 0,
    width: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """
    (t, vertices): t in s from the start of the quintic part, through `seconds` of motion.

    `width`: the grasped corners' distance of a cloth of another size (core/cloth_size.py).
    """
    targets = full_targets(primitive, rate_hz, width)
    q0 = targets.quintic_index
    last = min(len(targets) - 1, q0 + int(np.ceil(seconds * rate_hz)))
    frames = [engine.reset(seed, targets.left[0], targets.right[0])]
    for k in range(1, last + 1):
        frames.append(engine.step(targets.left[k], targets.right[k]).copy())
    t = targets.t[: last + 1] - targets.quintic_start
    return t, np.asarray(frames)


def _interp(t_ref: np.ndarray, states: np.ndarray, t: float) -> np.ndarray:
    i = int(np.clip(np.searchsorted(t_ref, t), 1, len(t_ref) - 1))
    w = float(np.clip((t - t_ref[i - 1]) / (t_ref[i] - t_ref[i - 1]), 0.0, 1.0))
    return (1 - w) * states[i - 1] + w * states[i]


def _cost(
    offset_s: float,
    times: np.ndarray,
    clouds: list[RealCloud],
    t_ref: np.ndarray,
    states: np.ndarray,
    s: SearchSettings,
    fps: float,
) -> float:
    tau = times - offset_s
    inside = np.nonzero((tau >= -s.pre) & (tau <= s.window))[0]
    if len(inside) < s.min_coverage * (s.pre + s.window) * fps:
        return np.inf
    return float(
        np.mean([clouds[i].chamfer_hausdorff(_interp(t_ref, states, tau[i]))[0] for i in inside])
    )


def search_start(
    stamps_ns: list[int],
    clouds: list[np.ndarray],
    t_ref: np.ndarray,
    states: np.ndarray,
    settings: SearchSettings = SearchSettings(),
) -> StartTime:
    """Return the bag time at which the real frames best match the reference motion."""
    usable = [(st, c) for st, c in zip(stamps_ns, clouds) if len(c)]
    if len(usable) < 2:
        raise AlignmentError('automatic alignment needs at least two non-empty frames')
    base = usable[0][0]
    times = np.array([(st - base) / 1e9 for st, _ in usable])
    real = [RealCloud(c) for _, c in usable]
    fps = (len(times) - 1) / max(times[-1] - times[0], 1e-9)
    cost = lambda o: _cost(o, times, real, t_ref, states, settings, fps)  # noqa: E731
    coarse = np.arange(
        times[0] - settings.pre, times[-1] - settings.window / 2, settings.coarse_step
    )
    costs = [cost(o) for o in coarse]
    if not costs or not np.isfinite(np.min(costs)):
        raise AlignmentError(
            f'automatic alignment: the bag ({times[-1]:.2f} s of frames) is too short for '
            f'{settings.pre + settings.window:g} s of comparison'
        )
    best = float(coarse[int(np.argmin(costs))])
    fine_step = settings.coarse_step / settings.fine_steps
    fine = best + fine_step * np.arange(-settings.fine_steps, settings.fine_steps + 1)
    fine_costs = [cost(o) for o in fine]
    best = float(fine[int(np.argmin(fine_costs))])
    return StartTime(
        base + int(round(best * 1e9)), 'automatic (reference simulation)', fine_step / 2
    )
