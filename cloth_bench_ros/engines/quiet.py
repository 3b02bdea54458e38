"""Silencing what an engine's C/C++ library prints straight to the process's stdout and stderr."""

from __future__ import annotations

import contextlib
import ctypes
import os
import sys
from typing import Iterator

_LIBC = ctypes.CDLL(None)


@contextlib.contextmanager
def quiet_c_output() -> Iterator[None]:
    """Send file descriptors 1 and 2 to /dev/null for the duration (C stdio buffers included)."""
    sys.stdout.flush()
    sys.stderr.flush()
    try:
        saved = [os.dup(1), os.dup(2)]
    except OSError:  # no standard file descriptors: nothing to silence
        yield
        return
    with open(os.devnull, 'w') as devnull:
        os.dup2(devnull.fileno(), 1)
        os.dup2(devnull.fileno(), 2)
        try:
            yield
        finally:
            _LIBC.fflush(None)  # drop what the library buffered while still silenced
            for fd, copy in zip((1, 2), saved):
                os.dup2(copy, fd)
                os.close(copy)
