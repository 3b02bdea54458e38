"""
Import the published dataset (PLY/PCD folders) into one rosbag2 MCAP bag per trial.

Layout (docs/benchmark.md, section 5):
`<root>/<cloth>_rag_<trial>/<primitive>/cloud/<NNNNN>.ply|.pcd`. Frame NNNNN is stamped
NNNNN / 30 s; points are kept exactly (NaN included; the reader drops and counts them),
optionally moved by a 4x4 transform, and stored as float32 x/y/z; `--clean` runs them through
core.cleaning first.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
import re
import warnings

from cloth_bench_ros import validation
from cloth_bench_ros.core.cleaning import clean, CleaningConfig
from cloth_bench_ros.core.phase import ContactSearch, first_contact, in_contact
from cloth_bench_ros.core.scene import REAL_FPS
from cloth_bench_ros.data import BagWriter, CLOUD_TOPIC, TrialInfo
from cloth_bench_ros.errors import ClothBenchError
from cloth_bench_ros.safe_io import check_output_dir, staged_directory
import numpy as np
from tqdm import tqdm

CLOTH_NAMES = {'chequered': 'chequered', 'cotton': 'towel', 'linen': 'linen'}  # folder -> ours
PRIMITIVES = ('dynamic', 'quasi_static')

# Change of phase (first contact) of the dynamic trials, real frame index (docs/benchmark.md,
# section 4).
CHANGE_OF_PHASE = {
    ('chequered', 0): 95, ('chequered', 1): 95, ('chequered', 2): 99,
    ('towel', 0): 99, ('towel', 1): 98, ('towel', 2): 99,
    ('linen', 0): 90, ('linen', 1): 89, ('linen', 2): 89,
}  # fmt: skip

MAX_POINTS = 100_000_000  # per cloud file: far above a 1280 x 720 depth image
_TRIAL_DIR = re.compile(r'^(chequered|cotton|linen)_rag_(\d+)$')
_FRAME_FILE = re.compile(r'^(\d{5})\.(ply|pcd)$')


class CloudFileError(ClothBenchError, ValueError):
    """A point-cloud file that cannot be read; str() is one line naming the file."""


# ------------------------------------------------------------------------------- cloud files

_PLY_TYPES = {
    'char': 'i1', 'int8': 'i1', 'uchar': 'u1', 'uint8': 'u1',
    'short': 'i2', 'int16': 'i2', 'ushort': 'u2', 'uint16': 'u2',
    'int': 'i4', 'int32': 'i4', 'uint': 'u4', 'uint32': 'u4',
    'float': 'f4', 'float32': 'f4', 'double': 'f8', 'float64': 'f8',
}  # fmt: skip


def _header_lines(path: Path, data: bytes, end_marker: bytes) -> tuple[list[str], int]:
    """Header lines up to and including the line starting with end_marker; offset after it."""
    lines, pos = [], 0
    while True:
        nl = data.find(b'\n', pos)
        if nl < 0:
            raise CloudFileError(f'{path}: header has no {end_marker.decode()!r} line')
        line = data[pos:nl].rstrip(b'\r').decode('ascii', errors='replace').strip()
        pos = nl + 1
        lines.append(line)
        if line.split(' ')[0].encode() == end_marker:
            return lines, pos
        if len(lines) > 1000:
            raise CloudFileError(f'{path}: header is too long or not a header')


def _xyz(path: Path, table: np.ndarray) -> np.ndarray:
    names = table.dtype.names or ()
    missing = [c for c in 'xyz' if c not in names]
    if missing:
        raise CloudFileError(
            f'{path}: no {"/".join(missing)} field (fields: {", ".join(names) or "none"})'
        )
    return np.stack([table[c].astype(np.float64) for c in 'xyz'], axis=1)


def read_ply(path: Path) -> np.ndarray:
    """x, y, z of the vertex element of a PLY file (binary LE/BE or ASCII) as float64 (n, 3)."""
    data = Path(path).read_bytes()
    if not data.startswith(b'ply'):
        raise CloudFileError(f"{path}: not a PLY file (no 'ply' magic)")
    lines, offset = _header_lines(path, data, b'end_header')
    fmt = None
    elements: list[tuple[str, int, list[tuple[str, str]]]] = []
    for line in lines[1:]:
        words = line.split()
        if not words or words[0] in ('comment', 'obj_info', 'end_header'):
            continue
        try:
            if words[0] == 'format':
                fmt = words[1]
            elif words[0] == 'element':
                count = validation.integer(
                    _int(words[2]), f'element {words[1]} count', 0, MAX_POINTS
                )
                elements.append((words[1], count, []))
            elif words[0] == 'property':
                if not elements:
                    raise ValueError('property before any element')
                if words[1] == 'list':
                    elements[-1][2].append((words[4], 'list'))
                else:
                    elements[-1][2].append((words[2], _PLY_TYPES[words[1]]))
            else:
                raise ValueError(f'unknown header line {line!r}')
        except (IndexError, KeyError, ValueError) as exc:
            raise CloudFileError(f'{path}: bad PLY header line {line!r} ({exc})') from None
    if len([e for e in elements if e[0] == 'vertex']) > 1:
        raise CloudFileError(f'{path}: more than one vertex element')
    order = {'binary_little_endian': '<', 'binary_big_endian': '>', 'ascii': ''}.get(fmt or '')
    if order is None:
        raise CloudFileError(f'{path}: unsupported PLY format {fmt!r}')
    skip = 0  # bytes (binary) or lines (ascii) of elements before the vertex element
    for name, count, props in elements:
        if name == 'vertex':
            if any(t == 'list' for _, t in props):
                raise CloudFileError(f'{path}: list property in the vertex element')
            if not order:
                rows = (
                    data[offset:]
                    .decode('ascii', errors='replace')
                    .splitlines()[skip:skip + count]
                )
                if len(rows) < count:
                    raise CloudFileError(f'{path}: truncated, {len(rows)} of {count} vertices')
                try:
                    values = np.array(
                        [[float(v) for v in r.split()] for r in rows], dtype=np.float64
                    )
                    table = np.zeros(count, [(p, 'f8') for p, _ in props])
                    for i, (p, _) in enumerate(props):
                        table[p] = values[:, i] if count else []
                except (ValueError, IndexError) as exc:
                    raise CloudFileError(f'{path}: bad ASCII vertex ({exc})') from None
                return _xyz(path, table)
            dtype = np.dtype([(p, order + t) for p, t in props])
            start = offset + skip
            if len(data) < start + count * dtype.itemsize:
                got = max(0, (len(data) - start) // dtype.itemsize)
                raise CloudFileError(f'{path}: truncated, {got} of {count} vertices')
            return _xyz(path, np.frombuffer(data, dtype=dtype, count=count, offset=start))
        if order:
            if any(t == 'list' for _, t in props):
                raise CloudFileError(
                    f'{path}: element {name!r} with list properties precedes the vertices'
                )
            skip += count * np.dtype([(p, order + t) for p, t in props]).itemsize
        else:
            skip += count
    raise CloudFileError(f'{path}: no vertex element')


_PCD_TYPES = {  # fmt: skip
    ('F', 4): 'f4', ('F', 8): 'f8',
    ('I', 1): 'i1', ('I', 2): 'i2', ('I', 4): 'i4', ('I', 8): 'i8',
    ('U', 1): 'u1', ('U', 2): 'u2', ('U', 4): 'u4', ('U', 8): 'u8',
}


def _int(word: str) -> int:
    """Return a header integer, strictly decimal ("5", not "5.0" nor "five")."""
    return validation.parse_integer(word, 'header value')


def _pcd_points(head: dict[str, list[str]]) -> int:
    """POINTS, or WIDTH x HEIGHT; each non-negative, and equal where both are given."""
    width = (
        validation.integer(_int(head['WIDTH'][0]), 'WIDTH', 0, MAX_POINTS)
        if 'WIDTH' in head
        else None
    )
    height = (
        validation.integer(_int(head['HEIGHT'][0]), 'HEIGHT', 0, MAX_POINTS)
        if 'HEIGHT' in head
        else None
    )
    if 'POINTS' in head:
        n = validation.integer(_int(head['POINTS'][0]), 'POINTS', 0, MAX_POINTS)
        if width is not None and height is not None and width * height != n:
            raise ValueError(f'POINTS {n} is not WIDTH x HEIGHT = {width} x {height}')
        return n
    if width is None or height is None:
        raise KeyError('POINTS (or WIDTH and HEIGHT)')
    return validation.integer(width * height, 'WIDTH x HEIGHT', 0, MAX_POINTS)


def read_pcd(path: Path) -> np.ndarray:
    """x, y, z of a PCD file (DATA ascii or binary) as float64 (n, 3), NaN points kept."""
    data = Path(path).read_bytes()
    lines, offset = _header_lines(path, data, b'DATA')
    head: dict[str, list[str]] = {}
    for line in lines:
        if line and not line.startswith('#'):
            key, *values = line.split()
            head[key.upper()] = values
    try:
        fields = head['FIELDS']
        sizes = [validation.integer(_int(s), 'SIZE', 1, 8) for s in head['SIZE']]
        types = head['TYPE']
        counts = [
            validation.integer(_int(c), 'COUNT', 1, 1024)
            for c in head.get('COUNT', ['1'] * len(fields))
        ]
        n = _pcd_points(head)
        mode = head['DATA'][0].lower()
        if not len(fields) == len(sizes) == len(types) == len(counts):
            raise ValueError('FIELDS, SIZE, TYPE and COUNT differ in length')
        if len(set(fields) - {'_'}) != len([f for f in fields if f != '_']):
            raise ValueError(f'a field name is given twice in FIELDS {" ".join(fields)}')
        dtype = np.dtype([
            (f if f != '_' else f'_pad{i}', _PCD_TYPES[(t.upper(), s)], (c,) if c > 1 else ())
            for i, (f, s, t, c) in enumerate(zip(fields, sizes, types, counts))
        ])  # fmt: skip
    except validation.InputError as exc:
        raise CloudFileError(f'{path}: bad PCD header ({exc})') from None
    except (KeyError, IndexError, ValueError) as exc:
        raise CloudFileError(f'{path}: bad PCD header ({type(exc).__name__}: {exc})') from None
    if mode == 'binary':
        if len(data) < offset + n * dtype.itemsize:
            got = max(0, (len(data) - offset) // dtype.itemsize)
            raise CloudFileError(f'{path}: truncated, {got} of {n} points')
        return _xyz(
            path, np.frombuffer(data, dtype=dtype.newbyteorder('<'), count=n, offset=offset)
        )
    if mode == 'ascii':
        text = data[offset:].decode('ascii', errors='replace').split('\n')
        rows = [r.split() for r in text if r.strip()]
        if len(rows) < n:
            raise CloudFileError(f'{path}: truncated, {len(rows)} of {n} points')
        width = sum(counts)
        try:
            table = np.array(
                [[float(v) for v in r[:width]] for r in rows[:n]], dtype=np.float64
            ).reshape(n, width)
        except ValueError as exc:
            raise CloudFileError(f'{path}: bad ASCII point ({exc})') from None
        column = dict(zip(fields, np.cumsum([0, *counts[:-1]])))
        missing = [c for c in 'xyz' if c not in column]
        if missing:
            raise CloudFileError(
                f'{path}: no {"/".join(missing)} field (fields: {", ".join(fields)})'
            )
        return table[:, [column[c] for c in 'xyz']]
    raise CloudFileError(f'{path}: unsupported PCD DATA {mode!r} (ascii and binary are supported)')


def read_cloud_file(path: Path) -> np.ndarray:
    """Points of a .ply or .pcd file as float64 (n, 3)."""
    path = Path(path)
    try:
        if path.suffix == '.ply':
            return read_ply(path)
        if path.suffix == '.pcd':
            return read_pcd(path)
    except OSError as exc:
        raise CloudFileError(f'{path}: cannot be read ({exc.strerror or exc})') from None
    raise CloudFileError(f'{path}: not a .ply or .pcd file')


# ------------------------------------------------------------------------------- dataset import


@dataclass(frozen=True)
class DatasetTrial:
    """One `<cloth>_rag_<trial>/<primitive>` folder of the dataset."""

    cloth: str  # ours: chequered, towel, linen
    trial: int
    primitive: str
    folder: Path  # .../<cloth>_rag_<trial>/<primitive>
    frames: tuple[tuple[int, Path], ...]  # (frame index, file), sorted

    @property
    def bag_name(self) -> str:
        return f'{self.cloth}_{self.trial}_{self.primitive}'


def find_trials(root: Path) -> list[DatasetTrial]:
    """Return the trial folders under root with their frame files; ValueError if none."""
    root = Path(root)
    if not root.is_dir():
        raise CloudFileError(f'dataset root {root} is not a directory')
    trials = []
    for trial_dir in sorted(p for p in root.iterdir() if p.is_dir()):
        m = _TRIAL_DIR.match(trial_dir.name)
        if not m:
            continue
        cloth, index = CLOTH_NAMES[m.group(1)], int(m.group(2))
        for primitive in PRIMITIVES:
            cloud_dir = trial_dir / primitive / 'cloud'
            if not cloud_dir.is_dir():
                continue
            frames: dict[int, Path] = {}
            for f in cloud_dir.iterdir():
                fm = _FRAME_FILE.match(f.name)
                if not fm:
                    continue
                k = int(fm.group(1))
                if k in frames:
                    raise CloudFileError(
                        f'{cloud_dir}: frame {k:05d} exists as both {frames[k].name} and {f.name}'
                    )
                frames[k] = f
            if not frames:
                raise CloudFileError(f'{cloud_dir}: no <NNNNN>.ply or .pcd frame files')
            trials.append(
                DatasetTrial(
                    cloth, index, primitive, trial_dir / primitive, tuple(sorted(frames.items()))
                )
            )
    by_name: dict[str, DatasetTrial] = {}
    for tr in trials:  # e.g. cotton_rag_1 and cotton_rag_01: one would silently replace the other
        if tr.bag_name in by_name:
            raise CloudFileError(
                f'{by_name[tr.bag_name].folder} and {tr.folder} both map to trial {tr.bag_name}'
            )
        by_name[tr.bag_name] = tr
    if not trials:
        raise CloudFileError(
            f'dataset root {root} has no <cloth>_rag_<trial>/<primitive>/cloud folders '
            f'(cloth in {", ".join(CLOTH_NAMES)}, primitive in {", ".join(PRIMITIVES)})'
        )
    return trials


def _check_transform(transform: np.ndarray | None) -> np.ndarray | None:
    if transform is None:
        return None
    t = np.asarray(transform, dtype=float)
    if t.shape != (4, 4) or not np.isfinite(t).all():
        raise CloudFileError(f'transform must be a finite 4x4 matrix, got shape {t.shape}')
    if not np.allclose(t[3], [0, 0, 0, 1]):
        raise CloudFileError(f"transform's last row must be 0 0 0 1, got {t[3].tolist()}")
    return t


def import_dataset(
    root: Path,
    out: Path,
    transform: np.ndarray | None = None,
    progress: bool = True,
    overwrite: bool = False,
    cleaning: CleaningConfig | None = None,
) -> list[Path]:
    """
    Write one bag per trial folder under root into out; returns the bag paths.

    With `cleaning`, each transformed cloud goes through the one cleaning pipeline
    (core.cleaning) before it is written; without, points are kept exactly.

    A bag is written under a temporary name and renamed when complete, so an error never
    leaves a half-imported bag behind.
    """
    root, out = Path(root), Path(out)
    t = _check_transform(transform)
    trials = find_trials(root)
    check_output_dir(out)
    for tr in trials:  # every existing bag is found before the first one is written
        if (out / tr.bag_name).exists() and not overwrite:
            raise CloudFileError(
                f'bag {out / tr.bag_name} already exists (pass overwrite to replace it)'
            )
    bags = []
    total = sum(len(tr.frames) for tr in trials)
    with tqdm(total=total, unit='frame', disable=not progress, desc='import') as bar:
        for tr in trials:
            final = out / tr.bag_name
            known = (
                CHANGE_OF_PHASE.get((tr.cloth, tr.trial)) if tr.primitive == 'dynamic' else None
            )
            if tr.primitive == 'dynamic' and known is None:  # found in the clouds, as a run would
                known = first_contact(
                    in_contact(_frame_points(f, t, cleaning)) for _, f in tr.frames
                ).index
            info = TrialInfo(
                cloth=tr.cloth,
                trial=tr.trial,
                primitive=tr.primitive,
                change_of_phase_frame=known,
                source=f'imported from {tr.folder.relative_to(root).as_posix()}',
                fps=REAL_FPS,
                transform=(t if t is not None else np.eye(4)).tolist(),
            )
            bar.set_description(tr.bag_name)
            contact = []
            with staged_directory(final, overwrite) as staged, BagWriter(staged, info) as writer:
                for k, f in tr.frames:
                    pts = _frame_points(f, t, cleaning)
                    contact.append(in_contact(pts))
                    writer.write_cloud(CLOUD_TOPIC, round(k * 1_000_000_000 / REAL_FPS), pts)
                    bar.update(1)
            _check_change_of_phase(
                final, info, first_contact(contact), cleaning is not None and cleaning.table_plane
            )
            bags.append(final)
    return bags


def _frame_points(path: Path, t: np.ndarray | None, cleaning: CleaningConfig | None) -> np.ndarray:
    """One frame's points, moved into the simulation frame and cleaned as the bag stores them."""
    pts = read_cloud_file(path)
    if t is not None:
        pts = pts @ t[:3, :3].T + t[:3, 3]
    return clean(pts, cleaning) if cleaning is not None else pts


def _check_change_of_phase(
    bag: Path, info: TrialInfo, found: ContactSearch, table_removed: bool
) -> None:
    """Warn when the recorded change of phase and the first table contact disagree."""
    if info.primitive != 'dynamic' or not table_removed:  # else the table is in every frame
        return
    if (
        found.index is None
        or info.change_of_phase_frame is None
        or abs(found.index - info.change_of_phase_frame) > 1
    ):
        seen = (
            f'first table contact at frame {found.index}'
            if found.index is not None
            else found.reason
        )
        warnings.warn(
            f'bag {bag}: change of phase at frame {info.change_of_phase_frame}, but the clouds '
            f'show {seen}',
            stacklevel=3,
        )
