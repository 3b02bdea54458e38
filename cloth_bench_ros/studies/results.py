"""
The results file of a study: typed rows, one key per cell, untrusted reading, one locked writer.

<dir>/results.jsonl holds one JSON object per finished cell. Rows are read as untrusted input:
a line torn by an interrupted study is skipped (its cell runs again), but a line that is JSON and
not an object, lacks a key, has a name that is not a safe file-name part or a frames_csv path
outside the directory is a `ResultsError` (one line naming the file and line; exit 2 from the
CLI). Only one study writes a directory at a time: `ResultsLock` holds an exclusive lock on
<dir>/.results.lock for the whole study, and a second study on the same directory refuses to
start (the kernel drops the lock when its holder dies, even by SIGKILL: no stale lock).
"""

from __future__ import annotations

from dataclasses import replace
import fcntl
import json
import math
import os
from pathlib import Path
import socket
from typing import Any, Mapping, Sequence, TypedDict

from cloth_bench_ros.engines.settle import FULL
from cloth_bench_ros.errors import ClothBenchError
from cloth_bench_ros.options import OPTIONS
from cloth_bench_ros.safe_io import (
    atomic_write_text,
    confined_path,
    read_text_bounded,
    safe_name,
    UnsafeInputError,
)

RESULTS_FILE = 'results.jsonl'
LOCK_FILE = '.results.lock'
MAX_RESULTS_BYTES = 512 * 1024 * 1024

# What makes a cell unique, with the default of each field that older rows may lack.
KEY_FIELDS: dict[str, Any] = {
    'mode': 'paper',
    'config': 'preset',
    'engine': None,
    'rate_hz': None,
    'cloth': None,
    'primitive': None,
    'trial': 0,
    'seed': None,
    'pacing': OPTIONS['pacing'].default,
    'device': 'cpu',  # the engine's compute device (rows written before it existed ran on the CPU)
    # How the cell was computed (SCORED_WITH); rows older than a field never match a cell again.
    'engine_version': '',
    'all_metrics': True,  # every metric (metric_choice), or the paper's CD/HD only
    'surface_revision': 0,  # core/surface_metrics.SURFACE_REVISION of an all-metrics row, else 0
    'settle': FULL,  # the settle phase (rows written before it existed settled in full)
    # --task and --cloth-mesh: the file (which cell) and its content's SHA-256 (how it ran)
    **dict.fromkeys(('task_file', 'task_sha256', 'cloth_mesh', 'mesh_sha256'), ''),
}
# The key fields that say how a cell was computed, not which cell: a row that differs from a cell
# in these only is superseded when the cell runs again (`superseded_rows`).
SCORED_WITH = (
    'engine_version', 'all_metrics', 'surface_revision', 'settle', 'task_sha256', 'mesh_sha256'
)
NAME_FIELDS = ('mode', 'engine', 'cloth', 'primitive', 'pacing')
NUMERIC_FIELDS = (
    'CD',
    'HD',
    # the metrics beside the paper's (metric_choice.py keys)
    'CD_reverse',
    'HD_reverse',
    'CD_surface',
    'HD_surface',
    'CD_two_sided',
    'HD_two_sided',
    'precision',
    'recall',
    'F',
    'EMD',
    'contact_onset_error_s',
    'L_s',
    'step_time_mean',
    'step_time_p50',
    'step_time_p99',
    'step_time_max',
    'latency_mean',
    'latency_p50',
    'latency_p99',
    'latency_max',
    'real_time_factor',
    'cell_wall_s',
)


class ResultsError(ClothBenchError, ValueError):
    """A results file or directory that cannot be used; str() is one line naming it."""


class ResultRow(TypedDict, total=False):
    """One line of results.jsonl: the cell, then what its run measured (NaN for no value)."""

    mode: str
    config: str
    engine: str
    rate_hz: float
    cloth: str
    primitive: str
    trial: int
    seed: int
    pacing: str
    device: str  # the device the engine ran on (cpu, cuda:0, ...)
    all_metrics: bool  # scored on every metric, or on the paper's CD/HD only
    surface_revision: int  # the surface metrics' revision (all_metrics), else 0
    bag: str
    bag_fingerprint: str | None  # data.bag_layout.fingerprint: resumes only on the same bag
    grid: str | None
    params: dict
    status: str  # ok | diverged | error
    error: str
    CD: float
    HD: float
    L_s: float
    diverged: bool
    diverged_at_step: int | None
    diverged_reason: str
    frames_csv: str | None
    cell_wall_s: float
    engine_version: str


