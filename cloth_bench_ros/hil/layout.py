"""
The real-time layout of a hardware-in-the-loop run, chosen from what the machine allows.

Measured on 2 cores (docs/hil.md): MuJoCo at 1 kHz missed 13.5 %
of its deadlines with no layout, 1.9 % with the step loop polling on a core of its own and the
controller on SCHED_FIFO. That layout is the default wherever the machine allows it: a core for
the polling step loop needs at least two usable cores, SCHED_FIFO needs the permission to ask for
it. What cannot be had falls back, and the run says so in one line.
"""

from __future__ import annotations

from dataclasses import dataclass
import os

from cloth_bench_ros.errors import InputError

LAYOUTS = ('auto', 'none')
FIFO_PRIORITY = (
    50  # the controller's SCHED_FIFO priority (below the kernel's threaded IRQs at 50+)
)


@dataclass(frozen=True)
class Layout:
    """Where the three processes run: the simulator's pinned core, the FIFO priority, polling."""

    cpu: int  # core of the simulator's step loop (-1: not pinned)
    fifo: int  # SCHED_FIFO priority of the controller and simulator (0: default scheduler)
    busy_wait: bool  # the pinned step loop polls instead of sleeping
    why: str  # one line: what was chosen and why

    def line(self) -> str:
        """Return the line the run prints."""
        return f'layout: {self.why}'


def usable_cpus() -> list[int]:
    """Return the cores this process may run on."""
    return (
        sorted(os.sched_getaffinity(0))
        if hasattr(os, 'sched_getaffinity')
        else list(range(os.cpu_count() or 1))
    )


def fifo_permitted(priority: int = FIFO_PRIORITY) -> bool:
    """Return True if this process may put a thread on SCHED_FIFO at `priority` (tried, undone)."""
    if not hasattr(os, 'sched_setscheduler'):
        return False
    try:
        previous = os.sched_getscheduler(0), os.sched_getparam(0)
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
        os.sched_setscheduler(0, previous[0], previous[1])
    except OSError:
        return False
    return True


def choose_layout(cpus: list[int], fifo_ok: bool) -> Layout:
    """Return the measured best layout for `cpus` usable cores, FIFO permitted or not."""
    fifo = FIFO_PRIORITY if fifo_ok else 0
    scheduler = (
        f'controller on SCHED_FIFO {fifo}'
        if fifo_ok
        else (
            'controller on the default scheduler (SCHED_FIFO not permitted: needs CAP_SYS_NICE '
            f'or `ulimit -r {FIFO_PRIORITY}`)'
        )
    )
    if len(cpus) >= 2:
        core = cpus[-1]
        return Layout(
            core,
            fifo,
            True,
            f'step loop polling on core {core} of its own, controller and observer on '
            f'the other {len(cpus) - 1}, {scheduler}, observer at nice 19 '
            f'({len(cpus)} usable cores)',
        )
    return Layout(
        -1,
        fifo,
        False,
        'one usable core: the step loop sleeps between targets and shares it '
        f'(no core to poll on), {scheduler}',
    )


def resolve_layout(name: str, cpu: int | None, fifo: int | None, busy_wait: bool | None) -> Layout:
    """Return the layout of a run: `auto` (the machine's best) or `none`, flags on top."""
    if name not in LAYOUTS:
        raise InputError(f'--layout {name!r} is not one of {", ".join(LAYOUTS)}')
    if name == 'none':
        base = Layout(
            -1, 0, False, 'none (--layout none): no pinning, no real-time priority, no polling'
        )
    else:
        base = choose_layout(usable_cpus(), fifo_permitted())
    if cpu is None and fifo is None and busy_wait is None:
        return base
    given = Layout(
        base.cpu if cpu is None else cpu,
        base.fifo if fifo is None else fifo,
        base.busy_wait if busy_wait is None else busy_wait,
        '',
    )
    if given.busy_wait and given.cpu < 0:
        raise InputError('--busy-wait needs a core of its own for the step loop: give --cpu N too')
    parts = [
        f'step loop {"polling" if given.busy_wait else "sleeping"} '
        + (f'on core {given.cpu}' if given.cpu >= 0 else 'not pinned'),
        f'SCHED_FIFO {given.fifo}' if given.fifo else 'default scheduler',
    ]
    return Layout(
        given.cpu,
        given.fifo,
        given.busy_wait,
        ', '.join(parts) + f' (flags on top of --layout {name})',
    )
