"""What every command shares: parsers, option types, parent parsers, bag and override checks."""

from __future__ import annotations

import argparse
from collections.abc import Callable, Iterable
from pathlib import Path
import sys
from typing import Any, Union

from cloth_bench_ros import options, validation
from cloth_bench_ros.command_options import COMMAND_FLAGS
from cloth_bench_ros.engines import engine_class, engine_device, known_engines
from cloth_bench_ros.engines.presets import preset_set as resolve
from cloth_bench_ros.errors import ClothBenchError
from cloth_bench_ros.options import Option
from cloth_bench_ros.studies.errors import check_scheduler_address
import numpy as np


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
        except ClothBenchError as exc:  # argparse names the option already
            raise argparse.ArgumentTypeError(str(exc).removeprefix(f'{name}: ')) from None

    parse.__name__ = name  # argparse names the type in some messages
    return parse


Flag = Union[str, Option, tuple[str, dict[str, Any]]]


def declaration(name: str) -> Option:
    """Return the declaration of `name`: a node parameter's, a shared flag's or a command's."""
    return COMMAND_FLAGS[name] if name in COMMAND_FLAGS else options.declared(name)


def add_option(parser: Any, name: str | Option, flag: str | None = None, **overrides: Any) -> None:
    """
    Add the flag of a declaration (a declared name, or an Option).

    Its type, check, default, choices, action and help (with unit, range and default) come from
    the declaration; `overrides` are argparse's keywords. A `help` override is another meaning:
    the declared unit, range and default stay.
    """
    declared = name if isinstance(name, Option) else declaration(name)
    flag = flag or declared.flag
    assert flag, f'{declared.name} has no flag'
    kwargs: dict[str, Any] = {'help': declared.help_text().replace('%', '%%')}
    if declared.action == 'store_true':
        kwargs['action'] = 'store_true'
    else:
        if declared.action == 'optional_bool':
            kwargs['action'] = argparse.BooleanOptionalAction
        elif declared.action == 'append' and declared.default is not None:
            kwargs['action'] = _Repeated
        elif declared.action:
            kwargs['action'] = declared.action
        default = declared.default
        if declared.action == 'append':
            pass  # a list, each of its values checked as the flag's
        elif default is not None and declared.action != 'optional_bool' and not declared.validate:
            default = declared.check(default)  # a validated default is a value already
        kwargs['default'] = default
        if declared.choices:
            kwargs['choices'] = declared.choices
        elif declared.type is not bool and (declared.type is not str or declared.validate):
            kwargs['type'] = option(declared.parse, flag)
    for key in ('metavar', 'dest', 'nargs'):
        if getattr(declared, key):
            kwargs[key] = getattr(declared, key)
    if declared.required:
        kwargs['required'] = True
    if 'help' in overrides:  # another meaning; the unit, range and default stay the declared
        tail = declared.help_text().removeprefix(declared.help)
        overrides['help'] = (overrides['help'] + tail).replace('%', '%%')
    kwargs.update(overrides)
    parser.add_argument(flag, **kwargs).declared = declared  # type: ignore[attr-defined]


def add_options(parser: Any, flags: Iterable[Flag]) -> None:
    """
    Add flags in order: a declared name, an Option of this command, or (name, changes).

    `changes` are fields of the declaration that differ for this command (its help, default,
    action), e.g. ('engines', {'help': 'repeat (default mujoco)'}).
    """
    for item in flags:
        if isinstance(item, tuple) and set(item[1]) == {'help'}:
            add_option(parser, item[0], help=item[1]['help'])  # the declaration, another meaning
        elif isinstance(item, tuple):
            add_option(parser, declaration(item[0]).variant(**item[1]))
        else:
            add_option(parser, item)


class _Repeated(argparse._AppendAction):
    """A repeated flag with a declared list as its default: the values given replace it."""

    def __call__(self, parser, namespace, values, option_string=None) -> None:  # noqa: D102
        if getattr(namespace, self.dest, None) is self.default:
            setattr(namespace, self.dest, [])
        super().__call__(parser, namespace, values, option_string)


class _Renamed(argparse.Action):
    """An old name of a flag: a one-line note on stderr, then the new flag's action."""

    def __init__(self, option_strings, dest, target, split=False, **kwargs) -> None:
        nargs = 0 if target.nargs == 0 else None
        super().__init__(option_strings, argparse.SUPPRESS, nargs=nargs,
                         default=argparse.SUPPRESS, help=argparse.SUPPRESS)
        self.target = target
        self.split = split  # an old comma-separated list: one value of the new flag each

    def __call__(self, parser, namespace, values, option_string=None) -> None:  # noqa: D102
        new = self.target.option_strings[0]
        print(f'cloth-bench: {option_string} is deprecated, use {new}'
              + (' (repeated)' if self.split else ''), file=sys.stderr)
        if self.target.nargs == 0:
            self.target(parser, namespace, [], new)
            return
        words = [w.strip() for w in values.split(',') if w.strip()] if self.split else [values]
        if not words:
            raise argparse.ArgumentError(self, f'no value in {values!r} (comma-separated)')
        for word in words:
            self.target(parser, namespace, parser._get_values(self.target, [word])
                        if self.target.nargs is None else word, new)


