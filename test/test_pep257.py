"""The ament_python template's pep257 test: ament_pep257 with ament's default configuration."""

from pathlib import Path

from ament_pep257.main import main
import pytest

ROOT = Path(__file__).resolve().parents[1]
LINTED = ['cloth_bench_ros', 'test', 'benchmarks', 'launch']


@pytest.mark.slow
@pytest.mark.linter
@pytest.mark.pep257
def test_pep257(monkeypatch):
    monkeypatch.chdir(ROOT)
    rc = main(argv=LINTED)
    assert rc == 0, 'Found code style errors / warnings'
