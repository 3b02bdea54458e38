"""
One root for the user-facing errors, reported by the CLI in one line.

Every error class of the package (outside the rclpy-compatible runtime, whose classes mirror
rclpy's) derives from ClothBenchError.
"""

from __future__ import annotations

import ast
import errno
import importlib
from pathlib import Path

import cloth_bench_ros
from cloth_bench_ros.cli import main
from cloth_bench_ros.data import BagError
from cloth_bench_ros.errors import ClothBenchError, InputError, is_user_error, one_line, PathError
from cloth_bench_ros.safe_io import atomic_write_text
import pytest

PACKAGE = Path(cloth_bench_ros.__file__).parent
EXCEPTION_BASES = {'Exception', 'ValueError', 'RuntimeError', 'OSError', 'ClothBenchError'}
# Not errors: a study stopped by Ctrl-C, which the CLI reports with exit status 130; an engine's
# instability signal, which its step turns into a divergence.
NOT_ERRORS = {
    ('cloth_bench_ros.studies.errors', 'StudyInterrupted'),
    ('cloth_bench_ros.engines.base', 'Instability'),
}


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


def _run_args(tmp_path: Path) -> list[str]:
    from cloth_bench_ros.paths import bundled_bag

    bag = bundled_bag('towel', 'dynamic')
    out = tmp_path / 'run'
    return ['run', '--bag', str(bag), '--output', str(out), '--grid', '4x4', '--rate', '10']


def test_a_planted_value_error_in_the_scoring_path_is_an_internal_error(
    tmp_path, capsys, monkeypatch
):
    # A bug that raises a plain ValueError deep in the scoring: not the user's bad input (2), but
    # an internal error (1) that says so, and --verbose lets its traceback out.
    from cloth_bench_ros.core.metrics import RealCloud

    def planted(self, vertices):
        raise ValueError('planted bug in the scoring path')

    monkeypatch.setattr(RealCloud, 'nearest_l1', planted)
    assert main(_run_args(tmp_path)) == 1
    err = capsys.readouterr().err
    assert 'internal error' in err and 'planted bug' in err and 'cloth-bench: error:' not in err
    with pytest.raises(ValueError, match='planted bug'):
        main(['--verbose', *_run_args(tmp_path / 'verbose')])


def test_bad_input_is_still_status_2_and_a_full_disk_too(tmp_path, capsys):
    assert is_user_error(InputError('--rate: 0 is outside [1, 10000]'))
    assert is_user_error(OSError(errno.ENOSPC, 'No space left on device'))
    assert not is_user_error(ValueError('a bug')) and not is_user_error(OSError(errno.EBADF, 'x'))
    assert main(['run', '--bag', str(tmp_path / 'missing'), '--output', str(tmp_path / 'o')]) == 2
    assert capsys.readouterr().err.startswith('cloth-bench: error: ')


def test_one_line_is_the_one_message_builder():
    assert one_line(ValueError('a\n  b\tc ')) == 'a b c'
    assert one_line(OSError()) == 'OSError'
    assert one_line(KeyError('k'), with_type=True) == "KeyError: 'k'"


def test_an_unwritable_output_is_a_path_error(tmp_path):
    blocked = tmp_path / 'file'
    blocked.write_text('')
    with pytest.raises(PathError, match='cannot write'):
        atomic_write_text(blocked / 'x.json', '{}')
