"""
Cloth engines behind one interface, discovered through the `cloth_bench_ros.engines` entry points.

Another package adds an engine by declaring, in its own setup.py:
    entry_points={"cloth_bench_ros.engines": ["myengine = my_pkg.module:MyCloth"]}
where MyCloth subclasses `cloth_bench_ros.engines.base.ClothEngine`.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from importlib.metadata import entry_points
from typing import Any, Mapping

from cloth_bench_ros.core.cloth_mesh import Cloth
from cloth_bench_ros.core.scene import ClothGrid
from cloth_bench_ros.engines.base import ClothEngine, EngineError, params_for_grid

ENTRY_POINT_GROUP = 'cloth_bench_ros.engines'

# Engines of the paper that cannot be installed from PyPI or Debian: listed with the reason.
UNAVAILABLE = {
    'flex': (
        'NVIDIA Flex 1.2 (SoftGym) needs CUDA and a source build; no package on PyPI or Debian'
    ),
    'sofa': 'SOFA 23.06 has no package on PyPI or Debian (binary releases and conda only)',
}


# An engine's name as a table or figure says it (the cross-reference study names its entrants so).
ENGINE_LABEL = {
    'mujoco': 'MuJoCo',
    'bullet': 'Bullet',
    'flex': 'Flex',
    'sofa': 'SOFA',
    'newton': 'Newton',
}


def engine_label(name: str) -> str:
    """Return an engine's display name (its registered name if it has none)."""
    return ENGINE_LABEL.get(name, name)


# The extra of this package that installs an engine's dependencies, named when they are missing.
ENGINE_EXTRAS = {'newton': 'newton'}


@dataclass(frozen=True)
class EngineInfo:
    name: str
    available: bool
    version: str
    reason: str  # why it is unavailable, empty when available


@lru_cache(maxsize=1)  # read once per process: a sweep's worker builds an engine per cell
def _entry_points() -> dict:
    return {ep.name: ep for ep in entry_points(group=ENTRY_POINT_GROUP)}


def engine_class(name: str) -> type[ClothEngine]:
    """Return the engine class registered under `name`; EngineError if unknown or unavailable."""
    eps = _entry_points()
    if name in eps:
        try:
            return eps[name].load()
        except ImportError as exc:
            raise EngineError(f'engine {name} is not available: {_missing(name, exc)}') from None
    if name in UNAVAILABLE:
        raise EngineError(f'engine {name} is not available: {UNAVAILABLE[name]}')
    known = sorted(set(eps) | set(UNAVAILABLE))
    raise EngineError(f'unknown engine {name!r} (known: {", ".join(known)})')


def known_engines() -> list[EngineInfo]:
    """Every registered or known engine with its availability, version and reason."""
    infos = []
    for name, ep in sorted(_entry_points().items()):
        try:
            cls = ep.load()
            infos.append(EngineInfo(name, True, cls.version(), ''))
        except ImportError as exc:
            infos.append(EngineInfo(name, False, '', _missing(name, exc)))
    for name, reason in UNAVAILABLE.items():
        if name not in {i.name for i in infos}:
            infos.append(EngineInfo(name, False, '', reason))
    return infos


def _missing(name: str, exc: ImportError) -> str:
    """Return why engine `name` did not import, with the extra that installs what it lacks."""
    extra = ENGINE_EXTRAS.get(name)
    if extra is None:
        return f'import failed: {exc}'
    return f"{exc} (install it with: pip install 'cloth_bench_ros[{extra}]')"


def engine_device(name: str, params: Mapping[str, Any] | None = None) -> str:
    """Return the device engine `name` runs on with `params` (EngineError if it is absent)."""
    return engine_class(name).device_for(params or {})


def engine_model(name: str, params: Mapping[str, Any] | None = None) -> str:
    """Return the model engine `name` runs with `params` ('' for an engine without models)."""
    return str(engine_class(name).validate_params(dict(params or {})).get('model', ''))


def make_engine(
    name: str,
    rate_hz: float,
    params: dict | None = None,
    grid: Cloth | None = None,
    params_grid: ClothGrid | None = None,
) -> ClothEngine:
    """
    Instantiate engine `name` at `rate_hz` with validated parameters on `grid`.

    `params` are set for `params_grid` (default: the default mesh, as presets and identified
    values are) and scaled to `grid` by `params_for_grid`, so that a mesh changes only the
    resolution of the cloth.
    """
    cls = engine_class(name)
    return cls(rate_hz, params_for_grid(cls, params or {}, rate_hz, grid, params_grid), grid)
