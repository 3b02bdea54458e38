"""
The root of the package's user-facing errors, and the one line that reports any error.

Every error that reports bad input or a failing environment to the user (a bag that cannot be
read, an unknown engine parameter, an unsafe file, a path that cannot be written) derives from
ClothBenchError; str() is one line naming the input and what is wrong. The CLI and the node mains
catch only these (and rclpy's own parameter, name and argument errors, `is_user_error`) as exit
status 2: any other exception, a plain ValueError included, is a bug (exit status 1). Classes that
were ValueErrors before stay ValueErrors too, so that callers' narrower handlers keep working.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
import errno
import os

# rclpy's user-facing errors (ParameterException and its subclasses such as
# InvalidParameterTypeException, NameValidationException, _rclpy.RCLInvalidROSArgsError,
# UnknownROSArgsError) and the embedded runtime's twins: matched by class name, since rclpy is
# not importable everywhere and its classes derive from neither ValueError nor this root.
RCLPY_USER_ERRORS = frozenset(
    {
        'ParameterException',
        'NameValidationException',
        'RCLInvalidROSArgsError',
        'UnknownROSArgsError',
    }
)
# A full disk or quota is the machine's state, never a bug, wherever the write happens.
_ENVIRONMENT_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT})


class ClothBenchError(Exception):
    """A user-facing error: one line naming the input and what is wrong; exit status 2."""


class InputError(ClothBenchError, ValueError):
    """A user-facing value that is refused; str() is one line naming the input and the problem."""


class PathError(ClothBenchError, OSError):
    """A path the user named that cannot be read or written, or a full disk."""


def one_line(exc: BaseException, with_type: bool = False) -> str:
    """Return str(exc) on one line; the class name where the text is empty (or `with_type`)."""
    text = ' '.join(str(exc).split())
    if not text:
        return type(exc).__name__
    return f'{type(exc).__name__}: {text}' if with_type else text


def is_rclpy_user_error(exc: BaseException) -> bool:
    """Return True for rclpy's (or the embedded runtime's) parameter, name and argument errors."""
    return any(cls.__name__ in RCLPY_USER_ERRORS for cls in type(exc).__mro__)


def is_user_error(exc: BaseException) -> bool:
    """Return True for what is reported as bad input (exit 2); anything else is a bug."""
    return (
        isinstance(exc, ClothBenchError)
        or is_rclpy_user_error(exc)
        or (isinstance(exc, OSError) and exc.errno in _ENVIRONMENT_ERRNOS)
    )


def path_error(path: str | os.PathLike[str], action: str, exc: OSError) -> PathError:
    """Return the PathError of an OSError met while `action` (`read`, `write`) on `path`."""
    return PathError(f'{os.fspath(path)}: cannot {action} ({exc.strerror or one_line(exc)})')


@contextmanager
def user_path(path: str | os.PathLike[str], action: str = 'read') -> Iterator[None]:
    """Turn an OSError inside the block, on a path the user named, into one PathError line."""
    try:
        yield
    except PathError:
        raise
    except OSError as exc:
        raise path_error(path, action, exc) from exc
