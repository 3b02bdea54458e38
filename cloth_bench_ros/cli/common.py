"""What every command shares: parsers, option types, parent parsers, bag and override checks."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from contextlib import closing
from pathlib import Path
from typing import Any

from cloth_bench_ros import validation
from cloth_bench_ros.errors import ClothBenchError
from cloth_bench_ros.options import OPTIONS

CLOTH_CHOICES = OPTIONS['cloth'].choices


class UserError(ClothBenchError):
    """Bad input from the user: printed as one line, exit status 2."""


class Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line (the usage is in --help)."""

    def error(self, message: str):
        self.exit(2, f'{self.prog}: error: {message}\n')


def option(check: Callable[[str, str], Any], name: str) -> Callable[[str], Any]:
    """Return an argparse type from a validation check: its one-line error becomes argparse's."""

    def parse(text: str) -> Any:
        try:
            return check(text, name)
        except validation.InputError as exc:  # argparse names the option already
            raise argparse.ArgumentTypeError(str(exc).removeprefix(f'{name}: ')) from None

    parse.__name__ = name  # argparse names the type in some messages
    return parse


def number(check: Callable[..., float], name: str) -> Callable[[str], float]:
    """Return an argparse type for a number checked by `check(value, name)`."""
    return option(lambda t, n: check(validation.parse_number(t, n), n), name)


def integer(name: str, low: int, high: int | None = None) -> Callable[[str], int]:
    """Return an argparse type for an integer in [low, high]."""
    return option(
        lambda t, n: validation.integer(validation.parse_integer(t, n), n, low, high), name
    )


def factor(name: str) -> Callable[[str], float]:
    """Return an argparse type for a finite factor > 1."""
    return number(lambda v, n: validation.number(v, n, 1.0, None, low_open=True), name)


rate = option(OPTIONS['rate_hz'].parse, '--rate')
seed = option(OPTIONS['seed'].parse, '--seed')
frame = option(
    lambda t, n: validation.frame_index(validation.parse_integer(t, n), n),
    '--change-of-phase-frame',
)
grid = option(validation.parse_grid, '--grid')
workers = integer('--workers', 1)
non_negative = number(validation.non_negative, 'value')


def add_option(parser: Any, name: str, flag: str | None = None, **overrides: Any) -> None:
    """Add the flag of options.OPTIONS[name]: its type, check, default, choices and help."""
    declared = OPTIONS[name]
    flag = flag or declared.flag
    assert flag, f'{name} has no flag'
    kwargs: dict[str, Any] = {
        'default': declared.check(declared.default),
        'help': declared.help_text(),
    }
    if declared.choices:
        kwargs['choices'] = declared.choices
    else:
        kwargs['type'] = option(declared.parse, flag)
    if declared.metavar:
        kwargs['metavar'] = declared.metavar
    if 'help' in overrides:  # another meaning; the unit, range and default stay the declared
        overrides['help'] = '; '.join([overrides['help'], *declared.help_text().split('; ')[1:]])
    kwargs.update(overrides)
    parser.add_argument(flag, **kwargs).declared = declared  # type: ignore[attr-defined]


def scheduler(text: str) -> str:
    """Return a Dask scheduler address (tcp://127.0.0.1:8786)."""
    from cloth_bench_ros.studies.dask_executor import check_scheduler_address

    try:
        return check_scheduler_address(text)
    except ClothBenchError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def scene_options(primitive: bool = True) -> argparse.ArgumentParser:
    """Parent parser: --cloth and --primitive (one trial's cloth and task)."""
    parent = argparse.ArgumentParser(add_help=False)
    add_option(parent, 'cloth')
    if primitive:
        add_option(parent, 'primitive')
    return parent


def presets_options() -> argparse.ArgumentParser:
    """Parent parser: --presets, a named preset set or a directory of <engine>.yaml files."""
    parent = argparse.ArgumentParser(add_help=False)
    parent.add_argument(
        '--presets',
        default='default',
        help=(
            'cloth parameters: default (config/presets), identified (fitted to the bundled '
            'MuJoCo-made references), identified-newton-vbd (fitted to the Newton VBD ones), or '
            'a directory of <engine>.yaml files (e.g. an identify --output)'
        ),
    )
    return parent


def preset_set(args: argparse.Namespace) -> Any:
    """Return the PresetSet of --presets (EngineError, one line, for an unknown name or path)."""
    from cloth_bench_ros.engines.presets import preset_set as resolve

    return resolve(args.presets)


def live_options() -> argparse.ArgumentParser:
    """Parent parser: --live and its server's address and wait (docs/live.md)."""
    from cloth_bench_ros.data.live_view import DEFAULT_HOST, DEFAULT_PORT, DEFAULT_WAIT_S

    parent = argparse.ArgumentParser(add_help=False)
    group = parent.add_argument_group('live view in Foxglove (see docs/live.md)')
    group.add_argument(
        '--live',
        action='store_true',
        help='serve the run to Foxglove while it goes (WebSocket; the error on the cloth, CD/HD)',
    )
    group.add_argument(
        '--live-host',
        type=option(validation.host, '--live-host'),
        default=DEFAULT_HOST,
        help=f'address the live view binds (default {DEFAULT_HOST}: this machine only)',
    )
    group.add_argument(
        '--live-port',
        type=integer('--live-port', 0, 65535),
        default=DEFAULT_PORT,
        help=f"its port (default {DEFAULT_PORT}, Foxglove's)",
    )
    group.add_argument(
        '--live-wait',
        type=number(validation.wait_s, '--live-wait'),
        default=DEFAULT_WAIT_S,
        metavar='S',
        help=(
            f'seconds a lockstep run waits for a first viewer before it starts (default'
            f' {DEFAULT_WAIT_S:g}; then it goes on without one)'
        ),
    )
    return parent


