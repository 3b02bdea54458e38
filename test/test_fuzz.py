"""
Fuzz: randomly corrupted bags and results files end cleanly in `bag info`, `run` and `report`.

A few hundred variants, seeded: bytes flipped, truncated, MCAP chunks swapped, blocks zeroed,
metadata.yaml damaged (bags); keys dropped, values of the wrong type, rows that are not objects,
names that point outside the report directory, torn lines (results.jsonl). Each must end within
its time limit with exit status 0 or 2 and no traceback (an uncaught exception is status 1 in
`cli.main`), and `report` must write nothing outside the directory it was given. The bulk runs
`cli.main` in-process; a sample of the same variants runs in a real `cloth-bench` subprocess.
Cases that fail in code another issue is rewriting are marked xfail with that issue's number.
"""

from __future__ import annotations

import json
from pathlib import Path
import signal
import subprocess
import sys
import warnings

from cloth_bench_ros import cli
from cloth_bench_ros.data import BagReader, BagWriter
from cloth_bench_ros.sweep import study as sw
from mcap.reader import SeekingReader
import numpy as np
import pytest

SEED = 20261122
COUNTS = {'bag-info': 240, 'run': 30, 'report': 14}  # report renders PNGs: ~1 s a case
SUBPROCESS_SAMPLE = {('bag-info', 0), ('bag-info', 3), ('run', 1), ('report', 2)}
TIME_LIMIT_S = {'bag-info': 20, 'run': 60, 'report': 60}
REPO = Path(__file__).resolve().parents[1]
BUNDLED = REPO / 'bags' / 'towel_dynamic'
FRAMES = 24  # of the bundled bag, rewritten in 32 KiB chunks so that there are chunks to swap

# Cases known to fail, with the issue that owns the code (none left since issues 9 and 13 landed).
KNOWN: dict[tuple[str, int], str] = {}


class Hung(BaseException):
    """Raised by the alarm when a case runs past its time limit (not an Exception)."""


def _alarm(signum, frame):
    raise Hung()


@pytest.fixture(scope='module')
def base_bag(tmp_path_factory) -> tuple[Path, list[tuple[int, int]]]:
    """Return the bundled towel bag's trial, first FRAMES clouds and chunks' (offset, length)."""
    bag = tmp_path_factory.mktemp('fuzz_base') / 'towel_dynamic'
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')
        reader = BagReader(BUNDLED)
        with BagWriter(bag, reader.trial, chunk_size=32 * 1024) as writer:
            for k, (stamp, points) in enumerate(reader.clouds()):
                if k == FRAMES:
                    break
                writer.write_cloud('/cloth_bench/real/cloud', stamp, points)
    mcap = next(bag.glob('*.mcap'))
    with mcap.open('rb') as f:
        chunks = [
            (c.chunk_start_offset, c.chunk_length)
            for c in SeekingReader(f).get_summary().chunk_indexes
        ]
    assert len(chunks) >= 4
    return bag, chunks


@pytest.fixture(scope='module')
def base_results(base_bag, tmp_path_factory) -> Path:
    """Write results.jsonl of two real cells (MuJoCo, 10 Hz, 4x4), one with frames kept."""
    bag, _ = base_bag
    out = tmp_path_factory.mktemp('fuzz_results')
    cells = sw.paper_cells(
        ['mujoco'],
        [10.0],
        ['towel'],
        ['dynamic'],
        [0, 1],
        bag.parent,
        grid=(4, 4),
        keep_frames_seeds=[0],
    )
    for cell in cells:
        row = sw.run_cell(cell, str(out))
        assert row['status'] == 'ok', row
        sw.append_row(out / sw.RESULTS_FILE, row)
    return out / sw.RESULTS_FILE


# ------------------------------------------------------------------------------------ mutations


