"""
One root for the user-facing errors, reported by the CLI in one line.

Every error class of the package (outside the rclpy-compatible runtime, whose classes mirror
rclpy's) derives from ClothBenchError.
"""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import cloth_bench_ros
from cloth_bench_ros.cli import main
from cloth_bench_ros.data import BagError
from cloth_bench_ros.errors import ClothBenchError

PACKAGE = Path(cloth_bench_ros.__file__).parent
EXCEPTION_BASES = {'Exception', 'ValueError', 'RuntimeError', 'OSError', 'ClothBenchError'}
# Not an error: a study stopped by Ctrl-C, which the CLI reports with exit status 130.
NOT_ERRORS = {('cloth_bench_ros.studies.errors', 'StudyInterrupted')}


def error_classes() -> list[tuple[str, str]]:
    """Return (module, class) of every class outside runtime/ derived from an exception."""
    found = []
    for path in sorted(PACKAGE.rglob('*.py')):
        rel = path.relative_to(PACKAGE.parent).with_suffix('')
        if rel.parts[1:2] == ('runtime',):
            continue
        module = '.'.join(rel.parts[:-1] if rel.parts[-1] == '__init__' else rel.parts)
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ClassDef) and any(
                isinstance(b, ast.Name) and (b.id in EXCEPTION_BASES or b.id.endswith('Error'))
                for b in node.bases
            ):
                found.append((module, node.name))
    return found


def test_every_error_class_derives_from_the_root():
    classes = error_classes()
    assert ('cloth_bench_ros.data.errors', 'BagError') in classes and len(classes) >= 10
    loose = [
        f'{m}.{name}'
        for m, name in classes
        if (m, name) not in NOT_ERRORS
        and not issubclass(getattr(importlib.import_module(m), name), ClothBenchError)
    ]
    assert not loose, f'not derived from ClothBenchError: {loose}'


def test_a_root_error_that_is_no_value_error_is_one_line_and_status_2(tmp_path, capsys):
    assert not issubclass(BagError, ValueError)
    assert main(['bag', 'info', str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith('cloth-bench: error: ') and err.count('\n') == 1 and str(tmp_path) in err
