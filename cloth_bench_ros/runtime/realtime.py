"""Process settings for a real-time critical path: CPU pinning, SCHED_FIFO, garbage collection.

Each request reports what it got: Linux refuses SCHED_FIFO to a process without CAP_SYS_NICE
(or an RLIMIT_RTPRIO above 0), and a core outside the process's allowed set cannot be pinned.
A refusal is a result to print, never an exception. Linux schedules threads, not processes, and
a DDS participant receives in threads of its own (Cyclone's recvUC, dq.builtins, tev, ...):
affinity and scheduler are set for every thread the process has when asked (/proc/self/task),
and threads started later inherit them from the thread that starts them.
"""

from __future__ import annotations

import gc
import os
from dataclasses import dataclass


@dataclass(frozen=True)
class RealtimeOutcome:
    """What a process asked for and what the system granted, in one line each."""

    cpu: str
    scheduler: str
    gc: str
    frozen: bool  # the heap was frozen and automatic collection is off: call collect_young()
    previous_cpus: frozenset[int] | None = None  # the affinity before pinning, restored by release()
    previous_policy: int | None = None  # the scheduler before SCHED_FIFO, restored by release()

    def lines(self) -> list[str]:
        return [f"cpu: {self.cpu}", f"scheduler: {self.scheduler}", f"gc: {self.gc}"]


def threads() -> list[int]:
    """Thread ids of this process (Linux: /proc/self/task), else [0] (the calling thread)."""
    try:
        return sorted(int(t) for t in os.listdir("/proc/self/task"))
    except (OSError, ValueError):
        return [0]


def pin_to_cpu(cpu: int) -> str:
    """Pin every thread of this process to one core (-1: leave it); the outcome as a sentence."""
    if cpu < 0:
        return f"not pinned (allowed cores {_allowed()})"
    if not hasattr(os, "sched_setaffinity"):
        return f"pinning to core {cpu} refused: os.sched_setaffinity is not available on this system"
    try:
        os.sched_setaffinity(0, {cpu})
        tids = threads()
        for tid in tids:
            _ignore_gone(os.sched_setaffinity, tid, {cpu})
    except (OSError, ValueError) as exc:
        return f"pinning to core {cpu} refused ({exc}); allowed cores {_allowed()}"
    return f"pinned to core {cpu} ({len(tids)} threads)"


def _ignore_gone(call, tid: int, *args) -> None:
    """call(tid, *args), unless the thread has ended meanwhile."""
    try:
        call(tid, *args)
    except ProcessLookupError:
        pass


def _allowed() -> str:
    try:
        return ",".join(str(c) for c in sorted(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return "unknown"


def request_fifo(priority: int) -> str:
    """Ask for SCHED_FIFO at `priority` (0: stay on the default scheduler); the outcome as a sentence."""
    if priority <= 0:
        return "default scheduler (SCHED_OTHER), no real-time priority requested"
    if not hasattr(os, "sched_setscheduler"):
        return f"SCHED_FIFO {priority} refused: os.sched_setscheduler is not available on this system"
    low, high = os.sched_get_priority_min(os.SCHED_FIFO), os.sched_get_priority_max(os.SCHED_FIFO)
    if not low <= priority <= high:
        return f"SCHED_FIFO {priority} refused: priority outside [{low}, {high}]"
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
        tids = threads()
        for tid in tids:
            _ignore_gone(os.sched_setscheduler, tid, os.SCHED_FIFO, os.sched_param(priority))
    except PermissionError:
        return (f"SCHED_FIFO {priority} refused: not permitted (needs CAP_SYS_NICE or an RLIMIT_RTPRIO "
                f"of at least {priority}, e.g. `ulimit -r {priority}` or /etc/security/limits.conf); "
                f"running on SCHED_OTHER")
    except OSError as exc:
        return f"SCHED_FIFO {priority} refused ({exc}); running on SCHED_OTHER"
    return f"SCHED_FIFO priority {priority} ({len(tids)} threads)"


def freeze_heap() -> str:
    """After start-up: move every live object out of the collector's reach, stop automatic runs.

    From here on the step loop never pays for a collection it did not schedule; the caller runs
    `collect_young()` where a pause costs nothing (after a state has gone out).
    """
    gc.collect()
    gc.freeze()
    gc.disable()
    return f"automatic collection off, {gc.get_freeze_count()} start-up objects frozen; collected after each state"


YOUNG_THRESHOLD, MIDDLE_THRESHOLD = 700, 10  # gc's own default thresholds of generations 0 and 1


def collect_young() -> None:
    """The young generations' collection when due by gc's default thresholds (tens of microseconds).

    The oldest generation is left alone during a run: after `freeze_heap` it holds only what a
    run creates and keeps, and ordinary garbage is freed by reference counting anyway.
    """
    counts = gc.get_count()
    if counts[0] >= YOUNG_THRESHOLD:
        gc.collect(1 if counts[1] >= MIDDLE_THRESHOLD else 0)


def apply(cpu: int, fifo_priority: int, freeze_gc: bool) -> RealtimeOutcome:
    """Pin, request SCHED_FIFO and freeze the heap as asked; what the system granted."""
    cpus = frozenset(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None
    policy = os.sched_getscheduler(0) if hasattr(os, "sched_getscheduler") else None
    return RealtimeOutcome(pin_to_cpu(cpu), request_fifo(fifo_priority),
                           freeze_heap() if freeze_gc else "automatic collection (not frozen)", freeze_gc,
                           cpus, policy)


def release(outcome: RealtimeOutcome) -> None:
    """Undo `apply` (a simulator composed into a longer-lived process, e.g. `hil --in-process`)."""
    if outcome.frozen:
        gc.unfreeze()
        gc.enable()
    for tid in threads():
        if outcome.previous_cpus is not None and outcome.cpu.startswith("pinned"):
            _ignore_gone(os.sched_setaffinity, tid, outcome.previous_cpus)
        if outcome.previous_policy is not None and outcome.scheduler.startswith("SCHED_FIFO"):
            _ignore_gone(os.sched_setscheduler, tid, outcome.previous_policy, os.sched_param(0))
