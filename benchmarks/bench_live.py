"""
Cost of `--live`: a lockstep run with the live view and one viewer against the same run without.

Runs, in one process and alternately, the node graph (trajectory publisher, simulator, recorder
replaying the bundled towel dynamic bag, evaluator) at 100 Hz (a) without the live view and (b)
with it and one viewer connected: a WebSocket client on a thread of its own that subscribes to
every channel and reads every message (the Foxglove protocol, as test/test_live_view.py speaks
it). The figure is the run's own wall time (first target to the evaluator's end, summary.json's
run.wall_time), so the wait for the viewer before the start is not counted; the medians' ratio is
printed (and that of the minima, steadier on a busy machine). Goal: at most 1.05. The metrics
of both runs must be identical.

    python benchmarks/bench_live.py [--engine mujoco] [--rate 100] [--repeats 3]
        [--grid 11x15]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import socket
import statistics
import threading
import time

from cloth_bench_ros.paths import bundled_bag
from cloth_bench_ros.studies.pipeline import run_pipeline, RunConfig
from cloth_bench_ros.validation import parse_grid

GOAL = 1.05


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        return s.getsockname()[1]


class Viewer(threading.Thread):
    """One viewer: connects (retrying until the server is up), subscribes to all, reads all."""

    def __init__(self, port: int) -> None:
        super().__init__(daemon=True)
        self.port, self.messages, self.bytes = port, 0, 0

    def run(self) -> None:
        asyncio.run(self._watch())

    async def _watch(self) -> None:
        import websockets

        deadline = time.monotonic() + 60
        while True:
            try:
                ws = await websockets.connect(
                    f'ws://127.0.0.1:{self.port}',
                    subprotocols=['foxglove.sdk.v1', 'foxglove.websocket.v1'],
                    max_size=None,
                )
                break
            except OSError:
                if time.monotonic() > deadline:
                    return
                await asyncio.sleep(0.05)
        async with ws:
            try:
                async for msg in ws:
                    if isinstance(msg, str):
                        op = json.loads(msg)
                        if op['op'] == 'advertise':
                            subs = [{'id': c['id'], 'channelId': c['id']} for c in op['channels']]
                            await ws.send(json.dumps({'op': 'subscribe', 'subscriptions': subs}))
                    else:
                        self.messages += 1
                        self.bytes += len(msg)
            except websockets.exceptions.ConnectionClosed:
                pass


def one_run(config: RunConfig, live: bool) -> tuple[float, dict, int]:
    """Return the run's own wall time, its summary and the messages its viewer read."""
    viewer = None
    if live:
        port = _free_port()
        config.live = {'live': True, 'live_port': port, 'live_wait': 30.0}
        viewer = Viewer(port)
        viewer.start()
    else:
        config.live = {}
    summary = run_pipeline(config)
    assert summary is not None
    if viewer is not None:
        viewer.join(timeout=30)
    return float(summary['run']['wall_time']), summary, viewer.messages if viewer else 0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--engine', default='mujoco')
    parser.add_argument('--rate', type=float, default=100.0)
    parser.add_argument('--repeats', type=int, default=3)
    parser.add_argument('--grid', default=None, help="NXxNZ (default: the engine's, 11x15)")
    args = parser.parse_args()
    config = RunConfig(
        bag=bundled_bag('towel', 'dynamic'),
        engines=[args.engine],
        rate_hz=args.rate,
        grid=parse_grid(args.grid) if args.grid else None,
    )
    plain, live, counts, metrics = [], [], [], set()
    one_run(config, False)  # warm-up: imports, engine compilation, caches
    for _ in range(args.repeats):
        wall, summary, _ = one_run(config, False)
        plain.append(wall)
        metrics.add(json.dumps(summary['engines'][args.engine]['CD_d']))
        wall, summary, messages = one_run(config, True)
        live.append(wall)
        counts.append(messages)
        metrics.add(json.dumps(summary['engines'][args.engine]['CD_d']))
    ratio = statistics.median(live) / statistics.median(plain)
    best = min(live) / min(plain)  # the least disturbed run of each: steadier on a busy machine
    print(
        f'{args.engine} lockstep at {args.rate:g} Hz, {args.repeats} runs each: without --live'
        f' {statistics.median(plain):.3f} s, with --live and one viewer'
        f' {statistics.median(live):.3f} s (median run wall time; the viewer read'
        f' {min(counts)}-{max(counts)} messages)'
    )
    print(
        f'ratio live / plain: {ratio:.3f} of medians, {best:.3f} of minima (goal <= {GOAL});'
        f' CD_d identical: {len(metrics) == 1}'
    )


if __name__ == '__main__':
    main()