def live_parameters(args: argparse.Namespace) -> dict:
    """Return the evaluator's live-view parameters of --live and its options ({} without)."""
    if not getattr(args, 'live', False):
        return {}
    return {
        'live': True,
        'live_host': args.live_host,
        'live_port': int(args.live_port),
        'live_wait': float(args.live_wait),
    }


def executor_options() -> argparse.ArgumentParser:
    """Parent parser: where a study's cells run (local workers or Dask) and its progress bar."""
    parent = argparse.ArgumentParser(add_help=False)
    parent.add_argument(
        '--workers', type=workers, help='local worker processes (default: all cores)'
    )
    parent.add_argument(
        '--scheduler',
        type=scheduler,
        help='run on an existing Dask cluster, e.g. tcp://127.0.0.1:8786',
    )
    parent.add_argument('--no-progress', action='store_true', help='no progress bar')
    return parent


def device(text: str) -> str:
    """
    Return the Newton device of `--device` (cpu, cuda, cuda:N, auto), checked on this machine.

    A device that is not here is refused now, in one line naming what Warp found.
    """
    try:
        name = validation.device(text, '--device')
        from cloth_bench_ros.engines import engine_device

        return engine_device('newton', {'device': name})
    except ValueError as exc:  # InputError, or EngineError (also for Newton not installed)
        raise argparse.ArgumentTypeError(
            str(exc).removeprefix('--device: ').removeprefix('parameter device: ')
        ) from None


class _DeviceAction(argparse.Action):
    """--device X: the same as --set newton.device=X (so every command with --set has it)."""

    def __call__(self, parser, namespace, values, option_string=None) -> None:  # noqa: D102
        specs = list(getattr(namespace, 'set', None) or [])
        setattr(namespace, 'set', [*specs, f'newton.device={values}'])
        setattr(namespace, self.dest, values)


def device_option(parser: argparse.ArgumentParser, with_set: bool = True) -> None:
    """
    --device cpu|cuda[:N]|auto: where Newton runs (default auto: CUDA if Warp finds it, else CPU).

    With `with_set`, the choice is also an engine override (`--set newton.device=...`), which is
    how it reaches the engines of every command that takes --set.
    """
    parser.add_argument(
        '--device',
        type=device,
        action=_DeviceAction if with_set else 'store',
        metavar='DEVICE',
        help=(
            "Newton's device: cpu, cuda or cuda:N (default: the first CUDA device Warp finds,"
            ' else cpu)'
        ),
    )


def engine_override_option(
    parser: argparse.ArgumentParser, help: str  # noqa: A002  (argparse's own keyword)
) -> None:
    """--set ENGINE.PARAM=VALUE (repeatable), and --device for Newton."""
    parser.add_argument('--set', action='append', metavar='ENGINE.PARAM=VALUE', help=help)
    device_option(parser)


def check_bag(bag: Path, topic: str | None = None) -> None:
    """Fail early, in one line naming the bag, unless the cloud topic's first frame decodes."""
    from cloth_bench_ros.data import BagReader
    from cloth_bench_ros.data.bag_reader import decode_cloud

    with BagReader(bag) as reader:
        topic = reader.cloud_topic(topic)
        with closing(reader.raw_messages([topic])) as frames:  # its file is closed here
            first = next(frames, None)
        if first is None:
            raise UserError(f'bag {bag}: no PointCloud2 message on {topic} could be read')
        decode_cloud(bag, topic, 0, first[2], first[3])


def engine_overrides(specs: list[str] | None, engines: list[str] | None = None) -> dict[str, dict]:
    """Return --set engine.param=value as {engine: {param: value}}, checked against the schemas."""
    from cloth_bench_ros.engines import engine_class

    overrides = validation.parse_overrides(specs)
    for engine, params in overrides.items():
        if engines is not None and engine not in engines and set(params) == {'device'}:
            raise UserError(
                f'--device applies to engine {engine}, which is not part of this run'
                f' ({", ".join(engines)})'
            )
        if engines is not None and engine not in engines:
            raise UserError(
                f'--set {engine}.…: engine {engine} is not part of this run ({", ".join(engines)})'
            )
        try:
            engine_class(engine).validate_params(params)
        except ClothBenchError as exc:
            raise UserError(f'--set {engine}: {exc}') from None
    return overrides


def available_engines() -> list[str]:
    """Names of the engines that import on this machine."""
    from cloth_bench_ros.engines import known_engines

    return [i.name for i in known_engines() if i.available]


def read_transform(path: str):
    """Return a 4x4 matrix from a .npy file or a text file of 16 numbers."""
    import numpy as np

    try:
        if path.endswith('.npy'):
            values = np.load(path).astype(float).ravel()
        else:
            values = np.array([float(x) for x in Path(path).read_text().replace(',', ' ').split()])
    except (OSError, ValueError) as exc:
        raise UserError(f'transform {path}: cannot be read ({exc})') from None
    if values.size != 16 or not np.isfinite(values).all():
        raise UserError(
            f'transform {path}: needs 16 finite numbers (a 4x4 matrix), found {values.size}'
        )
    return values.reshape(4, 4)


def add_metric_option(parser: argparse.ArgumentParser) -> None:
    """Add `--metric`: what rankings and comparisons are made on (core/metric_choice.py)."""
    from cloth_bench_ros.core.metric_choice import DEFAULT_METRIC, METRICS

    parser.add_argument(
        '--metric',
        default=DEFAULT_METRIC,
        choices=tuple(METRICS),
        help=f"metric to rank and compare on (default {DEFAULT_METRIC}: the paper's CD;"
        ' docs/metrics.md)',
    )
