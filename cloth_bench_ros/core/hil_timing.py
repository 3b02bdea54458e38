"""
Hardware-in-the-loop timing as a controller sees it: per target, due, sent and state received.

The controller (the trajectory publisher) keeps one `TargetTimeline`: target k is due at
`anchor + (stamp_k - stamp_0)` on the monotonic clock, goes out at `sent[k]`, and its state comes
back at `received[k]`. Latency is received - due, so a controller that sends late or a simulator
that falls behind both count. A target whose state never comes back was skipped by the simulator
(keep-last: a late simulator steps to the newest target) or lost; the simulator's own count of
skipped targets tells the two apart (`check_bookkeeping`).
"""

from __future__ import annotations

from dataclasses import dataclass
import io
import math

from cloth_bench_ros.errors import InputError
import numpy as np

UNSET = -1  # a time not (yet) taken
TIMELINE_COLUMNS = ('k', 'stamp_ns', 'due_ns', 'sent_ns', 'received_ns')


class TargetTimeline:
    """Preallocated per-target times (int64 ns, monotonic clock); nothing allocated per target."""

    def __init__(self, stamps_ns: np.ndarray) -> None:
        self.stamps = np.asarray(stamps_ns, dtype=np.int64)
        n = len(self.stamps)
        self.due = np.full(n, UNSET, dtype=np.int64)
        self.sent = np.full(n, UNSET, dtype=np.int64)
        self.received = np.full(n, UNSET, dtype=np.int64)
        self.anchor: int | None = None

    def __len__(self) -> int:
        return len(self.stamps)

    def start(self, anchor_ns: int) -> None:
        """Target k is due at anchor + (stamp_k - stamp_0)."""
        self.anchor = int(anchor_ns)
        np.add(self.stamps - self.stamps[0], self.anchor, out=self.due)

    def due_through(self, now_ns: int, period_ns: int) -> int:
        """
        Return the index of the last target due by now, rounding to the nearest schedule point.

        A tick that fires a little before its due time still sends its target.
        """
        return int(np.searchsorted(self.due, now_ns + period_ns // 2, side='right')) - 1

    def index_of(self, stamp_ns: int) -> int:
        """K of a stamp, or -1 if no target has it."""
        k = int(np.searchsorted(self.stamps, stamp_ns))
        return k if k < len(self.stamps) and self.stamps[k] == stamp_ns else -1

    def mark_received(self, stamp_ns: int, now_ns: int) -> int:
        """Note the first state with this stamp; its k (-1 for an unknown stamp)."""
        k = self.index_of(stamp_ns)
        if k >= 0 and self.received[k] == UNSET:
            self.received[k] = now_ns
        return k

    def to_csv(self) -> str:
        """One row per target: k, stamp, due, sent, received (ns; -1 = not taken)."""
        table = np.stack(
            [np.arange(len(self)), self.stamps, self.due, self.sent, self.received], axis=1
        )
        out = io.StringIO()
        np.savetxt(
            out, table, fmt='%d', delimiter=',', header=','.join(TIMELINE_COLUMNS), comments=''
        )
        return out.getvalue()

    @classmethod
    def from_csv(cls, text: str) -> 'TargetTimeline':
        """Return a timeline written by `to_csv`; ValueError on another layout."""
        lines = text.splitlines()
        if not lines or lines[0].strip() != ','.join(TIMELINE_COLUMNS):
            raise InputError(f'timeline: header is not {",".join(TIMELINE_COLUMNS)}')
        table = np.loadtxt(io.StringIO(text), dtype=np.int64, delimiter=',', skiprows=1, ndmin=2)
        if table.shape[1] != len(TIMELINE_COLUMNS) or not np.array_equal(
            table[:, 0], np.arange(len(table))
        ):
            raise InputError('timeline: rows are not k = 0, 1, 2, ... with five columns')
        timeline = cls(table[:, 1])
        timeline.due[:], timeline.sent[:], timeline.received[:] = (
            table[:, 2],
            table[:, 3],
            table[:, 4],
        )
        timeline.anchor = int(table[0, 2]) if len(table) else None
        return timeline


@dataclass(frozen=True)
class HilFigures:
    """Return the item-4 figures of a real-time run (controller's timeline, simulator's counts)."""

    targets: int  # in the trajectory
    sent: int
    states: int  # targets whose state came back
    skipped: int  # the simulator's count: targets it never stepped (a newer one was waiting)
    lost: int  # sent, not skipped, and no state came back
    deadline_misses: int  # states later than one period after their target was due
    latency_p50: float  # s
    latency_p99: float
    latency_p999: float
    latency_max: float
    send_lag_p99: float  # s, sent - due: the controller's own punctuality
    real_time_factor: (
        float  # simulated time over wall time from the first due time to the last state
    )

    def as_dict(self) -> dict:
        return dict(self.__dict__)


def latencies(timeline: TargetTimeline) -> np.ndarray:
    """Received - due in seconds, for the targets whose state came back."""
    got = timeline.received != UNSET
    return (timeline.received[got] - timeline.due[got]) / 1e9


def hil_figures(timeline: TargetTimeline, skipped: int, period_s: float) -> HilFigures:
    """Latency percentiles, misses, skipped and lost targets, send lag and real-time factor."""
    lat = latencies(timeline)
    sent = timeline.sent != UNSET
    states = int(lat.size)
    nan = math.nan

    def pct(q: float) -> float:
        return float(np.percentile(lat, q)) if lat.size else nan

    lag = (timeline.sent[sent] - timeline.due[sent]) / 1e9
    got = np.flatnonzero(timeline.received != UNSET)
    rtf = nan
    if got.size and timeline.anchor is not None:
        wall = (timeline.received[got[-1]] - timeline.due[0]) / 1e9
        sim = (timeline.stamps[got[-1]] - timeline.stamps[0]) / 1e9
        rtf = float(sim / wall) if wall > 0 else nan
    return HilFigures(
        targets=len(timeline),
        sent=int(sent.sum()),
        states=states,
        skipped=int(skipped),
        lost=int(sent.sum()) - states - int(skipped),
        deadline_misses=int(np.sum(lat > period_s)),
        latency_p50=pct(50),
        latency_p99=pct(99),
        latency_p999=pct(99.9),
        latency_max=float(lat.max()) if lat.size else nan,
        send_lag_p99=float(np.percentile(lag, 99)) if lag.size else nan,
        real_time_factor=rtf,
    )


def check_bookkeeping(timeline: TargetTimeline, stepped: int, skipped: int) -> list[str]:
    """
    Return what does not add up between the controller's timeline and the simulator's counts.

    Empty when all does.

    Every target is sent, in order, no earlier than half a period before it is due; every sent
    target is either stepped or skipped by the simulator; a state never arrives before its
    target was sent; the controller got a state for every stepped target.
    """
    problems = []
    n = len(timeline)
    sent = timeline.sent != UNSET
    if not sent.all():
        problems.append(f'{n - int(sent.sum())} of {n} targets were never sent')
    if np.any(np.diff(timeline.sent[sent]) < 0):
        problems.append('targets were sent out of order')
    if stepped + skipped != int(sent.sum()):
        problems.append(f'sent {int(sent.sum())} != stepped {stepped} + skipped {skipped}')
    got = timeline.received != UNSET
    if np.any(got & ~sent):
        problems.append('a state came back for a target that was never sent')
    if np.any(timeline.received[got & sent] < timeline.sent[got & sent]):
        problems.append('a state came back before its target was sent')
    if int(got.sum()) != stepped:
        problems.append(f'states received {int(got.sum())} != targets stepped {stepped}')
    return problems