def result_key(fields: Mapping[str, Any]) -> tuple:
    """Return the unique key of a cell from a Cell's or a row's fields (missing: the default)."""
    values = []
    for name, default in KEY_FIELDS.items():
        value = fields.get(name, default)
        if value is None:
            raise KeyError(name)
        values.append(
            float(value)
            if name == 'rate_hz'
            else int(value) if name in ('trial', 'seed', 'surface_revision')
            else bool(value) if name == 'all_metrics' else value
        )
    return tuple(values)


def superseded_rows(cells: Sequence[Any], existing: Sequence[dict]) -> list[dict]:
    """Return the rows of these cells computed otherwise (another engine version or metrics)."""
    def identity(key: tuple) -> tuple:
        return tuple(v for name, v in zip(KEY_FIELDS, key) if name not in SCORED_WITH)

    keys = {cell.key() for cell in cells}
    cells_of = {identity(key) for key in keys}
    return [r for r in existing if row_key(r) not in keys and identity(row_key(r)) in cells_of]


def drop_superseded(path: Path, cells: Sequence[Any], existing: Sequence[dict]) -> None:
    """Remove from a results file the rows of these cells computed otherwise (they run again)."""
    gone = {id(r) for r in superseded_rows(cells, existing)}
    if gone:
        rewrite_rows(path, [r for r in existing if id(r) not in gone])


def with_kept_scoring(cells: Sequence[Any], existing: Sequence[dict]) -> list[Any]:
    """Return the cells, each CD/HD-only one whose cell is kept scored on every metric as that."""
    keys = {row_key(r) for r in existing}
    out = []
    for cell in cells:
        every = replace(cell, all_metrics=True)
        out.append(every if not cell.all_metrics and every.key() in keys else cell)
    return out


def row_key(row: Mapping[str, Any]) -> tuple:
    """Return the key of a results row (the same as its Cell.key())."""
    return result_key(row)


