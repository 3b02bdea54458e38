"""
Replay throughput: BagReader.clouds versus rosbags alone (AnyReader + deserialize).

Writes its own bag (default 132 frames x 50,000 points) to a temporary directory, reads it
with both in this process, and prints frames/s, MB/s of CDR payload and their ratio. Both
sides produce the same float64 points (read_xyz + drop_nan), so the comparison is like for like.

    .venv/bin/python benchmarks/bench_replay.py [--frames 132] [--points 50000] [--repeat 3]
"""

from __future__ import annotations

import argparse
from pathlib import Path
import tempfile
import time

from cloth_bench_ros.core import pointcloud2
from cloth_bench_ros.data import BagReader, BagWriter, CLOUD_TOPIC, TrialInfo
import numpy as np
from rosbags.highlevel import AnyReader


def make_bag(path: Path, frames: int, points: int) -> int:
    """Return a bag of random clouds at 30 Hz; returns the CDR payload bytes of its clouds."""
    rng = np.random.default_rng(0)
    trial = TrialInfo('towel', 0, 'dynamic', 99, 'bench_replay synthetic')
    base = rng.uniform([-0.1, -0.2, 0.3], [0.6, 0.2, 1.0], (points, 3))
    with BagWriter(path, trial) as w:
        for k in range(frames):
            w.write_cloud(
                CLOUD_TOPIC, round(k * 1e9 / 30), base + rng.normal(0, 0.002, base.shape)
            )
    return sum(len(cdr) for *_, cdr in BagReader(path).raw_messages(CLOUD_TOPIC))


def read_ours(path: Path) -> int:
    n = 0
    for _, pts in BagReader(path).clouds():
        n += len(pts)
    return n


def read_rosbags(path: Path) -> int:
    n = 0
    with AnyReader([path]) as reader:
        conns = [c for c in reader.connections if c.topic == CLOUD_TOPIC]
        for conn, _, raw in reader.messages(conns):
            pts, _ = pointcloud2.drop_nan(
                pointcloud2.read_xyz(reader.deserialize(raw, conn.msgtype))
            )
            n += len(pts)
    return n


def best_time(fn, path: Path, repeat: int) -> tuple[float, int]:
    times, n = [], 0
    for _ in range(repeat):
        t0 = time.perf_counter()
        n = fn(path)
        times.append(time.perf_counter() - t0)
    return min(times), n


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--frames', type=int, default=132)
    ap.add_argument('--points', type=int, default=50_000)
    ap.add_argument('--repeat', type=int, default=3)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / 'bench'
        t0 = time.perf_counter()
        payload = make_bag(path, args.frames, args.points)
        t_write = time.perf_counter() - t0
        size = sum(f.stat().st_size for f in path.glob('*.mcap'))
        print(
            f'bag: {args.frames} frames x {args.points} points, CDR {payload / 1e6:.1f} MB, '
            f'file {size / 1e6:.1f} MB (zstd), written in {t_write:.2f} s'
        )
        results = {}
        for name, fn in (('BagReader.clouds', read_ours), ('rosbags AnyReader', read_rosbags)):
            dt, n = best_time(fn, path, args.repeat)
            assert n == args.frames * args.points, (name, n)
            results[name] = dt
            print(
                f'{name:<18} {args.frames / dt:8.1f} frames/s {payload / 1e6 / dt:8.1f} MB/s '
                f'({dt:.3f} s, best of {args.repeat})'
            )
        ratio = results['rosbags AnyReader'] / results['BagReader.clouds']
        print(f'ratio (BagReader speed / rosbags speed): {ratio:.2f}')


if __name__ == '__main__':
    main()
