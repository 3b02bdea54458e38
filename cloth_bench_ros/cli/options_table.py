"""
The options table of docs/cli.md, made from the parser: each flag, its default, form and commands.

`python -m cloth_bench_ros.cli.options_table docs/cli.md` rewrites the table between its markers;
test/test_options.py fails when the file and the declarations differ.
"""

from __future__ import annotations

import argparse
from pathlib import Path
import sys

from cloth_bench_ros.cli import build_parser

BEGIN = '<!-- options table: made by `python -m cloth_bench_ros.cli.options_table docs/cli.md` -->'
END = '<!-- end of the options table -->'


def _commands(parser: argparse.ArgumentParser, path: str = ''):
    """Yield (command, action) for every option of every subcommand."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _commands(sub, f'{path} {name}'.strip())
        elif path:
            yield path, action


def _default(action: argparse.Action) -> str:
    option = getattr(action, 'declared', None)
    value = option.default if option is not None else action.default
    if option is not None and option.name == 'trials' and value == 0:
        return 'auto'  # the study's AUTO: the budget from the convergence curve
    if option is not None and option.unset is not None and value == option.unset:
        return ''  # "not given" (a node's -1 or 0)
    if isinstance(value, bool) or value in (None, '', argparse.SUPPRESS):
        return ''
    if isinstance(value, (list, tuple)):
        return ', '.join(f'{v:g}' if isinstance(v, float) else str(v) for v in value)
    return f'{value:g}' if isinstance(value, float) else str(value)


def _form(action: argparse.Action) -> str:
    if action.nargs == 0:
        return 'switch'
    if isinstance(action, argparse._AppendAction):
        return 'repeated'
    if action.nargs == '+':
        return 'one or more'
    return 'value'


def rows() -> list[tuple[str, str, str, str]]:
    """Return (flag, default, form, commands) per flag and default, in the flag's order."""
    table: dict[tuple[str, str, str], list[str]] = {}
    for command, action in _commands(build_parser()):
        if action.help == argparse.SUPPRESS or isinstance(action, argparse._HelpAction):
            continue
        flag = '/'.join(action.option_strings) or action.metavar or action.dest
        table.setdefault((flag, _default(action), _form(action)), []).append(command)
    return [(flag, default, form, ', '.join(commands))
            for (flag, default, form), commands in sorted(table.items())]


def renamed() -> list[tuple[str, str, str]]:
    """Return (old flag, new flag, commands) of every renamed flag (a note on stderr)."""
    found: dict[tuple[str, str], list[str]] = {}
    for command, action in _commands(build_parser()):
        target = getattr(action, 'target', None)
        if target is not None:
            key = (action.option_strings[0], target.option_strings[0])
            found.setdefault(key, []).append(command)
    return [(old, new, ', '.join(c)) for (old, new), c in sorted(found.items())]


def markdown() -> str:
    """Return the table, between its markers."""
    lines = [BEGIN, '', '| flag | default | form | commands |', '| --- | --- | --- | --- |']
    for flag, default, form, commands in rows():
        shown = f'`{default}`' if default else ''
        lines.append(f'| `{flag}` | {shown} | {form} | {commands} |')
    lines += ['', 'Old names, still accepted with a one-line note on stderr:', '',
              '| old | new | commands |', '| --- | --- | --- |']
    lines += [f'| `{old}` | `{new}` | {commands} |' for old, new, commands in renamed()]
    return '\n'.join([*lines, '', END])


def rewrite(path: Path) -> bool:
    """Replace the table between the markers of `path`; return whether it changed."""
    text = path.read_text()
    start, end = text.index(BEGIN), text.index(END) + len(END)
    new = text[:start] + markdown() + text[end:]
    path.write_text(new)
    return new != text


if __name__ == '__main__':
    print('changed' if rewrite(Path(sys.argv[1])) else 'unchanged')
