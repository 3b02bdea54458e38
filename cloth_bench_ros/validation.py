"""
The one validation layer for user-facing values: CLI options, node parameters, presets, metadata.

Every value a user (or a file a user gave) hands the project goes through these functions, so the
same rules hold everywhere: numbers are finite and inside their range, integers are integers
(`2.7` and `true` are refused, never coerced), rates and mesh sizes are bounded before anything
is allocated, seeds and frame indices are non-negative, and a value given twice where one is
meant is refused rather than guessed. Each refusal is an `InputError` whose str() is one line
naming the input (`parameter grid_nx`, `--rate`, `preset file X: presets.towel.dynamic`) and what
is wrong with it.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
import math
import numbers
from pathlib import Path
import re
from typing import Any

from cloth_bench_ros.errors import InputError
from cloth_bench_ros.safe_io import load_yaml_bounded, UnsafeInputError

MIN_RATE_HZ = 1.0  # below this a trajectory has too few steps to score
MAX_RATE_HZ = 10_000.0  # 10x the paper's highest rate; 1e9 would allocate 55 GiB of targets
MAX_GRID_SIDE = 201  # vertices along one side of the cloth mesh
MAX_GRID_VERTICES = 20_000  # the synthetic reference uses 31 x 43 = 1333
MAX_SEED = 2**63 - 1  # a ROS 2 integer parameter is int64
MAX_FRAME = 10**7  # 90 hours at 30 fps
MAX_ENGINE_PARAMS_BYTES = 64 * 1024  # the engine_params YAML string of a node
MAX_TIME_OFFSET_S = 1e6  # s; keeps stamps well inside int64 nanoseconds
# A cloth's size (docs/identification.md): its grasped edge lies on the table's x extent (-0.3 to
# 0.8 m, corners at x = 0 and W), and it hangs clear of the table top (0.195 m) from the grippers'
# start height (1.0 m) with 5 cm to spare.
CLOTH_WIDTH_RANGE = (0.1, 0.8)  # m
CLOTH_LENGTH_RANGE = (0.1, 0.75)  # m
CLOTH_MASS_RANGE = (1e-4, 100.0)  # kg, the engines' own range of a cloth's mass


def _is_number(value: object) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def number(
    value: object,
    name: str,
    low: float | None = None,
    high: float | None = None,
    low_open: bool = False,
    unit: str = '',
) -> float:
    """Return a finite real number in [low, high] (or (low, high]); bools and text refused."""
    if not _is_number(value):
        raise InputError(f'{name}: {value!r} is not a number')
    x = float(value)  # type: ignore[arg-type]
    if not math.isfinite(x):
        raise InputError(f'{name}: {value!r} is not a finite number')
    below = low is not None and (x <= low if low_open else x < low)
    if below or (high is not None and x > high):
        left = '(' if low_open else '['
        suffix = f' {unit}' if unit else ''
        raise InputError(f'{name}: {value!r}{suffix} is outside {left}{_g(low)}, {_g(high)}]')
    return x


def integer(value: object, name: str, low: int | None = None, high: int | None = None) -> int:
    """Return an integer in [low, high]; an integral float is accepted, 2.7 and bools refused."""
    if isinstance(value, bool) or not (isinstance(value, numbers.Integral) or _is_number(value)):
        raise InputError(f'{name}: {value!r} is not an integer')
    if not isinstance(value, numbers.Integral):
        x = float(value)  # type: ignore[arg-type]
        if not math.isfinite(x) or not x.is_integer():
            raise InputError(f'{name}: {value!r} is not an integer')
    n = int(value)  # type: ignore[call-overload]
    if (low is not None and n < low) or (high is not None and n > high):
        raise InputError(f'{name}: {n} is outside [{_g(low)}, {_g(high)}]')
    return n


def _g(bound: float | None) -> str:
    if bound is None:
        return 'inf'
    return f'{bound:g}' if isinstance(bound, float) else str(bound)


def boolean(value: object, name: str) -> bool:
    """Return true or false, nothing else (no 0/1, no strings)."""
    if not isinstance(value, bool):
        raise InputError(f'{name}: {value!r} is not true or false')
    return value


def choice(value: object, name: str, choices: Sequence[str]) -> str:
    """One of `choices`."""
    if not isinstance(value, str) or value not in choices:
        raise InputError(f'{name}: {value!r} is not one of {", ".join(choices)}')
    return value


_DEVICE = re.compile(r'auto|cpu|cuda(:\d{1,4})?')


def device(value: object, name: str = 'device') -> str:
    """
    Return a compute device's name: `cpu`, `cuda`, `cuda:N`, or `auto` (CUDA if one is found).

    Only the spelling is checked here; whether the device is on this machine is the engine's
    question (`engines.newton_cloth.resolve_device`), asked before anything runs.
    """
    if not isinstance(value, str) or not _DEVICE.fullmatch(value.strip()):
        raise InputError(f'{name}: {value!r} is not cpu, cuda, cuda:N or auto')
    return value.strip()


def rate_hz(value: object, name: str = 'rate') -> float:
    """Return a simulator rate in [MIN_RATE_HZ, MAX_RATE_HZ] Hz."""
    return number(value, name, MIN_RATE_HZ, MAX_RATE_HZ, unit='Hz')


def positive(value: object, name: str, high: float | None = None) -> float:
    """Return a finite number > 0 (and <= high)."""
    return number(value, name, 0.0, high, low_open=True)


def non_negative(value: object, name: str, high: float | None = None) -> float:
    """Return a finite number >= 0 (and <= high)."""
    return number(value, name, 0.0, high)


def time_offset(value: object, name: str) -> float:
    """Return a duration in seconds added to or skipped from stamps, in [0, MAX_TIME_OFFSET_S]."""
    return number(value, name, 0.0, MAX_TIME_OFFSET_S, unit='s')


def seed(value: object, name: str = 'seed') -> int:
    """Return a random seed: an integer in [0, 2^63 - 1]."""
    return integer(value, name, 0, MAX_SEED)


MAX_WAIT_S = 3600.0  # a live view's wait for its first viewer


def port(value: object, name: str) -> int:
    """Return a TCP port to serve on: 1-65535, or 0 for one the system picks."""
    return integer(value, name, 0, 65535)


def host(value: object, name: str) -> str:
    """Return a host name or address to serve on (not empty, no spaces)."""
    if not isinstance(value, str) or not value or any(c.isspace() for c in value):
        raise InputError(f'{name}: {value!r} is not a host name or address')
    return value


def wait_s(value: object, name: str) -> float:
    """Return a wait in seconds, in [0, MAX_WAIT_S]."""
    return number(value, name, 0.0, MAX_WAIT_S, unit='s')


def frame_index(value: object, name: str, unset: int | None = None) -> int | None:
    """Return a frame index >= 0; `unset` (e.g. -1 for "from the bag") and None mean none given."""
    if value is None or (unset is not None and not isinstance(value, bool) and value == unset):
        return None
    return integer(value, name, 0, MAX_FRAME)


def grid(nx: object, nz: object, name: str = 'grid') -> tuple[int, int]:
    """Return a cloth mesh size: 2..MAX_GRID_SIDE per side, MAX_GRID_VERTICES in all."""
    x = integer(nx, f'{name} nx', 2, MAX_GRID_SIDE)
    z = integer(nz, f'{name} nz', 2, MAX_GRID_SIDE)
    if x * z > MAX_GRID_VERTICES:
        raise InputError(
            f'{name}: {x}x{z} = {x * z} vertices, more than the {MAX_GRID_VERTICES} allowed'
        )
    return x, z


def unique(values: Iterable[str], name: str) -> list[str]:
    """`values` with no repeats; a repeated one is refused (ambiguous, never merged)."""
    seen: list[str] = []
    for v in values:
        if v in seen:
            raise InputError(f'{name}: {v!r} is given twice')
        seen.append(v)
    return seen


def existing_dir(path: str | Path, name: str) -> Path:
    """Return a directory that exists."""
    p = Path(path)
    if not p.is_dir():
        raise InputError(
            f'{name} {p}: ' + ('not a directory' if p.exists() else 'no such directory')
        )
    return p


# ------------------------------------------------------------------------------ text from users

_GRID = re.compile(r'\s*(\d{1,9})\s*[xX]\s*(\d{1,9})\s*')


def parse_number(text: str, name: str) -> float:
    """Return a finite number from command-line text."""
    try:
        x = float(text)
    except ValueError:
        raise InputError(f'{name}: {text!r} is not a number') from None
    return number(x, name)


def parse_integer(text: str, name: str) -> int:
    """Return an integer from command-line text ("3", not "3.0" nor "three")."""
    try:
        return int(text.strip(), 10)
    except ValueError:
        raise InputError(f'{name}: {text!r} is not an integer') from None


def parse_grid(text: str, name: str = 'grid') -> tuple[int, int]:
    """Parse "11x15" -> (11, 15), bounded by `grid`; nothing is allocated before the check."""
    m = _GRID.fullmatch(text)
    if not m:
        raise InputError(f'{name} {text!r} is not NXxNZ (e.g. 11x15)')
    return grid(int(m.group(1)), int(m.group(2)), f'{name} {text.strip()}')


def parse_cloth_size(text: str, name: str = 'cloth size') -> tuple[float, float] | None:
    """Parse "W,L" in metres -> (W, L) inside the cloth ranges; '' -> None (the benchmark's)."""
    if not text.strip():
        return None
    parts = text.split(',')
    if len(parts) != 2:
        raise InputError(f'{name} {text!r} is not W,L in metres (e.g. 0.4,0.6)')
    width = number(parse_number(parts[0], name), f'{name} width', *CLOTH_WIDTH_RANGE, unit='m')
    length = number(parse_number(parts[1], name), f'{name} length', *CLOTH_LENGTH_RANGE, unit='m')
    return width, length


def parse_value(text: str) -> bool | int | float | str:
    """Return a command-line parameter value: bool (true/on/yes, false/off/no), int, float, str."""
    low = text.strip().lower()
    if low in ('true', 'on', 'yes', 'false', 'off', 'no'):
        return low in ('true', 'on', 'yes')
    try:
        return int(text, 10)
    except ValueError:
        pass
    try:
        return float(text)
    except ValueError:
        return text.strip()


def parse_overrides(specs: Sequence[str] | None) -> dict[str, dict[str, Any]]:
    """Return {"engine": {"param": value}} from "engine.param=value" strings; no repeats."""
    out: dict[str, dict[str, Any]] = {}
    for spec in specs or ():
        lhs, sep, value = spec.partition('=')
        engine, dot, param = lhs.partition('.')
        engine, param = engine.strip(), param.strip()
        if not sep or not dot or not engine or not param:
            raise InputError(
                f'--set {spec!r} is not engine.param=value (e.g. mujoco.self_collision=true)'
            )
        params = out.setdefault(engine, {})
        if param in params:
            raise InputError(f'--set {engine}.{param}: given twice')
        params[param] = parse_value(value)
    return out


def parameter_mapping(text: object, name: str) -> dict[str, Any]:
    """Return a YAML mapping of parameter name -> scalar (a node's `engine_params`)."""
    if not isinstance(text, str):
        raise InputError(f'{name}: {text!r} is not a YAML string')
    if len(text.encode('utf-8')) > MAX_ENGINE_PARAMS_BYTES:
        raise InputError(f'{name}: longer than {MAX_ENGINE_PARAMS_BYTES} bytes')
    try:
        data = load_yaml_bounded(text, name) if text.strip() else {}
    except UnsafeInputError as exc:
        raise InputError(str(exc)) from None
    if data is None:
        data = {}
    if not isinstance(data, Mapping):
        raise InputError(f'{name}: {text!r} is not a mapping of parameter: value')
    for key, value in data.items():
        if not isinstance(key, str):
            raise InputError(f'{name}: key {key!r} is not a parameter name')
        if not isinstance(value, (bool, int, float, str)):
            raise InputError(f'{name}: {key} is {type(value).__name__}, not a single value')
    return dict(data)


def node_parameters(node: Any, checks: Mapping[str, Any]) -> dict[str, Any]:
    """
    Each declared parameter `name` of `node` checked by `checks[name](value, "parameter name")`.

    The error names the node and the parameter, e.g. "simulator: parameter grid_nx: -3 is outside
    [0, 201]".
    """
    out = {}
    for pname, check in checks.items():
        value = node.get_parameter(pname).value
        try:
            out[pname] = check(value, f'parameter {pname}')
        except InputError as exc:
            raise InputError(f'{node.get_name()}: {exc}') from None
    return out
