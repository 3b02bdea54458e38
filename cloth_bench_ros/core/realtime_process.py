"""
Process settings for a real-time critical path: CPU pinning, SCHED_FIFO, garbage collection.

Each request reports what it got: Linux refuses SCHED_FIFO to a process without CAP_SYS_NICE
(or an RLIMIT_RTPRIO above 0), and a core outside the process's allowed set cannot be pinned.
A refusal is a result to print, never an exception. Linux schedules threads, not processes, and
a DDS participant receives in threads of its own (Cyclone's recvUC, dq.builtins, tev, ...):
pinning gives the step loop's thread its core and moves the others off it, the scheduler is set
for every thread the process has when asked (/proc/self/task), and threads started later inherit
both from the thread that starts them.
"""

from __future__ import annotations

from dataclasses import dataclass
import gc
import os
import threading


@dataclass(frozen=True)
class RealtimeOutcome:
    """What a process asked for and what the system granted, in one line each."""

    cpu: str
    scheduler: str
    gc: str
    frozen: bool  # the heap was frozen and automatic collection is off: call collect_young()
    previous_cpus: frozenset[int] | None = (
        None  # the affinity before pinning, restored by release()
    )
    previous_policy: int | None = None  # the scheduler before SCHED_FIFO, restored by release()

    def lines(self) -> list[str]:
        return [f'cpu: {self.cpu}', f'scheduler: {self.scheduler}', f'gc: {self.gc}']


def threads() -> list[int]:
    """Thread ids of this process (Linux: /proc/self/task), else [0] (the calling thread)."""
    try:
        return sorted(int(t) for t in os.listdir('/proc/self/task'))
    except (OSError, ValueError):
        return [0]


def pin_to_cpu(cpu: int) -> str:
    """
    Give the calling thread core `cpu`; move every other thread of the process off it.

    -1 leaves all; the outcome as a sentence.

    The calling thread is the step loop. The DDS threads (Cyclone's receive and event threads) go
    to the other allowed cores: on the loop's core they would preempt a step, and a loop that
    polls instead of sleeping (`busy_wait`) would starve them.
    """
    if cpu < 0:
        return f'not pinned (allowed cores {_allowed()})'
    if not hasattr(os, 'sched_setaffinity'):
        return (
            f'pinning to core {cpu} refused: os.sched_setaffinity is not available on this system'
        )
    try:
        others = set(os.sched_getaffinity(0)) - {cpu}
        os.sched_setaffinity(0, {cpu})  # Linux: 0 is the calling thread
        moved = 0
        for tid in threads():
            if tid != threading.get_native_id() and others:
                _ignore_gone(os.sched_setaffinity, tid, others)
                moved += 1
    except (OSError, ValueError) as exc:
        return f'pinning to core {cpu} refused ({exc}); allowed cores {_allowed()}'
    where = (
        f'cores {",".join(str(c) for c in sorted(others))}'
        if others
        else 'the same core (no other allowed)'
    )
    return f'step loop pinned to core {cpu}, {moved} other threads on {where}'


def keep_off_cpu(cpu: int) -> str:
    """
    Move every thread of this process off core `cpu` (-1: leave them).

    The simulator's pinned step loop then has its core to itself; the outcome as a sentence.
    """
    if cpu < 0 or not hasattr(os, 'sched_setaffinity'):
        return f'not pinned (allowed cores {_allowed()})'
    allowed = set().union(*(_affinity(tid) for tid in threads()))
    others = allowed - {cpu}
    if not others:
        return f'kept on core {cpu}: no other core allowed'
    for tid in threads():
        _ignore_gone(os.sched_setaffinity, tid, others)
    return f'kept off core {cpu} (on cores {",".join(str(c) for c in sorted(others))})'


def lower_priority(niceness: int = 19) -> str:
    """Run this process's threads at `niceness` (work off the critical path yields the CPU)."""
    if not hasattr(os, 'setpriority'):
        return 'priority unchanged: os.setpriority is not available on this system'
    for tid in threads():
        try:
            os.setpriority(os.PRIO_PROCESS, tid, niceness)  # Linux: per thread
        except (ProcessLookupError, PermissionError):
            pass
    return f'nice {niceness} (off the critical path)'


def _affinity(tid: int) -> set[int]:
    try:
        return set(os.sched_getaffinity(tid))
    except ProcessLookupError:
        return set()


def _ignore_gone(call, tid: int, *args) -> None:
    """call(tid, *args), unless the thread has ended meanwhile."""
    try:
        call(tid, *args)
    except ProcessLookupError:
        pass


