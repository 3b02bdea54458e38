"""
Cost of `--live`: a lockstep run with the live view and one viewer against the same run without.

Runs, in one process and alternately, the node graph (trajectory publisher, simulator, recorder
replaying the bundled towel dynamic bag, evaluator) at 100 Hz (a) without the live view and (b)
with it and one viewer connected: a WebSocket client in a process of its own that subscribes to
every channel and reads every message (the Foxglove protocol, as test/test_live_view.py speaks
it). Both are timed from the run's first step after the start-up (step 1: every node, the
evaluator included, is ready; a live run's viewer is in) to the evaluator's summary: wall time,
and the CPU time of the executor's thread (every node's callbacks, the live view's encoding
included: the run's critical path in lockstep), which load on the machine disturbs least; the
process's whole CPU time (the server's threads included) is printed beside them. Goal: live /
plain at most 1.05. The metrics of both runs must be identical.

    python benchmarks/bench_live.py [--engine mujoco] [--rate 100] [--repeats 3]
        [--grid 11x15]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import resource
import socket
import statistics
import subprocess
import sys
import time

from cloth_bench_ros.core.evaluation import OnlineEvaluator
from cloth_bench_ros.paths import bundled_bag
from cloth_bench_ros.studies.run_pipeline import run_pipeline, RunConfig
from cloth_bench_ros.validation import parse_grid

GOAL = 1.05


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        return s.getsockname()[1]


async def watch(port: int) -> int:
    """One viewer: connect (retrying until the server is up), subscribe to all, read all."""
    import websockets

    deadline = time.monotonic() + 60
    while True:
        try:
            ws = await websockets.connect(
                f'ws://127.0.0.1:{port}',
                subprotocols=['foxglove.sdk.v1', 'foxglove.websocket.v1'],
                max_size=None,
            )
            break
        except OSError:
            if time.monotonic() > deadline:
                return 0
            await asyncio.sleep(0.05)
    messages = 0
    async with ws:
        try:
            async for msg in ws:
                if isinstance(msg, str):
                    op = json.loads(msg)
                    if op['op'] == 'advertise':
                        subs = [{'id': c['id'], 'channelId': c['id']} for c in op['channels']]
                        await ws.send(json.dumps({'op': 'subscribe', 'subscriptions': subs}))
                else:
                    messages += 1
        except websockets.exceptions.ConnectionClosed:
            pass
    return messages


def _cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)  # every thread of this process
    return usage.ru_utime + usage.ru_stime


SPAN: dict[str, tuple[float, float]] = {}  # (executor CPU, wall) at the run's start and end


def _instrument() -> None:
    """
    Note CPU and wall time at the run's first step after the start-up and at its summary.

    Step 0 answers the start-up handshake, sent before the graph is ready (and before a viewer
    is in); step 1 is stepped once every node, the evaluator included, is ready: the span from it
    to the summary is the run itself, the same in both kinds of run.
    """
    step, summary = OnlineEvaluator.add_step, OnlineEvaluator.summary

    def add_step(self, engine, stamp_ns, index, *args, **kwargs):
        if index > 0:
            SPAN.setdefault('start', (time.thread_time(), time.perf_counter()))
        return step(self, engine, stamp_ns, index, *args, **kwargs)

    def summary_at_end(self, *args, **kwargs):
        SPAN.setdefault('end', (time.thread_time(), time.perf_counter()))
        return summary(self, *args, **kwargs)

    OnlineEvaluator.add_step = add_step  # type: ignore[method-assign]  (a benchmark's probe)
    OnlineEvaluator.summary = summary_at_end  # type: ignore[method-assign]


def one_run(config: RunConfig, live: bool) -> tuple[float, float, float, dict, int]:
    """Return the run's wall and executor CPU time (see _instrument), the process's CPU time..."""
    viewer = None
    if live:  # the viewer in a process of its own: its work is not the run's
        port = _free_port()
        config.live = {'live': True, 'live_port': port, 'live_wait': 30.0}
        viewer = subprocess.Popen(
            [sys.executable, __file__, '--viewer', str(port)], stdout=subprocess.PIPE, text=True
        )
    else:
        config.live = {}
    cpu = _cpu_s()
    SPAN.clear()
    summary = run_pipeline(config)
    cpu = _cpu_s() - cpu
    assert summary is not None
    messages = int(viewer.communicate(timeout=60)[0] or 0) if viewer is not None else 0
    (cpu0, wall0), (cpu1, wall1) = SPAN['start'], SPAN['end']
    return wall1 - wall0, cpu1 - cpu0, cpu, summary, messages


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--engine', default='mujoco')
    parser.add_argument('--rate', type=float, default=100.0)
    parser.add_argument('--repeats', type=int, default=3)
    parser.add_argument('--grid', default=None, help="NXxNZ (default: the engine's, 11x15)")
    parser.add_argument('--viewer', type=int, metavar='PORT', help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.viewer:  # the viewer process of one run
        print(asyncio.run(watch(args.viewer)))
        return
    config = RunConfig(
        bag=bundled_bag('towel', 'dynamic'),
        engines=[args.engine],
        rate_hz=args.rate,
        grid=parse_grid(args.grid) if args.grid else None,
    )
    _instrument()
    runs: dict[bool, list] = {False: [], True: []}  # live? -> (wall, main CPU, process CPU)
    counts, metrics = [], set()
    one_run(config, False)  # warm-up: imports, engine compilation, caches
    for _ in range(args.repeats):
        for live in (False, True):
            wall, main_cpu, cpu, summary, messages = one_run(config, live)
            runs[live].append((wall, main_cpu, cpu))
            metrics.add(json.dumps(summary['engines'][args.engine]['CD_d']))
            if live:
                counts.append(messages)
    med = statistics.median

    def ratio(i: int) -> float:
        return med(r[i] for r in runs[True]) / med(r[i] for r in runs[False])

    for live in (False, True):
        wall, main_cpu, cpu = (med(r[i] for r in runs[live]) for i in range(3))
        print(
            f'{"with --live and one viewer" if live else "without --live":27s} wall {wall:.3f} s,'
            f' executor CPU {main_cpu:.3f} s, process CPU {cpu:.3f} s (medians of {args.repeats})'
        )
    print(f'the viewer read {min(counts)}-{max(counts)} messages per run')
    pairs = [live[1] / plain[1] for plain, live in zip(runs[False], runs[True])]
    print(
        f'ratio live / plain: executor CPU {ratio(1):.3f} (goal <= {GOAL}; median of the'
        f' back-to-back pairs {med(pairs):.3f}), wall {ratio(0):.3f}, process CPU {ratio(2):.3f};'
        f' CD_d identical: {len(metrics) == 1}'
    )


if __name__ == '__main__':
    main()
