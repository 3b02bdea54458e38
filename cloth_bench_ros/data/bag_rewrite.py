"""
`cloth-bench bag rewrite`: copy a bag into the current writer's layout, messages unchanged.

Older bags of the project (metadata version 8, no `topic_type_hash` on the MCAP channels) are
read with BagReader and written again with BagWriter; the copy is then read back and compared.
"""

from __future__ import annotations

from dataclasses import replace
import os
from pathlib import Path
import shutil

from cloth_bench_ros.core.phase import first_table_contact
from cloth_bench_ros.data.bag_reader import BagReader
from cloth_bench_ros.data.bag_writer import BagWriter
from cloth_bench_ros.data.errors import BagError
from cloth_bench_ros.data.messages import DIAGNOSTIC_ARRAY, serialize
from cloth_bench_ros.data.trial import CUSTOM_DATA_PREFIX, trial_message, TRIAL_TOPIC, TrialInfo


def _custom_data(trial_strings: dict[str, str] | None) -> dict[str, str]:
    return {CUSTOM_DATA_PREFIX + k: v for k, v in (trial_strings or {}).items()}


def _check_same(src: BagReader, dst: BagReader, trial: TrialInfo | None) -> None:
    """Raise BagError unless dst holds src's messages (topic, type, time, bytes) and `trial`."""
    if dst.trial != trial or dst.custom_data != _custom_data(
        trial.to_strings() if trial else None
    ):
        raise BagError(f'bag {dst.path}: trial metadata differs from {src.path} after the rewrite')
    old, new = list(src.logged_messages()), list(dst.logged_messages())
    if len(old) != len(new):
        raise BagError(
            f'bag {dst.path}: {len(new)} messages after the rewrite, {src.path} has {len(old)}'
        )
    if trial != src.trial:  # the trial message was written anew
        old, new = old[1:], new[1:]
    for i, (a, b) in enumerate(zip(old, new)):
        if a[:3] != b[:3] or bytes(a[3]) != bytes(b[3]):
            raise BagError(
                f'bag {dst.path}: message {i} ({a[0]}) differs from {src.path} after the rewrite'
            )


def detected_change_of_phase(reader: BagReader) -> int | None:
    """Return the first table contact in a project bag's clouds (stamped from the motion)."""
    frames = list(reader.clouds())
    found = first_table_contact(points for _, points in frames)
    if found.index is None:
        return None
    fps = reader.trial.fps if reader.trial else 30.0
    return int(round(frames[found.index][0] * fps / 1e9))


def rewrite_bag(
    src: str | os.PathLike[str],
    dst: str | os.PathLike[str],
    change_of_phase_frame: int | str | None = None,
) -> dict[str, int]:
    """
    Write the bag src anew at dst with BagWriter (current layout); messages per topic.

    Payloads, topics, types, log times and trial metadata stay the same, which is checked by
    reading dst back; BagError (and no dst) if src cannot be carried over unchanged. A
    `change_of_phase_frame` (a frame, or "detected" for the first table contact in the clouds)
    replaces the trial's, the one change a rewrite may make.
    """
    src_path, dst_path = Path(src), Path(dst)
    if dst_path.exists() and src_path.exists() and dst_path.resolve() == src_path.resolve():
        raise BagError(f'bag {dst_path}: give a new directory, not the source bag itself')
    with BagReader(src_path) as reader:
        return _rewrite(reader, src_path, dst_path, change_of_phase_frame)


def _rewrite(
    reader: BagReader, src_path: Path, dst_path: Path, change_of_phase_frame: int | str | None
) -> dict[str, int]:
    if not reader.complete:
        raise BagError(f'bag {src_path} is truncated; rewriting would keep only part of it')
    trial = source_trial = reader.trial
    if reader.custom_data != _custom_data(trial.to_strings() if trial else None):
        raise BagError(
            f'bag {src_path}: custom_data holds more than the trial; the writer would drop it'
        )
    if change_of_phase_frame is not None:
        if trial is None or trial.primitive != 'dynamic':
            raise BagError(
                f'bag {src_path}: only a dynamic trial of the project has a change of phase'
            )
        frame = (
            detected_change_of_phase(reader)
            if change_of_phase_frame == 'detected'
            else change_of_phase_frame
        )
        if frame is None:
            raise BagError(f'bag {src_path}: no table contact found in its clouds')
        trial = replace(trial, change_of_phase_frame=int(frame))
    created = not dst_path.exists()
    writer = BagWriter(dst_path, trial)
    try:
        # BagWriter writes the trial message itself, first; the source's must be that very message.
        expected_first = (
            None
            if trial is None or source_trial is None
            else (TRIAL_TOPIC, DIAGNOSTIC_ARRAY, 0, serialize(trial_message(source_trial)))
        )
        for topic, msgtype, log_ns, cdr in reader.logged_messages():
            if expected_first is not None:
                if (topic, msgtype, log_ns, bytes(cdr)) != expected_first:
                    raise BagError(
                        f'bag {src_path} does not open with the trial message the writer writes; '
                        'rewriting would change its messages'
                    )
                expected_first = None
                continue
            writer.write(topic, msgtype, log_ns, cdr, log_time_ns=log_ns)
        if expected_first is not None:
            raise BagError(
                f'bag {src_path} has trial metadata but no trial message; rewriting would add one'
            )
        counts = writer.close()
        with BagReader(dst_path) as written:
            _check_same(reader, written, trial)
    except BaseException:
        writer.close()
        if created:
            shutil.rmtree(dst_path, ignore_errors=True)
        else:
            for made in (writer.mcap_path, dst_path / 'metadata.yaml'):
                made.unlink(missing_ok=True)
        raise
    return counts
