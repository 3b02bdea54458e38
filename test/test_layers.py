"""
The package's layers import only downwards, without circles, and the report runs nothing.

Layers, top to bottom: config -> core -> engines -> data -> live -> runtime -> nodes -> studies ->
sweep -> identify -> rank -> hil -> report -> cli; a module imports only from its own layer or
those above it. config is the modules at the package's top level (errors, paths, safe_io,
validation, metric_choice, options, command_options): each is declared in TOP_LEVEL, and a new one
without a layer fails. Every import counts, also those inside functions and under TYPE_CHECKING.
"""

from __future__ import annotations

import ast
from pathlib import Path

import cloth_bench_ros
import pytest

PACKAGE = Path(cloth_bench_ros.__file__).parent
# config: the top-level modules (TOP_LEVEL). A feature package sits where its parts are used:
# live/ (the live view) below the nodes that stream and write it; sweep/, identify/ (which
# validates on sweep cells), rank/ (which identifies) and hil/ (which reads the settings sweep)
# above the shared study machinery in studies/.
LAYERS = (
    'config', 'core', 'engines', 'data', 'live', 'runtime', 'nodes', 'studies', 'sweep',
    'identify', 'rank', 'hil', 'report', 'cli',
)


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix('').parts
    return '.'.join(parts[:-1] if parts[-1] == '__init__' else parts)


def all_modules() -> dict[str, Path]:
    return {module_name(p): p for p in sorted(PACKAGE.rglob('*.py'))}


# The package's top-level modules and their layers (the package itself: its docstring only).
TOP_LEVEL = {
    'cloth_bench_ros': 'config',
    'cloth_bench_ros.errors': 'config',
    'cloth_bench_ros.paths': 'config',
    'cloth_bench_ros.safe_io': 'config',
    'cloth_bench_ros.validation': 'config',
    'cloth_bench_ros.metric_choice': 'config',
    'cloth_bench_ros.options': 'config',
    'cloth_bench_ros.command_options': 'config',
}


def layer(module: str) -> str:
    """Return a module's layer: its subpackage's, or a top-level module's declared one."""
    parts = module.split('.')
    if len(parts) > 1 and parts[1] in LAYERS:
        return parts[1]
    return TOP_LEVEL.get(module, 'undeclared')


def test_every_top_level_module_has_a_declared_layer(graph):
    assert [m for m in graph if layer(m) == 'undeclared'] == []


def imports_of(module: str, path: Path, modules: dict[str, Path]) -> dict[str, int]:
    """Return the package's modules that `module` imports, with their lines."""
    package = module if path.name == '__init__.py' else module.rpartition('.')[0]
    found: dict[str, int] = {}

    def add(name: str, line: int) -> None:
        while name and name not in modules:
            name = name.rpartition('.')[0]
        if name and name != module:
            found.setdefault(name, line)

    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split('.')[0] == 'cloth_bench_ros':
                    add(alias.name, node.lineno)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ''
            if node.level:
                anchor = package.split('.')[: len(package.split('.')) - (node.level - 1)]
                base = '.'.join(anchor + ([base] if base else []))
            if base.split('.')[0] != 'cloth_bench_ros':
                continue
            for alias in node.names:  # `from package import module` imports the module
                add(
                    f'{base}.{alias.name}' if f'{base}.{alias.name}' in modules else base,
                    node.lineno,
                )
    return found


@pytest.fixture(scope='module')
def graph() -> dict[str, dict[str, int]]:
    modules = all_modules()
    return {m: imports_of(m, p, modules) for m, p in modules.items()}


def test_the_package_has_every_layer(graph):
    assert {layer(m) for m in graph} == set(LAYERS)


def test_imports_only_go_downwards(graph):
    upward = [
        f'{m} (line {line}) imports {target}: {layer(m)} may not import {layer(target)}'
        for m, targets in sorted(graph.items())
        for target, line in sorted(targets.items())
        if layer(target) in LAYERS and LAYERS.index(layer(target)) > LAYERS.index(layer(m))
    ]
    assert not upward, '\n'.join(upward)


def test_the_report_runs_nothing(graph):
    """A report module imports no study's run_* function: it renders results others produced."""
    modules = all_modules()
    running = []
    for m in (m for m in graph if layer(m) == 'report'):
        for node in ast.walk(ast.parse(modules[m].read_text())):
            if isinstance(node, ast.ImportFrom) and (node.module or '').startswith(
                'cloth_bench_ros.studies'
            ):
                if any(a.name.startswith('run') for a in node.names):
                    running.append(
                        f'{m} (line {node.lineno}) imports {[a.name for a in node.names]} from'
                        f' {node.module}'
                    )
    assert not running, '\n'.join(running)


def test_the_feature_packages_have_their_place():
    """data/ may not import the live view, studies/ no feature, a feature none above it."""
    graph = {
        'cloth_bench_ros.data.bag_writer': {'cloth_bench_ros.live.view': 3},
        'cloth_bench_ros.studies.cells': {'cloth_bench_ros.sweep.study': 4},
        'cloth_bench_ros.sweep.study': {'cloth_bench_ros.hil.study': 5},
        'cloth_bench_ros.identify.output': {'cloth_bench_ros.rank.trials': 6},
        'cloth_bench_ros.rank.answer': {'cloth_bench_ros.report.rank': 7},
        'cloth_bench_ros.live.view': {'cloth_bench_ros.data.messages': 1},
        'cloth_bench_ros.rank.study': {'cloth_bench_ros.identify.study': 2},
    }
    with pytest.raises(AssertionError) as caught:
        test_imports_only_go_downwards(graph)
    for said in ('data may not import live', 'studies may not import sweep',
                 'sweep may not import hil', 'identify may not import rank',
                 'rank may not import report'):
        assert said in str(caught.value)
    assert 'cloth_bench_ros.live.view (line' not in str(caught.value)  # live may import data
    assert 'cloth_bench_ros.rank.study (line' not in str(caught.value)  # rank may identify


def circles(graph: dict[str, dict[str, int]]) -> list[list[str]]:
    """Return the strongly connected components of more than one module (Tarjan's algorithm)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, {}):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_no_circles(graph):
    found = circles(graph)
    assert not found, '\n'.join(' <-> '.join(c) for c in found)


def test_the_checks_find_what_they_look_for():
    """The checks themselves: an upward import, a circle and a report that runs are caught."""
    graph = {
        'cloth_bench_ros.core.a': {'cloth_bench_ros.report.b': 1},
        'cloth_bench_ros.report.b': {'cloth_bench_ros.core.a': 1},
        'cloth_bench_ros.cli': {},
    }
    assert circles(graph) == [['cloth_bench_ros.core.a', 'cloth_bench_ros.report.b']]
    assert layer('cloth_bench_ros.safe_io') == 'config' and layer('cloth_bench_ros.cli') == 'cli'
    assert layer('cloth_bench_ros.new_module') == 'undeclared'
    with pytest.raises(AssertionError, match='config may not import core'):
        test_imports_only_go_downwards({'cloth_bench_ros.options': {'cloth_bench_ros.core.a': 1},
                                        'cloth_bench_ros.core.a': {}})
    with pytest.raises(AssertionError, match='core may not import report'):
        test_imports_only_go_downwards(graph)
    with pytest.raises(AssertionError, match='<->'):
        test_no_circles(graph)
