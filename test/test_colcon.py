"""`colcon build` makes the install layout `ros2 run` and `ros2 launch` use, and it runs."""

import ast
import os
from pathlib import Path
import shutil
import subprocess
import sys

import pytest

REPO = Path(__file__).resolve().parent.parent
NODES = ('trajectory_publisher', 'simulator', 'recorder', 'evaluator')
COLCON = shutil.which('colcon') or str(Path(sys.executable).parent / 'colcon')


@pytest.fixture(scope='module')
def install(tmp_path_factory) -> Path:
    if not os.path.exists(COLCON):
        pytest.fail('colcon is not installed (pip install colcon-common-extensions)')
    ws = tmp_path_factory.mktemp('ws')
    pkg = ws / 'src' / 'cloth_bench_ros'
    files = subprocess.run(
        ['git', 'ls-files', '-co', '--exclude-standard'],
        cwd=REPO,
        capture_output=True,
        text=True,
        check=True,
    ).stdout.split()
    for rel in files:
        if rel.startswith(('test/', 'benchmarks/', '.ci/')) or not (REPO / rel).is_file():
            continue
        (pkg / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(REPO / rel, pkg / rel)
    env = {**os.environ, 'PATH': f'{Path(sys.executable).parent}:{os.environ["PATH"]}'}
    result = subprocess.run(
        [COLCON, 'build', '--packages-select', 'cloth_bench_ros'],
        cwd=ws,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    return ws / 'install'


def test_layout_for_ros2_run_and_launch(install):
    prefix = install / 'cloth_bench_ros'
    for node in NODES:
        script = prefix / 'lib' / 'cloth_bench_ros' / node
        assert script.is_file() and os.access(script, os.X_OK), script
    assert (
        prefix / 'share' / 'ament_index' / 'resource_index' / 'packages' / 'cloth_bench_ros'
    ).is_file()
    share = prefix / 'share' / 'cloth_bench_ros'
    assert (share / 'package.xml').is_file()
    assert (share / 'launch' / 'benchmark.launch.py').is_file()
    assert (share / 'config' / 'benchmark.yaml').is_file()
    assert any((share / 'config' / 'presets').glob('*.yaml'))
    for name in ('identified', 'identified-newton-vbd'):  # the named preset sets (--presets NAME)
        assert sorted(p.name for p in (share / 'config' / 'presets' / name).glob('*.yaml')) == [
            'bullet.yaml',
            'mujoco.yaml',
            'newton.yaml',
        ]


def _installed_env(install: Path) -> dict:
    site = next((install / 'cloth_bench_ros' / 'lib').glob('python3*/site-packages'))
    return {**os.environ, 'PYTHONPATH': str(site), 'CLOTH_BENCH_EMBEDDED': '1'}


def test_installed_node_reports_bad_parameters_in_one_line(install, tmp_path):
    recorder = install / 'cloth_bench_ros' / 'lib' / 'cloth_bench_ros' / 'recorder'
    result = subprocess.run(
        [str(recorder), '--ros-args', '-p', f'bag:={tmp_path / "missing"}'],
        cwd=tmp_path,
        env=_installed_env(install),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 2
    assert 'missing' in result.stderr and 'Traceback' not in result.stderr


@pytest.mark.slow
def test_the_installed_cli_runs_the_main_job_and_scores_a_camera_recording(install, tmp_path):
    from test_install import camera_run, FAST, scored

    cli = install / 'cloth_bench_ros' / 'lib' / 'cloth_bench_ros' / 'cloth-bench'
    for name, args in (('bundled', ['run', *FAST]), ('camera', camera_run(tmp_path))):
        out = tmp_path / name
        run = subprocess.run(
            [str(cli), *args, '--output', str(out)],
            cwd=tmp_path,
            env=_installed_env(install),
            capture_output=True,
            text=True,
            timeout=900,
        )
        summary = scored(run, out, 'mujoco')
        if name == 'camera':  # cleaned by default: no project metadata
            assert summary['real']['cleaning']['table_plane'] > 0


def test_installed_package_reads_its_installed_config(install, tmp_path):
    code = (
        "import cloth_bench_ros.paths as p; print(p.share_dir('config')); from"
        " cloth_bench_ros.engines.presets import load_preset; print(load_preset('mujoco', 'towel',"
        " 'dynamic'))"
    )
    result = subprocess.run(
        [sys.executable, '-c', code],
        cwd=tmp_path,
        env=_installed_env(install),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr
    assert str(install) in result.stdout.splitlines()[0]


def test_package_xml_declares_format_3_ament_python_and_the_message_packages():
    import xml.etree.ElementTree as ET

    root = ET.parse(REPO / 'package.xml').getroot()
    assert root.get('format') == '3' and root.findtext('name') == 'cloth_bench_ros'
    assert root.find('export/build_type').text == 'ament_python'
    deps = {e.text for e in root.findall('exec_depend')}
    for dep in (
        'rclpy',
        'sensor_msgs',
        'ament_index_python',
        'geometry_msgs',
        'std_msgs',
        'diagnostic_msgs',
        'rosgraph_msgs',
        'python3-numpy',
        'python3-scipy',
        'python3-yaml',
    ):
        assert dep in deps, dep


def test_launch_file_compiles_and_declares_its_arguments():
    source = (REPO / 'launch' / 'benchmark.launch.py').read_text()
    compile(source, 'benchmark.launch.py', 'exec')
    declared = {
        key.value
        for node in ast.walk(ast.parse(source))
        if isinstance(node, ast.Assign) and getattr(node.targets[0], 'id', '') == 'defaults'
        for key in node.value.keys
    }
    for arg in ('engines', 'rate_hz', 'primitive', 'cloth', 'bag', 'seed', 'pacing', 'output_dir'):
        assert arg in declared, arg
