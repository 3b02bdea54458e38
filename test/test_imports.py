"""
Imports sit at a module's top; one left inside a function says why on its line.

A function-level import is kept only for an optional dependency (Newton, Warp, open3d, real
rclpy) or a measured start-up cost, with an end-of-line comment `# lazy: <reason>`; there are at
most MAX_FUNCTION_IMPORTS of them in the package (docs/development.md). Each import statement
counts once, also inside a nested function.
"""

from __future__ import annotations

import ast
from dataclasses import dataclass
import io
from pathlib import Path
import re
import subprocess
import sys
import tokenize

import cloth_bench_ros
import pytest

PACKAGE = Path(cloth_bench_ros.__file__).parent
MAX_FUNCTION_IMPORTS = 40
LAZY_REASON = re.compile(r'#\s*lazy:\s*\S')
TOP_LEVEL = '(top level)'  # the package's own modules: options.py, validation.py, ...


@dataclass(frozen=True)
class FunctionImport:
    path: str  # relative to the package's parent: cloth_bench_ros/core/cleaning.py
    line: int
    statement: str
    lazy_reason: bool  # the statement's lines carry a `# lazy: ...` comment

    def __str__(self) -> str:
        return f'{self.path}:{self.line}: {self.statement}'


def function_imports(source: str, path: str = '<source>') -> list[FunctionImport]:
    """Return each import statement inside a function of `source`, in line order."""
    comments = {
        token.start[0]: token.string
        for token in tokenize.generate_tokens(io.StringIO(source).readline)
        if token.type == tokenize.COMMENT
    }
    found: dict[tuple[int, int], FunctionImport] = {}  # a nested function's: once
    for function in ast.walk(ast.parse(source, path)):
        if not isinstance(function, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        for node in ast.walk(function):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                lines = range(node.lineno, (node.end_lineno or node.lineno) + 1)
                found[(node.lineno, node.col_offset)] = FunctionImport(
                    path,
                    node.lineno,
                    ast.unparse(node),
                    any(LAZY_REASON.search(comments.get(n, '')) for n in lines),
                )
    return [found[key] for key in sorted(found)]


def part_of(module: Path) -> str:
    """Return the subpackage a module is in (core, engines, ...), or TOP_LEVEL."""
    parts = module.relative_to(PACKAGE).parts
    return parts[0] if len(parts) > 1 else TOP_LEVEL


def package_imports(parts: set[str] | None = None) -> list[FunctionImport]:
    """Return the function-level imports of the package's modules (those of `parts` if given)."""
    out = []
    for module in sorted(PACKAGE.rglob('*.py')):
        if parts is None or part_of(module) in parts:
            path = str(module.relative_to(PACKAGE.parent))
            out += function_imports(module.read_text(), path)
    return out


def unexplained(imports: list[FunctionImport]) -> list[str]:
    return [str(i) for i in imports if not i.lazy_reason]


def over_the_cap(imports: list[FunctionImport], cap: int = MAX_FUNCTION_IMPORTS) -> str | None:
    """Return why `imports` are too many (their count per subpackage), or None."""
    if len(imports) <= cap:
        return None
    per_part: dict[str, int] = {}
    for i in imports:
        part = part_of(PACKAGE.parent / i.path)
        per_part[part] = per_part.get(part, 0) + 1
    counts = ', '.join(f'{part} {n}' for part, n in sorted(per_part.items()))
    return f'{len(imports)} imports inside functions, more than {cap} ({counts})'


PARTS = sorted({part_of(m) for m in PACKAGE.rglob('*.py')})


@pytest.mark.parametrize('part', PARTS)
def test_every_function_level_import_says_why_it_is_lazy(part):
    missing = unexplained(package_imports({part}))
    assert not missing, (
        'imports inside functions without a `# lazy: <reason>` comment (move them to the top, '
        'or say why they stay):\n' + '\n'.join(missing)
    )


def test_function_level_imports_stay_few():
    too_many = over_the_cap(package_imports())
    assert too_many is None, too_many


def test_the_parser_loads_no_command_implementation():
    """`--help` builds every parser; a command's module and its feature load when it runs."""
    code = (
        'import sys\n'
        'from cloth_bench_ros.cli import build_parser, implementation\n'
        'build_parser()\n'
        "heavy = ('dask', 'distributed', 'optuna', 'matplotlib', 'scipy', 'rosbags', 'mcap')\n"
        "print(sorted(m for m in sys.modules if m.endswith('_command') or m in heavy))\n"
        "implementation('cloth_bench_ros.cli.studies_command:cmd_sweep')\n"
        "print(sorted(m for m in sys.modules if m.endswith('_command') or m in heavy))\n"
    )
    out = subprocess.run(
        [sys.executable, '-c', code], capture_output=True, text=True, check=True
    ).stdout.splitlines()
    assert out[0] == '[]'
    assert 'cloth_bench_ros.cli.studies_command' in out[1] and 'distributed' in out[1]


SAMPLE = """
import os


def outer():
    import json  # lazy: a reason

    def inner():
        from pathlib import (
            Path,
        )  # lazy: the comment on the statement's last line
        import re
        return Path, re
    return json, inner


class Holder:
    import sys  # a class body's import is not a function's

    def method(self):
        import csv; import math  # lazy: both on this line
"""


def test_the_checks_find_what_they_look_for():
    """Nested functions count once, the comment may end a statement, unmarked ones are named."""
    found = function_imports(SAMPLE, 'sample.py')
    assert [(i.line, i.lazy_reason) for i in found] == [
        (6, True), (9, True), (12, False), (21, True), (21, True)
    ]
    assert unexplained(found) == ['sample.py:12: import re']
    assert over_the_cap(found, cap=5) is None
    too_many = over_the_cap(package_imports({'core'}), cap=0)
    assert too_many is not None and 'core' in too_many and 'more than 0' in too_many