def corrupt_bag(
    base: Path, chunks: list[tuple[int, int]], rng: np.random.Generator, dest: Path
) -> str:
    """Copy the bag to dest with one random corruption; its description."""
    kind = rng.choice(
        [
            'flip',
            'flip',
            'truncate',
            'swap_chunks',
            'zero_block',
            'meta_flip',
            'meta_truncate',
            'cdr',
        ]
    )
    if kind == 'cdr':  # a valid bag (chunks, CRCs, summary) holding one corrupt message
        return corrupt_message(base, rng, dest)
    dest.mkdir(parents=True)
    mcap_name = next(base.glob('*.mcap')).name
    data = bytearray((base / mcap_name).read_bytes())
    meta = bytearray((base / 'metadata.yaml').read_bytes())
    if kind == 'flip':
        n = int(rng.integers(1, 17))
        for pos in rng.integers(0, len(data), n):
            data[pos] ^= int(rng.integers(1, 256))
        what = f'{n} bytes flipped'
    elif kind == 'truncate':
        cut = int(rng.integers(0, len(data)))
        del data[cut:]
        what = f'truncated at {cut}'
    elif kind == 'swap_chunks':
        i, j = sorted(rng.choice(len(chunks), 2, replace=False))
        (a, la), (b, lb) = chunks[i], chunks[j]
        data[a:b + lb] = data[b:b + lb] + data[a + la:b] + data[a:a + la]
        what = f'chunks {i} and {j} swapped'
    elif kind == 'zero_block':
        start, size = int(rng.integers(0, len(data))), int(rng.integers(1, 4096))
        data[start:start + size] = bytes(len(data[start:start + size]))
        what = f'{size} bytes zeroed at {start}'
    elif kind == 'meta_flip':
        n = int(rng.integers(1, 9))
        for pos in rng.integers(0, len(meta), n):
            meta[pos] ^= int(rng.integers(1, 128))
        what = f'{n} metadata.yaml bytes flipped'
    else:
        cut = int(rng.integers(0, len(meta)))
        del meta[cut:]
        what = f'metadata.yaml truncated at {cut}'
    (dest / mcap_name).write_bytes(bytes(data))
    (dest / 'metadata.yaml').write_bytes(bytes(meta))
    return what


def corrupt_message(base: Path, rng: np.random.Generator, dest: Path) -> str:
    """Return the bag rewritten by BagWriter with one message's CDR bytes flipped or cut short."""
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')
        reader = BagReader(base)
        records = list(reader.raw_messages())
        k = int(rng.integers(0, len(records)))
        topic, msgtype, stamp, cdr = records[k]
        cdr = bytearray(cdr)
        if rng.random() < 0.5:
            cut = int(rng.integers(0, len(cdr)))
            del cdr[cut:]
            what = f'message {k} ({topic}) cut to {cut} bytes'
        else:
            positions = rng.integers(
                0, min(len(cdr), 256), 4
            )  # header, fields, sizes: the parts that matter
            for pos in positions:
                cdr[pos] ^= int(rng.integers(1, 256))
            what = f'message {k} ({topic}) bytes {sorted(positions.tolist())} flipped'
        records[k] = (topic, msgtype, stamp, bytes(cdr))
        with BagWriter(
            dest, chunk_size=32 * 1024
        ) as writer:  # no trial argument: it would add a message
            for topic, msgtype, stamp, data in records:
                writer.write(topic, msgtype, stamp, data)
    return what


BAD_VALUES = [
    None,
    'x',
    -1,
    -1e308,
    1e308,
    float('nan'),
    [],
    {},
    True,
    '',
    '../../../fuzz_escape',
    'a' * 10_000,
]


ESCAPE_KEYS = ['cloth', 'engine', 'primitive', 'config', 'mode', 'frames_csv']


def corrupt_results(
    base: Path, rng: np.random.Generator, dest: Path, escape_key: str | None = None
) -> str:
    """Copy results.jsonl to dest with one random corruption; return its description."""
    dest.mkdir(parents=True)
    lines = base.read_text().splitlines()
    rows = [json.loads(line) for line in lines]
    kinds = [
        'drop_key',
        'bad_value',
        'bad_value',
        'not_object',
        'escape',
        'torn',
        'flip',
        'duplicate',
    ]
    kind = 'escape' if escape_key else rng.choice(kinds)
    i = int(rng.integers(0, len(rows)))
    if kind == 'drop_key':
        key = str(rng.choice(sorted(rows[i])))
        del rows[i][key]
        what = f'row {i} without {key}'
    elif kind == 'bad_value':
        key = str(rng.choice(sorted(rows[i])))
        value = BAD_VALUES[int(rng.integers(0, len(BAD_VALUES)))]
        rows[i][key] = value
        what = f'row {i} {key}={str(value)[:40]!r}'
    elif kind == 'escape':
        key = escape_key or str(rng.choice(ESCAPE_KEYS))
        rows[i][key] = (
            ('../../fuzz_escape', 'x/../../../fuzz_escape')[i % 2]
            if key != 'frames_csv'
            else '/etc/passwd'
        )
        what = f'row {i} {key} points outside'
    if kind in ('drop_key', 'bad_value', 'escape'):
        lines = [json.dumps(r) for r in rows]
    elif kind == 'not_object':
        lines[i] = json.dumps([None, 1, 's', [], True][int(rng.integers(0, 5))])
        what = f'row {i} is {lines[i]}'
    elif kind == 'duplicate':
        lines.insert(i, lines[i])
        what = f'row {i} twice'
    text = '\n'.join(lines) + '\n'
    if kind == 'torn':
        cut = int(rng.integers(0, len(text)))
        text = text[:cut]
        what = f'torn at {cut}'
    data = bytearray(text.encode())
    if kind == 'flip':
        n = int(rng.integers(1, 9))
        for pos in rng.integers(0, len(data), n):
            data[pos] ^= int(rng.integers(1, 128))
        what = f'{n} bytes flipped'
    (dest / sw.RESULTS_FILE).write_bytes(bytes(data))
    return what


