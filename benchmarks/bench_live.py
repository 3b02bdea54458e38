"""
Cost of `--live`: a lockstep run with the live view and one viewer against the same run without.

Runs, in one process and alternately, the node graph (trajectory publisher, simulator, recorder
replaying the bundled towel dynamic bag, evaluator) at 100 Hz (a) without the live view and (b)
with it and one viewer connected: a WebSocket client in a process of its own that subscribes to
every channel and reads every message (the Foxglove protocol, as test/test_live_view.py speaks
it). The figure is the run's own wall time (first target to the evaluator's end, summary.json's
run.wall_time), so the wait for the viewer before the start is not counted; the medians' ratio
is printed (and that of the minima, steadier on a busy machine), and the ratio of the CPU time
the run's process spent (every thread: the server's included), which load on the machine
disturbs least. Goal: at most 1.05. The metrics of both runs must be identical.

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

from cloth_bench_ros.paths import bundled_bag
from cloth_bench_ros.studies.pipeline import run_pipeline, RunConfig
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


def one_run(config: RunConfig, live: bool) -> tuple[float, float, dict, int]:
    """Return the run's own wall time, this process's CPU time, the summary, messages viewed."""
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
    summary = run_pipeline(config)
    cpu = _cpu_s() - cpu
    assert summary is not None
    messages = int(viewer.communicate(timeout=60)[0] or 0) if viewer is not None else 0
    return float(summary['run']['wall_time']), cpu, summary, messages


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
    plain, live, counts, metrics = [], [], [], set()
    plain_cpu, live_cpu = [], []
    one_run(config, False)  # warm-up: imports, engine compilation, caches
    for _ in range(args.repeats):
        wall, cpu, summary, _ = one_run(config, False)
        plain.append(wall)
        plain_cpu.append(cpu)
        metrics.add(json.dumps(summary['engines'][args.engine]['CD_d']))
        wall, cpu, summary, messages = one_run(config, True)
        live.append(wall)
        live_cpu.append(cpu)
        counts.append(messages)
        metrics.add(json.dumps(summary['engines'][args.engine]['CD_d']))
    med = statistics.median
    ratio = med(live) / med(plain)
    best = min(live) / min(plain)  # the least disturbed run of each: steadier on a busy machine
    print(
        f'{args.engine} lockstep at {args.rate:g} Hz, {args.repeats} runs each: without --live'
        f' {med(plain):.3f} s, with --live and one viewer {med(live):.3f} s (median run wall'
        f' time; the viewer read {min(counts)}-{max(counts)} messages); CPU time of the process'
        f' (server threads included, viewer not) {med(plain_cpu):.3f} s against'
        f' {med(live_cpu):.3f} s'
    )
    print(
        f'ratio live / plain: {ratio:.3f} of medians, {best:.3f} of minima (goal <= {GOAL});'
        f' CPU time {med(live_cpu) / med(plain_cpu):.3f}; CD_d identical: {len(metrics) == 1}'
    )


if __name__ == '__main__':
    main()