def _allowed() -> str:
    try:
        return ','.join(str(c) for c in sorted(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return 'unknown'


def request_fifo(priority: int) -> str:
    """Ask for SCHED_FIFO at `priority` (0: the default scheduler); the outcome as a sentence."""
    if priority <= 0:
        return 'default scheduler (SCHED_OTHER), no real-time priority requested'
    if not hasattr(os, 'sched_setscheduler'):
        return (
            f'SCHED_FIFO {priority} refused: os.sched_setscheduler is not available on this system'
        )
    low, high = os.sched_get_priority_min(os.SCHED_FIFO), os.sched_get_priority_max(os.SCHED_FIFO)
    if not low <= priority <= high:
        return f'SCHED_FIFO {priority} refused: priority outside [{low}, {high}]'
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
        tids = threads()
        for tid in tids:
            _ignore_gone(os.sched_setscheduler, tid, os.SCHED_FIFO, os.sched_param(priority))
    except PermissionError:
        return (
            f'SCHED_FIFO {priority} refused: not permitted (needs CAP_SYS_NICE or an RLIMIT_RTPRIO'
            f' of at least {priority}, e.g. `ulimit -r {priority}` or /etc/security/limits.conf);'
            ' running on SCHED_OTHER'
        )
    except OSError as exc:
        return f'SCHED_FIFO {priority} refused ({exc}); running on SCHED_OTHER'
    return f'SCHED_FIFO priority {priority} ({len(tids)} threads)'


def poll_on_default_scheduler() -> str:
    """
    Put the calling thread back on SCHED_OTHER for a loop that polls instead of sleeping.

    A SCHED_FIFO thread that never sleeps uses up the kernel's real-time budget
    (sched_rt_runtime_us of every sched_rt_period_us, 950 ms of 1 s by default) and is then
    stopped for the rest of the period: a 50 ms stall every second. Pinned alone on its core
    (pin_to_cpu), a polling thread needs no real-time priority; the other threads keep theirs.
    """
    if not hasattr(os, 'sched_getscheduler') or os.sched_getscheduler(0) != os.SCHED_FIFO:
        return 'step loop polls on the default scheduler'
    os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))  # Linux: 0 is the calling thread
    budget = (
        _read_int('/proc/sys/kernel/sched_rt_runtime_us'),
        _read_int('/proc/sys/kernel/sched_rt_period_us'),
    )
    return (
        "step loop polls on SCHED_OTHER (SCHED_FIFO would be throttled by the kernel's real-time"
        f' budget, {budget[0]} of every {budget[1]} us), the other threads keep SCHED_FIFO'
    )


def _read_int(path: str) -> int | None:
    try:
        with open(path) as f:
            return int(f.read().strip())
    except (OSError, ValueError):
        return None


def freeze_heap() -> str:
    """
    After start-up: move every live object out of the collector's reach, stop automatic runs.

    From here on the step loop never pays for a collection it did not schedule; the caller runs
    `collect_young()` where a pause costs nothing (after a state has gone out).
    """
    gc.collect()
    gc.freeze()
    gc.disable()
    return (
        f'automatic collection off, {gc.get_freeze_count()} start-up objects frozen; collected'
        ' after each state'
    )


YOUNG_THRESHOLD, MIDDLE_THRESHOLD = 700, 10  # gc's own default thresholds of generations 0 and 1


def collect_young() -> None:
    """
    Run the young generations' collection when due by gc's default thresholds.

    It takes tens of microseconds.

    The oldest generation is left alone during a run: after `freeze_heap` it holds only what a
    run creates and keeps, and ordinary garbage is freed by reference counting anyway.
    """
    counts = gc.get_count()
    if counts[0] >= YOUNG_THRESHOLD:
        gc.collect(1 if counts[1] >= MIDDLE_THRESHOLD else 0)


def apply(cpu: int, fifo_priority: int, freeze_gc: bool) -> RealtimeOutcome:
    """Pin, request SCHED_FIFO and freeze the heap as asked; what the system granted."""
    cpus = frozenset(os.sched_getaffinity(0)) if hasattr(os, 'sched_getaffinity') else None
    policy = os.sched_getscheduler(0) if hasattr(os, 'sched_getscheduler') else None
    return RealtimeOutcome(
        pin_to_cpu(cpu),
        request_fifo(fifo_priority),
        freeze_heap() if freeze_gc else 'automatic collection (not frozen)',
        freeze_gc,
        cpus,
        policy,
    )


def release(outcome: RealtimeOutcome) -> None:
    """Undo `apply` (a simulator composed into a longer-lived process, e.g. `hil --in-process`)."""
    if outcome.frozen:
        gc.unfreeze()
        gc.enable()
    for tid in threads():
        if outcome.previous_cpus is not None and outcome.cpu.startswith('step loop pinned'):
            _ignore_gone(os.sched_setaffinity, tid, outcome.previous_cpus)
        if outcome.previous_policy is not None and outcome.scheduler.startswith('SCHED_FIFO'):
            _ignore_gone(os.sched_setscheduler, tid, outcome.previous_policy, os.sched_param(0))
