"""The ament_python template's flake8 test: ament_flake8 with ament's default configuration."""

from pathlib import Path

from ament_flake8.main import main_with_errors
import pytest

ROOT = Path(__file__).resolve().parents[1]
# The template lints '.'; the quickstart's virtual environments live in the repository, so the
# package's own paths are named instead.
LINTED = ['cloth_bench_ros', 'test', 'benchmarks', 'launch', 'setup.py']


@pytest.mark.slow
@pytest.mark.flake8
@pytest.mark.linter
def test_flake8(monkeypatch):
    monkeypatch.chdir(ROOT)
    rc, errors = main_with_errors(argv=LINTED)
    assert rc == 0, 'Found %d code style errors / warnings:\n' % len(errors) + '\n'.join(errors)
