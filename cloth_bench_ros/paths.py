"""Where the package's config/ and bags/ are: the source tree, or share/ when installed."""

from __future__ import annotations

from pathlib import Path
import sys

PACKAGE = 'cloth_bench_ros'


def share_dir(name: str) -> Path:
    """<repo>/<name> in a source checkout, else <prefix>/share/cloth_bench_ros/<name>."""
    here = Path(__file__).resolve()
    source = here.parent.parent / name
    if (here.parent.parent / 'package.xml').is_file() and source.is_dir():
        return source
    # Installed: <prefix>/lib/pythonX.Y/site-packages/cloth_bench_ros/paths.py (colcon or pip).
    prefixes = [Path(sys.prefix)]
    if len(here.parents) > 4:  # a package at a shallower path is not such an install
        prefixes.insert(0, here.parents[4])
    for prefix in prefixes:
        candidate = prefix / 'share' / PACKAGE / name
        if candidate.is_dir():
            return candidate
    return source


def bundled_bag(cloth: str, primitive: str) -> Path:
    """Return the bag shipped in bags/ for a cloth and primitive."""
    return share_dir('bags') / f'{cloth}_{primitive}'
