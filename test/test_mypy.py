"""mypy over the package, with the configuration in setup.cfg."""

from pathlib import Path

from mypy import api
import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
@pytest.mark.linter
@pytest.mark.mypy
def test_mypy(monkeypatch, tmp_path):
    monkeypatch.chdir(ROOT)
    stdout, stderr, status = api.run(
        ['--config-file', 'setup.cfg', '--cache-dir', str(tmp_path), 'cloth_bench_ros']
    )
    assert status == 0, stdout + stderr
