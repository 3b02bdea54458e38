"""
A module has one job; about 450 lines is the guide, and a longer one is declared here.

A module is split where it has two jobs, not where it crosses a line count: one longer than
GUIDE_LINES is listed in LONG_MODULES with the one job that makes it long, so that a new long
module is a decision, not an accident. An entry whose module is back under the guide goes.
"""

from __future__ import annotations

from pathlib import Path

import cloth_bench_ros

PACKAGE = Path(cloth_bench_ros.__file__).parent
GUIDE_LINES = 450

# Module (relative to the package) -> the one job that makes it long.
LONG_MODULES = {
    'options.py': 'the declarations of the options every command and node shares: one table',
    'core/surface_distance.py': 'one algorithm: exact point-to-triangle distances and their grid',
    'data/replay.py': "the recorder's replay plan: every frame of a bag's topic in one account",
    'engines/newton_cloth.py': "one engine's adapter: Newton's two cloth models, grasp and device",
    'sweep/study.py': 'the sweep study: its cells, resume and scheduling into one results file',
}


def lines_of(module: Path) -> int:
    return len(module.read_text().splitlines())


def long_modules(package: Path = PACKAGE, guide: int = GUIDE_LINES) -> dict[str, int]:
    """Return the package's modules longer than `guide` lines, with their line counts."""
    return {
        str(m.relative_to(package)): n
        for m in sorted(package.rglob('*.py'))
        if (n := lines_of(m)) > guide
    }


def undeclared(found: dict[str, int], declared: dict[str, str]) -> list[str]:
    return [f'{m}: {n} lines' for m, n in found.items() if m not in declared]


def test_a_module_over_the_guide_is_declared():
    missing = undeclared(long_modules(), LONG_MODULES)
    assert not missing, (
        f'modules over {GUIDE_LINES} lines: split one with two jobs, or declare its one job in '
        'LONG_MODULES:\n' + '\n'.join(missing)
    )


def test_every_declared_module_is_still_long():
    found = long_modules()
    stale = sorted(m for m in LONG_MODULES if m not in found)
    assert not stale, f'not over {GUIDE_LINES} lines (or gone): drop from LONG_MODULES: {stale}'


def test_every_declaration_says_why_in_a_line():
    assert all(0 < len(why) <= 80 and '\n' not in why for why in LONG_MODULES.values())


def test_the_check_finds_a_long_module(tmp_path):
    (tmp_path / 'short.py').write_text('x = 1\n' * 3)
    (tmp_path / 'sub').mkdir()
    (tmp_path / 'sub' / 'long.py').write_text('x = 1\n' * 5)
    found = long_modules(tmp_path, guide=4)
    assert found == {'sub/long.py': 5}
    assert undeclared(found, {}) == ['sub/long.py: 5 lines']
    assert undeclared(found, {'sub/long.py': 'one job'}) == []