def add_renamed(parser: Any, old: str, new: str, split: bool = False) -> None:
    """
    Accept `old`, a flag's former name, for `new`: the same value, and a note on stderr.

    With `split`, the old flag took a comma-separated list and the new one is repeated.
    """
    target = next(a for a in parser._actions if new in a.option_strings)
    action = parser.add_argument(old, action=_Renamed, target=target, split=split)
    action.declared = target.declared  # type: ignore[attr-defined]


def scheduler(text: str) -> str:
    """Return a Dask scheduler address (tcp://127.0.0.1:8786)."""
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
    add_option(parent, 'presets')
    return parent


def preset_set(args: argparse.Namespace) -> Any:
    """Return the PresetSet of --presets (EngineError, one line, for an unknown name or path)."""
    return resolve(args.presets)


def live_options() -> argparse.ArgumentParser:
    """Parent parser: --live and its server's address and wait (docs/live.md)."""
    parent = argparse.ArgumentParser(add_help=False)
    group = parent.add_argument_group('live view in Foxglove (see docs/live.md)')
    add_options(group, ('live', 'live_host', 'live_port', 'live_wait'))
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


def recording_options(parser: argparse.ArgumentParser) -> Any:
    """Add the recording options (options.RECORDING_FLAGS) as one group; return the group."""
    group = parser.add_argument_group('scoring your own recording (see docs/own-recording.md)')
    add_options(group, options.RECORDING_FLAGS)
    return group


def check_split_without_engine(args: argparse.Namespace, command: str) -> None:
    """Refuse --align simulation: identify and rank find a recording's trials without an engine."""
    if args.align == 'simulation':
        raise UserError(
            f'{command}: --align simulation: {command} finds the trials of a recording without an '
            'engine (--align onset, or --start-time S for a recording of one trial)'
        )


def replay_params(args: argparse.Namespace) -> dict:
    """Return the recorder parameters of the recording options (a plain recording's)."""
    params = {}
    for name in options.REPLAY_OPTIONS:
        value = getattr(args, name)
        params[name] = options.OPTIONS[name].default if value is None else value
    if args.transform:
        params['transform'] = [float(v) for v in read_transform(args.transform).ravel()]
    return params


def executor_options() -> argparse.ArgumentParser:
    """Parent parser: where a study's cells run (local workers or Dask) and its progress bar."""
    parent = argparse.ArgumentParser(add_help=False)
    add_option(parent, 'workers')
    add_option(parent, 'scheduler', type=scheduler)
    add_option(parent, 'no_progress')
    return parent


def device(text: str) -> str:
    """
    Return the Newton device of `--device` (cpu, cuda, cuda:N, auto), checked on this machine.

    A device that is not here is refused now, in one line naming what Warp found.
    """
    try:
        name = validation.device(text, '--device')

        return engine_device('newton', {'device': name})
    except ClothBenchError as exc:  # InputError, or EngineError (also for Newton not installed)
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
    add_option(parser, 'newton_device', type=device,
               action=_DeviceAction if with_set else 'store')


def engine_override_option(
    parser: argparse.ArgumentParser, help: str  # noqa: A002  (argparse's own keyword)
) -> None:
    """--set ENGINE.PARAM=VALUE (repeatable), and --device for Newton."""
    add_option(parser, options.declared('set').variant(help=help))
    device_option(parser)


def engine_models(args: argparse.Namespace) -> None:
    """
    --engine NAME:MODEL: the engine NAME with `--set NAME.model=MODEL` (one syntax, every command).

    rank parses its own entrants (several models of one engine); elsewhere an engine has one model.
    """
    given = getattr(args, 'engine', None)
    if not given or getattr(args, 'command', '') == 'rank':
        return
    texts = [given] if isinstance(given, str) else list(given)
    names: list[str] = []
    models: dict[str, str] = {}
    for text in texts:
        name, colon, model = text.strip().partition(':')
        names.append(name)
        if not colon:
            continue
        if not model:
            raise UserError(f'--engine {text}: no model after the colon (e.g. newton:vbd)')
        if not hasattr(args, 'set'):
            raise UserError(f'--engine {text}: {args.command} takes engine names only')
        if models.setdefault(name, model) != model:
            raise UserError(f'--engine {name}: one model per engine here ({models[name]} and '
                            f'{model}); rank compares several')
    args.engine = names[0] if isinstance(given, str) else names
    if models:
        args.set = [*(f'{n}.model={m}' for n, m in models.items()), *(args.set or [])]


def engine_overrides(specs: list[str] | None, engines: list[str] | None = None) -> dict[str, dict]:
    """Return --set engine.param=value as {engine: {param: value}}, checked against the schemas."""
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
            model = f' (or --engine {engine}:MODEL)' if 'model' in params else ''
            given = f'--set {engine}{model}'
            raise UserError(f'{given}: {exc}') from None
    return overrides


def available_engines() -> list[str]:
    """Names of the engines that import on this machine."""
    return [i.name for i in known_engines() if i.available]


def read_transform(path: str):
    """Return a 4x4 matrix from a .npy file or a text file of 16 numbers."""
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
    """Add `--metric`: what rankings and comparisons are made on (metric_choice.py)."""
    add_option(parser, 'metric')