def json_safe(value: Any) -> Any:
    """Value with every non-finite float as None (JSON has no NaN), recursively."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    return value


def check_row(row: Any, base: Path, where: str) -> dict[str, Any]:
    """Return the row if it is a usable results row, else ResultsError naming `where`."""
    if not isinstance(row, dict):
        raise ResultsError(
            f'{where}: a result row must be a JSON object, found {type(row).__name__}'
        )
    missing = [k for k, default in KEY_FIELDS.items() if default is None and k not in row]
    if missing:
        raise ResultsError(f'{where}: result row lacks {", ".join(missing)}')
    try:
        for name in NAME_FIELDS:
            if name in row:
                safe_name(row[name], name)
        if not isinstance(row.get('config', ''), str) or len(row.get('config', '')) > 500:
            raise ResultsError(f'{where}: config must be a string of at most 500 characters')
        rate = row['rate_hz']
        if (
            isinstance(rate, bool)
            or not isinstance(rate, (int, float))
            or not (math.isfinite(rate) and rate > 0)
        ):
            raise ResultsError(f'{where}: rate_hz {rate!r} is not a positive number')
        text_fields = ('engine_version', 'task_file', 'task_sha256', 'cloth_mesh', 'mesh_sha256')
        for name, kind in (*((n, str) for n in text_fields), ('all_metrics', bool)):
            if name in row and not isinstance(row[name], kind):
                raise ResultsError(f'{where}: {name} {row[name]!r} is not a {kind.__name__}')
        for name in ('seed', 'trial', 'surface_revision'):
            if name in row and (
                isinstance(row[name], bool) or not isinstance(row[name], int) or row[name] < 0
            ):
                raise ResultsError(f'{where}: {name} {row[name]!r} is not a whole number >= 0')
        frames = row.get('frames_csv')
        if frames is not None:
            if not isinstance(frames, str):
                raise ResultsError(f'{where}: frames_csv must be a path or null')
            confined_path(base, frames)
    except UnsafeInputError as exc:
        raise ResultsError(f'{where}: {exc}') from None
    for name in NUMERIC_FIELDS:
        value = row.get(name)
        if value is None and name in row:
            row[name] = math.nan
        elif name in row and (isinstance(value, bool) or not isinstance(value, (int, float))):
            raise ResultsError(f'{where}: {name} {value!r} is not a number')
    return row  # type: ignore[return-value]


def results_path(path: Path) -> Path:
    """<path>/results.jsonl for a directory, else the path itself."""
    path = Path(path)
    return path / RESULTS_FILE if path.is_dir() else path


def load_rows(path: Path) -> list[dict[str, Any]]:
    """Return the rows of a results.jsonl; a torn line is skipped, a bad row refused."""
    path = results_path(path)
    if not path.exists():
        return []
    try:
        text = read_text_bounded(path, MAX_RESULTS_BYTES)
    except UnsafeInputError as exc:
        raise ResultsError(str(exc)) from None
    rows = []
    for number, line in enumerate(text.splitlines(), 1):
        line = line.strip()
        if not line:
            continue
        try:
            row = json.loads(line)
        except json.JSONDecodeError:
            continue  # a line cut short by an interrupted study: that cell runs again
        rows.append(check_row(row, path.parent, f'{path}:{number}'))
    return rows


def row_line(row: Mapping[str, Any]) -> str:
    """Return a row as its line of results.jsonl."""
    return json.dumps(json_safe(dict(row)), sort_keys=True) + '\n'


def rewrite_rows(path: Path, rows: Sequence[Mapping[str, Any]]) -> None:
    """Replace a results file by these rows, atomically (the rest were made with other inputs)."""
    atomic_write_text(Path(path), ''.join(row_line(r) for r in rows))


def append_row(path: Path, row: Mapping[str, Any]) -> None:
    """Append one JSON line, flushed; after a torn line, on a line of its own."""
    path = Path(path)
    data = row_line(row).encode()
    with path.open('ab') as f:
        if f.tell() > 0:
            with path.open('rb') as r:
                r.seek(-1, os.SEEK_END)
                if r.read(1) != b'\n':
                    data = b'\n' + data
        f.write(data)
        f.flush()
        os.fsync(f.fileno())


class ResultsLock:
    """
    Exclusive lock of a results directory for one study: `with ResultsLock(dir, "sweep"):`.

    A second study on a locked directory gets ResultsError naming who holds it. The lock is an
    flock(2) on <dir>/.results.lock: the kernel releases it when the holder exits or is killed.
    """

    def __init__(self, directory: Path, what: str) -> None:
        self.directory = Path(directory)
        self.what = what
        self._fd: int | None = None

    def __enter__(self) -> 'ResultsLock':
        path = self.directory / LOCK_FILE
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 200, 0).decode(errors='replace').strip() or 'another study'
            os.close(fd)
            raise ResultsError(
                f'results directory {self.directory} is in use by {holder}; wait for it to '
                'finish or choose another --output'
            ) from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f'{self.what} (pid {os.getpid()} on {socket.gethostname()})\n'.encode(), 0)
        self._fd = fd
        return self

    def __exit__(self, *exc: object) -> None:
        if self._fd is not None:
            os.ftruncate(self._fd, 0)
            os.close(self._fd)  # closing the descriptor releases the lock
            self._fd = None


def stale_cells(cells: Sequence[Any], existing: Sequence[dict]) -> dict[tuple, str]:
    """
    Return the key of each row of these cells that other inputs made, with a phrase saying why.

    A row resumes a cell only if it ran the same parameters on the same bag (its `params`, and its
    `bag_fingerprint` where the row has one).
    """
    by_key = {row_key(r): r for r in existing}
    fingerprints: dict[str, str | None] = {}
    stale = {}
    for cell in cells:
        row = by_key.get(cell.key())
        if row is None:
            continue
        params = json.loads(json.dumps(json_safe(cell.params)))
        if cell.bag not in fingerprints:
            fingerprints[cell.bag] = bag_fingerprint(cell.bag)
        if 'params' in row and row['params'] != params:
            stale[cell.key()] = f'{cell.ident()} (other parameters)'
        elif any(row.get(k) != v for k, v in cloth_fields(cell, True).items()):
            stale[cell.key()] = f'{cell.ident()} (a cloth of another size or mass)'
        elif row.get('bag_fingerprint') not in (None, fingerprints[cell.bag]):
            stale[cell.key()] = f'{cell.ident()} (another bag at {cell.bag})'
    return stale


def cloth_fields(cell: Any, every: bool = False) -> dict[str, Any]:
    """Return a cell's cloth_size and cloth_mass as a row keeps them (set ones, or `every`)."""
    size, mass = getattr(cell, 'cloth_size', None), getattr(cell, 'cloth_mass', None)
    fields = {'cloth_size': list(size) if size else None, 'cloth_mass': mass}
    return {k: v for k, v in fields.items() if every or v is not None}


def bag_fingerprint(bag: str) -> str | None:
    """Return a bag's fingerprint, or None where it cannot be read (the run reports why)."""
    from cloth_bench_ros.data.bag_layout import fingerprint  # lazy: the bag readers, +0.1 s

    try:
        return fingerprint(Path(bag))
    except OSError:
        return None
