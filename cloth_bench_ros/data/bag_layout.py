"""
Where a bag's messages are: which storage files, read by which path, from what a user points at.

A user may give a bag directory (metadata.yaml and its files), its metadata.yaml, one storage file,
or a directory whose metadata.yaml is missing (a recording killed before writing it: its files are
read directly, in the order `ros2 bag reindex` gives them). Uncompressed MCAP goes to the
project's own MCAP path; sqlite3 and compressed bags to rosbags (data/bag_storage.py).
"""

from __future__ import annotations

from dataclasses import dataclass, field
import hashlib
from pathlib import Path
import stat

from cloth_bench_ros.data.errors import BagError
from cloth_bench_ros.data.metadata import BagMetadata, read_metadata

_UNCOMPRESSED = ('', 'none', 'NONE')


@dataclass
class BagLayout:
    """A located bag: its path, metadata (None without metadata.yaml) and who reads its files."""

    path: Path  # the bag directory, or the one storage file given
    metadata: BagMetadata | None = None
    mcap_files: list[Path] = field(default_factory=list)  # read by the project's MCAP path
    rosbags_storage: str = ''  # sqlite3 or mcap when rosbags reads `rosbags_sources`
    rosbags_sources: list[Path] = field(default_factory=list)  # the directory, or raw .db3 files
    warning: str = ''  # said once when the bag is opened


def regular_file(path: Path) -> Path:
    """path, if it is a regular file (a FIFO or device would block or never end)."""
    try:
        mode = path.stat().st_mode
    except OSError as exc:
        raise BagError(f'bag {path} cannot be read ({exc.strerror or exc})') from None
    if not stat.S_ISREG(mode):
        raise BagError(f'bag {path} is not a regular file')
    return path


def raw_storage_files(directory: Path, suffix: str) -> list[Path]:
    """
    Return the `suffix` (.mcap, .db3, .mcap.zstd) files of a directory, in recording order.

    rosbag2 names split files `<bag>_<n><suffix>`; they are ordered by n, as `ros2 bag reindex`
    orders them (by name, `bag_10` would come before `bag_2`).
    """

    def order(path: Path) -> tuple[str, int, str]:
        stem, _, index = path.name[: -len(suffix)].rpartition('_')
        return (stem, int(index), '') if stem and index.isdigit() else (path.name, -1, path.name)

    return sorted((p for p in directory.glob(f'*{suffix}') if p.is_file()), key=order)


def _in_compressed_bag(path: Path) -> bool:
    """Return True if path is a storage file of a compressed bag (read through its metadata)."""
    meta = path.parent / 'metadata.yaml'
    if not meta.is_file():
        return False
    try:
        info = read_metadata(meta)
    except BagError:
        return False
    named = path.name in {Path(n).name for n in info['relative_file_paths']}
    return named and info['compression_mode'] not in _UNCOMPRESSED


def _compressed_without_metadata(path: Path, compressed: list[Path]) -> str:
    """Why a file-compressed recording without metadata.yaml is not read, and what to do."""
    names = ', '.join(f.name for f in compressed[:3]) + (', ...' if len(compressed) > 3 else '')
    return (
        f'bag {path} has no metadata.yaml and compressed storage files ({names}), which are not'
        ' read without it: decompress them (zstd -d --rm FILE) and read the directory again'
    )


def _without_metadata(path: Path) -> BagLayout:
    compressed = raw_storage_files(path, '.mcap.zstd') + raw_storage_files(path, '.db3.zstd')
    if compressed:  # reading only the uncompressed last file would silently lose the rest
        raise BagError(_compressed_without_metadata(path, compressed))
    files = [regular_file(f) for f in raw_storage_files(path, '.mcap')]
    databases = [regular_file(f) for f in raw_storage_files(path, '.db3')]
    if not files and not databases:
        raise BagError(f'{path} is not a rosbag2 bag (no metadata.yaml and no .mcap or .db3 file)')
    warning = (
        f'bag {path} has no metadata.yaml (recording interrupted?); reading its '
        f'{".mcap" if files else ".db3"} files directly'
    )
    if files:
        return BagLayout(path, mcap_files=files, warning=warning)
    return BagLayout(path, rosbags_storage='sqlite3', rosbags_sources=databases, warning=warning)


def locate(path: Path) -> BagLayout:
    """Return the layout of the bag at `path`; BagError naming it if there is none."""
    if not path.exists():
        raise BagError(f'bag {path} does not exist')
    if path.is_file() and (
        path.name == 'metadata.yaml' or _in_compressed_bag(path)
    ):  # the bag it belongs to
        path = path.parent
    if not path.is_dir():
        if path.name.endswith('.zstd'):
            raise BagError(_compressed_without_metadata(path, [path]))
        if path.suffix == '.db3':
            return BagLayout(path, rosbags_storage='sqlite3', rosbags_sources=[regular_file(path)])
        return BagLayout(path, mcap_files=[regular_file(path)])
    meta_path = path / 'metadata.yaml'
    if not meta_path.exists():
        return _without_metadata(path)
    info = read_metadata(meta_path)
    if info['storage_identifier'] not in ('mcap', 'sqlite3'):
        raise BagError(
            f'bag {path} uses storage {info["storage_identifier"]!r} (readable: mcap, sqlite3)'
        )
    if info['storage_identifier'] != 'mcap' or info['compression_mode'] not in _UNCOMPRESSED:
        return BagLayout(
            path, info, rosbags_storage=info['storage_identifier'], rosbags_sources=[path]
        )
    # Names from the file never leave the bag directory.
    files = [path / Path(n).name for n in info['relative_file_paths']]
    missing = [str(f) for f in files if not f.exists()]
    if missing:
        raise BagError(f'bag {path} lists missing file(s): {", ".join(missing)}')
    if not files:
        raise BagError(f'bag {path} lists no storage file in metadata.yaml')
    return BagLayout(path, info, mcap_files=[regular_file(f) for f in files])


FINGERPRINT_SPAN = 64 * 1024  # bytes read at each end of each file


def fingerprint(path: Path) -> str:
    """
    Return a short identity of a bag's files: each one's name, size, first and last 64 KiB.

    Cheap on bags of any size; a bag rewritten or made again (another reference, another change
    of phase) has another one. Resumed studies compare it to know that a row is of this bag.
    """
    path = Path(path)
    files = sorted(p for p in path.iterdir() if p.is_file()) if path.is_dir() else [path]
    digest = hashlib.blake2b(digest_size=12)
    for file in files:
        size = file.stat().st_size
        digest.update(f'{file.name}\0{size}\0'.encode())
        with open(file, 'rb') as f:
            digest.update(f.read(FINGERPRINT_SPAN))
            if size > FINGERPRINT_SPAN:
                f.seek(max(FINGERPRINT_SPAN, size - FINGERPRINT_SPAN))
                digest.update(f.read(FINGERPRINT_SPAN))
    return digest.hexdigest()