# --------------------------------------------------------------------------------------- cases


def _cases():
    for command, n in COUNTS.items():
        for index in range(n):
            reason = KNOWN.get((command, index))
            marks = [pytest.mark.xfail(strict=False, reason=reason)] if reason else []
            yield pytest.param(command, index, marks=marks, id=f'{command}-{index:03d}')


def _variant(
    command: str, index: int, base_bag, base_results, tmp_path: Path
) -> tuple[list[str], str]:
    rng = np.random.default_rng([SEED, list(COUNTS).index(command), index])
    if command == 'report':
        escape = ESCAPE_KEYS[index] if index < len(ESCAPE_KEYS) else None  # each key at least once
        what = corrupt_results(base_results, rng, tmp_path / 'res', escape)
        return [
            'report',
            str(tmp_path / 'res'),
            '--output',
            str(tmp_path / 'res' / 'report'),
        ], what
    bag, chunks = base_bag
    what = corrupt_bag(bag, chunks, rng, tmp_path / 'towel_dynamic')
    if command == 'bag-info':
        return ['bag', 'info', str(tmp_path / 'towel_dynamic')], what
    return [
        'run',
        '--bag',
        str(tmp_path / 'towel_dynamic'),
        '--grid',
        '4x4',
        '--rate',
        '10',
        '--output',
        str(tmp_path / 'out'),
    ], what


def _escaped(tmp_path: Path) -> list[Path]:
    """Files a report wrote outside its directory (names from a corrupted row point ../../..)."""
    report = tmp_path / 'res' / 'report'
    return [p for p in tmp_path.parent.rglob('*fuzz_escape*') if report not in p.parents]


@pytest.mark.slow
@pytest.mark.parametrize('command,index', list(_cases()))
def test_corrupted_input_ends_cleanly(command, index, base_bag, base_results, tmp_path, capsys):
    argv, what = _variant(command, index, base_bag, base_results, tmp_path)
    previous = signal.signal(signal.SIGALRM, _alarm)
    signal.setitimer(signal.ITIMER_REAL, TIME_LIMIT_S[command])
    try:
        with warnings.catch_warnings():
            warnings.simplefilter('ignore')
            code = cli.main(argv)
    except SystemExit as exc:
        code = exc.code
    except Hung:
        pytest.fail(f'{command} on a variant ({what}) ran past {TIME_LIMIT_S[command]} s')
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
    _, err = capsys.readouterr()
    assert code in (0, 2), f'{what}: status {code}: {err.strip()}'
    assert 'Traceback' not in err, f'{what}: {err}'
    if code == 2:
        assert err.strip().splitlines()[-1].startswith('cloth-bench'), f'{what}: {err}'
    assert not _escaped(tmp_path), f'{what}: wrote {_escaped(tmp_path)}'
    if (command, index) in SUBPROCESS_SAMPLE:  # the same variant through a real process
        result = subprocess.run(
            [sys.executable, '-m', 'cloth_bench_ros.cli', *argv],
            capture_output=True,
            text=True,
            timeout=TIME_LIMIT_S[command] + 30,
            cwd=tmp_path,
        )
        assert result.returncode == code, f'{what}: {result.stderr}'
        assert 'Traceback' not in result.stderr, f'{what}: {result.stderr}'
