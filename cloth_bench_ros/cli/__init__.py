"""
`cloth-bench`: the command-line front door, one parser module per command group.

Each command's parser (cli/run.py, cli/studies.py, ...) is light and names the function that
runs it (`set_defaults(implementation='cloth_bench_ros.cli.run_command:cmd_run')`); `main` loads
that module only when the command runs, as ros2cli loads its verbs, so that `cloth-bench --help`
imports none of the features (Dask, Optuna, matplotlib, the bag readers).
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import sys
from typing import Callable
import warnings

from cloth_bench_ros.cli import data, hil, identify, rank, run, studies
from cloth_bench_ros.cli.common import engine_models, Parser, UserError
from cloth_bench_ros.errors import is_user_error, one_line
from cloth_bench_ros.studies.errors import StudyInterrupted

__all__ = ['UserError', 'build_parser', 'main']


def build_parser() -> argparse.ArgumentParser:
    """Return the `cloth-bench` parser with every command group's subcommands."""
    parser = Parser(prog='cloth-bench', description='Sim-to-real benchmark of cloth simulators.')
    parser.add_argument('-v', '--verbose', action='store_true', help="log the nodes' messages")
    sub = parser.add_subparsers(dest='command', required=True, parser_class=Parser)
    for group in (run, studies, identify, rank, hil, data):
        group.add_parsers(sub)
    return parser


def implementation(name: str) -> Callable[[argparse.Namespace], int]:
    """Return the command function `module:function` names, its module imported now."""
    module, _, function = name.partition(':')
    return getattr(importlib.import_module(module), function)


def main(argv: list[str] | None = None) -> int:
    """Parse, run the command; a user error is one line and exit 2, a bug one line and exit 1."""
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING, format='%(levelname)s %(message)s'
    )
    warnings.formatwarning = lambda message, *_: f'cloth-bench: warning: {message}\n'
    try:
        engine_models(args)
        return implementation(args.implementation)(args)
    except BrokenPipeError:  # `cloth-bench ... | head`: the reader left, nothing to say
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except StudyInterrupted as exc:
        print(f'cloth-bench: {exc}', file=sys.stderr)
        return 130
    except KeyboardInterrupt:
        print('cloth-bench: interrupted', file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 - sorted below: bad input (2) or a bug (1)
        if is_user_error(exc):
            print(f'cloth-bench: error: {one_line(exc)}', file=sys.stderr)
            return 2
        if args.verbose:
            raise
        print(
            f'cloth-bench: internal error (a bug): {one_line(exc, with_type=True)} '
            '(--verbose shows the traceback)',
            file=sys.stderr,
        )
        return 1
