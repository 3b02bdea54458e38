"""`cloth-bench bag info`: a human-readable summary of a bag."""

from __future__ import annotations

import json
import os
import warnings

from cloth_bench_ros.data.bag_reader import BagReader
from cloth_bench_ros.data.errors import BagWarning
import numpy as np


def describe(path: str | os.PathLike[str], validate: bool = True) -> str:
    """
    Human-readable summary of a bag (for `cloth-bench bag info`); BagError if unreadable.

    With validate, every cloud is decoded and the frame counts are reported.
    """
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', BagWarning)
        reader = BagReader(path)
    with reader:
        return _summary(reader, validate)


def _summary(reader: BagReader, validate: bool) -> str:
    size = sum(f.stat().st_size for f in reader.files)
    start, end = reader.start_ns, reader.end_ns
    lines = [
        f'bag:          {reader.path}',
        f'files:        {", ".join(f.name for f in reader.files)} ({size / 1e6:.1f} MB)',
        f'storage:      {reader.storage}',
        f'metadata:     {reader.metadata_summary}',
        f'complete:     {"yes" if reader.complete else "no (truncated)"}',
    ]
    if start is not None and end is not None:
        lines.append(
            f'time:         {start / 1e9:.3f} s .. {end / 1e9:.3f} s ({(end - start) / 1e9:.3f} s)'
        )
    lines.append(f'messages:     {sum(reader.message_counts.values())}')
    lines.append('topics:')
    width = max((len(t) for t in reader.topics), default=0)
    for topic in sorted(reader.topics):
        lines.append(
            f'  {topic:<{width}}  {reader.topics[topic]}  ({reader.message_counts.get(topic, 0)}'
            ' msgs)'
        )
    trial = reader.trial
    if trial is None:
        lines.append('trial:        none')
    else:
        cop = 'none' if trial.change_of_phase_frame is None else str(trial.change_of_phase_frame)
        lines.append(
            f'trial:        {trial.cloth} trial {trial.trial} {trial.primitive}, change of phase'
            f' {cop}, {trial.fps:g} fps, units {trial.units}, frame {trial.frame_id}'
        )
        lines.append(f'source:       {trial.source}')
        if not np.allclose(trial.transform, np.eye(4)):
            lines.append(f'transform:    {json.dumps(trial.transform)}')
    for topic in reader.cloud_topics if validate else []:
        sizes = [len(p) for _, p in reader.clouds(topic)]
        s = reader.stats
        pts = f'{min(sizes)}..{max(sizes)} points per frame' if sizes else 'no points'
        lines.append(
            f'clouds:       {topic}: {s.frames} frames, {pts}, {s.nan_points_dropped} NaN points'
            f' dropped, {s.empty_clouds_skipped} empty clouds, {s.irregular_intervals} irregular'
            ' intervals'
        )
    for w in reader.warnings:
        lines.append(f'warning:      {w}')
    return '\n'.join(lines)
