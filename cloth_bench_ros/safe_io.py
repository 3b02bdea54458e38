"""
File I/O for untrusted inputs and results that must not be lost: bounded reads, atomic writes.

Everything the project reads from a file it did not write (bag metadata, parameter files, results
rows, presets) goes through `read_text_bounded` / `load_yaml_bounded`; every results or report
file is written with `atomic_write_*`; names taken from files become path parts only through
`safe_name` and `confined_path`.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
import os
from pathlib import Path
import re
import shutil
import stat
import tempfile
from typing import Any

from cloth_bench_ros.errors import ClothBenchError, one_line, path_error
import yaml

MAX_TEXT_BYTES = 16 * 1024 * 1024
MAX_YAML_ALIASES = 100
_SAFE_NAME = re.compile(r'^[A-Za-z0-9][A-Za-z0-9_.+-]{0,127}$')


class UnsafeInputError(ClothBenchError, ValueError):
    """A file or name that cannot be used safely; str() is one line naming it and the problem."""


def read_text_bounded(path: str | Path, max_bytes: int = MAX_TEXT_BYTES) -> str:
    """Return the text of a regular file of at most `max_bytes` (no FIFO, device or directory)."""
    path = Path(path)
    try:
        st = os.stat(path)
    except OSError as exc:
        raise UnsafeInputError(f'{path}: cannot read ({exc.strerror or exc})') from None
    if not stat.S_ISREG(st.st_mode):
        raise UnsafeInputError(f'{path}: not a regular file')
    if st.st_size > max_bytes:
        raise UnsafeInputError(f'{path}: {st.st_size} bytes, more than the {max_bytes} allowed')
    try:
        with open(path, 'rb') as f:
            data = f.read(max_bytes + 1)
        return data.decode('utf-8')
    except (OSError, UnicodeDecodeError) as exc:
        raise UnsafeInputError(f'{path}: cannot read as UTF-8 text ({exc})') from None


class _BoundedLoader(yaml.SafeLoader):
    """SafeLoader that refuses documents with more than MAX_YAML_ALIASES aliases (alias bombs)."""

    aliases_seen = 0

    def compose_node(self, parent: Any, index: Any) -> Any:
        if self.check_event(yaml.AliasEvent):
            self.aliases_seen += 1
            if self.aliases_seen > MAX_YAML_ALIASES:
                raise yaml.YAMLError(f'more than {MAX_YAML_ALIASES} aliases')
        return super().compose_node(parent, index)


def load_yaml_bounded(text: str, source: str) -> Any:
    """yaml.safe_load with an alias limit; errors are one line naming `source`."""
    loader = None
    try:
        loader = _BoundedLoader(text)  # the reader refuses non-printable characters here already
        return loader.get_single_data()
    except yaml.YAMLError as exc:
        raise UnsafeInputError(f'{source}: not valid YAML ({one_line(exc)})') from None
    finally:
        if loader is not None:
            loader.dispose()


def load_yaml_file(path: str | Path, max_bytes: int = MAX_TEXT_BYTES) -> Any:
    """Return a YAML file read with `read_text_bounded` and `load_yaml_bounded`."""
    return load_yaml_bounded(read_text_bounded(path, max_bytes), str(path))


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    """
    Write beside `path`, flush, then rename over it: readers see the old or the new file.

    An OSError (a directory that cannot be written, a full disk) is a PathError naming `path`.
    """
    path = Path(path)
    try:
        mode = stat.S_IMODE(os.stat(path).st_mode)
    except OSError:
        mode = 0o644  # mkstemp's 0600 would hide results and bags from other users
    try:
        fd, tmp = tempfile.mkstemp(prefix=f'.{path.name}.', suffix='.tmp', dir=path.parent)
    except OSError as exc:
        raise path_error(path, 'write', exc) from None
    try:
        os.fchmod(fd, mode)
        with os.fdopen(fd, 'wb') as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        Path(tmp).unlink(missing_ok=True)
        if isinstance(exc, OSError):
            raise path_error(path, 'write', exc) from None
        raise


def atomic_write_text(path: str | Path, text: str) -> None:
    """`atomic_write_bytes` of UTF-8 text."""
    atomic_write_bytes(path, text.encode('utf-8'))


def check_output_dir(path: str | Path) -> Path:
    """Create `path` if needed and check that files can be written there, before any work."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise UnsafeInputError(f'{path}: exists and is not a directory')
    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path, prefix='.write-check-'):
            pass
    except OSError as exc:
        raise UnsafeInputError(f'{path}: cannot write there ({exc.strerror or exc})') from None
    return path


@contextmanager
def staged_directory(final: str | Path, overwrite: bool = False) -> Iterator[Path]:
    """
    Return a directory to fill beside `final`, renamed to `final` only when the block completes.

    On any error (or a signal) nothing is left at `final`, and an old `final` stays as it was:
    readers see the old directory or the complete new one. The checks (exists, writable) run
    before the block starts. The staged path ends in final's name (a bag names its file after it).
    """
    final = Path(final)
    if final.exists() and not final.is_dir():
        raise UnsafeInputError(f'{final}: exists and is not a directory')
    if final.is_dir() and any(final.iterdir()) and not overwrite:
        raise UnsafeInputError(f'{final}: already exists (not empty; overwrite to replace it)')
    check_output_dir(final.parent)
    stage = Path(tempfile.mkdtemp(prefix=f'.{final.name}.partial-', dir=final.parent))
    try:
        yield stage / final.name
        old = stage / '.replaced'
        if final.exists():
            final.rename(old)
        try:
            (stage / final.name).rename(final)
        except BaseException:
            if old.exists():
                old.rename(final)
            raise
    finally:
        shutil.rmtree(stage, ignore_errors=True)


def safe_name(text: Any, what: str = 'name') -> str:
    """Return `text` if it is usable as one file-name part, else raise a one-line error."""
    name = str(text)
    if not _SAFE_NAME.match(name) or name in ('.', '..'):
        raise UnsafeInputError(f'{what} {name!r} is not a safe file name part')
    return name


def confined_path(base: str | Path, *parts: str) -> Path:
    """base/parts..., refused if it would resolve outside `base`."""
    root = Path(base).resolve()
    target = root.joinpath(*parts).resolve()
    if target != root and root not in target.parents:
        raise UnsafeInputError(f'{Path(*parts)} points outside {base}')
    return target
