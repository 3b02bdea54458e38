"""
Real ROS 2 (rclpy Jazzy over Fast DDS) runs the project's nodes.

The defects found against it stay fixed.

Each case runs real rclpy in its own loopback-only network namespace (test/real_ros.py) and is
compared with what the embedded runtime does for the same input.
"""

from __future__ import annotations

import json
from pathlib import Path
import random
import shlex
import signal
import subprocess
import time

from cloth_bench_ros.runtime.dds import loopback_environment
import pytest
from real_ros import in_namespace, require_real_ros, ROOT, ros_env, ROS_PYTHON, ros_script

pytestmark = pytest.mark.real_ros


@pytest.fixture(autouse=True)
def _real_ros():
    require_real_ros()


def test_rclpy_is_real_in_the_tier():
    out = subprocess.run(
        in_namespace(
            '-c', 'import rclpy, cloth_bench_ros.runtime as r; print(r.EMBEDDED, rclpy.__file__)'
        ),
        capture_output=True,
        text=True,
        env=ros_env(),
        timeout=120,
    )
    assert out.returncode == 0, out.stderr
    embedded, path = out.stdout.split()
    assert embedded == 'False' and 'site-packages' in path  # real rclpy, not the embedded runtime


def test_declared_options_under_real_rclpy_take_an_integer_and_carry_their_range():
    """`-p rate_hz:=1000` (an INTEGER under rcl) is 1000.0; the descriptor has the range."""
    script = (
        'import rclpy, cloth_bench_ros.runtime as r\n'
        "rclpy.init(args=['p', '--ros-args', '-p', 'rate_hz:=1000'])\n"
        "node = rclpy.create_node('probe')\n"
        "rate = r.declare_option(node, 'rate_hz')\n"
        "d = node.describe_parameter('rate_hz')\n"
        "g = r.declare_option(node, 'grid_nx')\n"
        "s = node.describe_parameter('grid_nx').integer_range[0]\n"
        'f = d.floating_point_range[0]\n'
        'print(rate, f.from_value, f.to_value, s.from_value, s.to_value, g)\n'
        'print(d.description)\n'
    )
    out = subprocess.run(
        in_namespace('-c', script), capture_output=True, text=True, env=ros_env(), timeout=120
    )
    assert out.returncode == 0, out.stderr
    numbers, description = out.stdout.splitlines()[:2]
    assert numbers.split() == ['1000.0', '1.0', '10000.0', '0', '201', '0']
    assert description == 'simulator rate; range [1, 10000] Hz; default 100'


@pytest.mark.parametrize(
    'ros_args, words',
    [
        (['-p', 'rate_hz:=fast'], 'parameter rate_hz'),
        # rclpy's own range check (options.py puts the range in the descriptor), named by node
        (['-p', 'rate_hz:=1000000000.0'], 'simulator: parameter rate_hz'),
        (['-p', 'grid_nx:=-3', '-p', 'grid_nz:=8'], 'simulator: parameter grid_nx'),
        (['--params-file', '/nonexistent/params.yaml'], 'params file'),
        (['--log-level', 'bogus'], 'log level'),
    ],
)
def test_bad_ros_arguments_are_one_line_and_exit_2_under_real_rclpy(ros_args, words):
    out = subprocess.run(
        in_namespace('-m', 'cloth_bench_ros.nodes.simulator', '--ros-args', *ros_args),
        capture_output=True,
        text=True,
        env=ros_env(),
        timeout=120,
    )
    assert out.returncode == 2, out.stderr
    errors = [line for line in out.stderr.splitlines() if line.startswith('error:')]
    assert len(errors) == 1 and words in errors[0] and 'Traceback' not in out.stderr


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM])
def test_sigint_and_sigterm_stop_a_real_rclpy_node_cleanly(sig):
    proc = subprocess.Popen(
        in_namespace(
            '-m',
            'cloth_bench_ros.nodes.simulator',
            '--ros-args',
            '-p',
            'grid_nx:=6',
            '-p',
            'grid_nz:=8',
        ),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=ros_env(),
    )
    deadline = time.monotonic() + 60
    lines = []
    while time.monotonic() < deadline:  # wait until the node is up (its "ready" log line)
        line = proc.stderr.readline()
        lines.append(line)
        if 'ready' in line or not line:
            break
    proc.send_signal(sig)  # unshare and sh exec the node: proc is the node's own process
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, ''.join(lines) + err
    assert 'Traceback' not in err and 'ExternalShutdownException' not in err


@pytest.mark.slow
def test_two_in_process_runs_at_once_do_not_hear_each_other(tmp_path):
    script = (
        ' & '.join(
            f'(timeout 300 {ROS_PYTHON} -m cloth_bench_ros.cli run --grid 6x8 --output'
            f' {tmp_path / name} > {tmp_path / name}.log 2>&1; echo $? > {tmp_path / name}.status)'
            for name in ('a', 'b')
        )
        + ' & wait'
    )
    subprocess.run(ros_script(script), env=ros_env(), timeout=600)
    embedded = subprocess.run(
        [
            *_embedded_python(),
            '-m',
            'cloth_bench_ros.cli',
            'run',
            '--grid',
            '6x8',
            '--output',
            str(tmp_path / 'embedded'),
        ],
        capture_output=True,
        text=True,
        timeout=300,
        env={**ros_env(), 'CLOTH_BENCH_EMBEDDED': '1'},
    )
    assert embedded.returncode == 0, embedded.stderr
    reference = json.loads((tmp_path / 'embedded' / 'summary.json').read_text())
    for name in ('a', 'b'):
        assert (tmp_path / f'{name}.status').read_text().strip() == '0', (
            tmp_path / f'{name}.log'
        ).read_text()
        summary = json.loads((tmp_path / name / 'summary.json').read_text())
        assert summary['real']['accounting']['adds_up']
        assert summary['engines']['mujoco']['CD_d'] == reference['engines']['mujoco']['CD_d']
        assert summary['engines']['mujoco']['HD_d'] == reference['engines']['mujoco']['HD_d']


def _embedded_python() -> list[str]:
    """Return the project's own venv's Python (the embedded runtime), for the same case."""
    import sys

    return [sys.executable]


@pytest.fixture(scope='module')
def embedded_reference(tmp_path_factory) -> dict:
    """Return the embedded in-process run's summary (6x8 MuJoCo towel fling, bundled bag)."""
    out_dir = tmp_path_factory.mktemp('embedded')
    embedded = subprocess.run(
        [*_embedded_python(), '-m', 'cloth_bench_ros.cli', 'run', '--grid', '6x8', '--output',
         str(out_dir)],
        capture_output=True,
        text=True,
        timeout=300,
        env={**ros_env(), 'CLOTH_BENCH_EMBEDDED': '1'},
    )
    assert embedded.returncode == 0, embedded.stderr
    return json.loads((out_dir / 'summary.json').read_text())


def _ros2_run_nodes(output: Path) -> dict[str, tuple[str, str]]:
    """Return the docs' node-by-node `ros2 run` lines: name -> (executable, its arguments)."""
    bag = ROOT / 'bags' / 'towel_dynamic'
    grid = '-p grid_nx:=6 -p grid_nz:=8'
    common = '--ros-args -r __ns:=/cloth_bench'
    return {
        'evaluator': ('evaluator', f'{common} -p use_sim_time:=true -p output_dir:={output}'),
        'simulator': ('simulator', f'{common} -p use_sim_time:=true -p engine:=mujoco {grid}'),
        'recorder': ('recorder', f'{common} -p use_sim_time:=true -p bag:={bag} {grid}'),
        'trajectory_publisher': ('trajectory_publisher', common),
    }


# A node graph runs the short bundled fling in 4-10 s; a node still running after this is a hang,
# said as one within a minute rather than after the suite's timeouts.
GRAPH_BUDGET_S = 60


def _node_graph(tmp_path, real: set[str], nodes: dict[str, tuple[str, str]]) -> None:
    """
    Run nodes one process each, as `ros2 run` or `ros2 launch` starts them, in one namespace.

    `nodes`: name -> (executable, its command-line arguments). The nodes named in `real` run on
    real rclpy over Fast DDS, the others on the embedded runtime over Cyclone DDS (loopback); the
    evaluator ends the run, the others are then stopped with SIGINT (as the launch file's
    OnProcessExit or a user would). Every process must exit 0 (one still running 30 s after SIGINT
    is killed); a simulator that ends before the evaluator fails the case at once, and a node
    still running after GRAPH_BUDGET_S fails it as a hang, with every node's log.
    """
    domain = random.randint(1, 101)
    embedded_env = ' '.join(
        f'{k}={shlex.quote(v)}' for k, v in loopback_environment(domain).items()
    )
    pythons = {
        name: f'{ROS_PYTHON}' if name in real else f'env {embedded_env} {_embedded_python()[0]}'
        for name in nodes
    }
    files = {name: {kind: tmp_path / f'{name}.{kind}' for kind in ('log', 'pid', 'status')}
             for name in nodes}
    launches = [
        # $! is this node's `timeout`; the node is its only child
        f'(timeout {GRAPH_BUDGET_S} {pythons[name]} -m cloth_bench_ros.nodes.{executable} {args}'
        f' > {files[name]["log"]} 2>&1 & echo $! > {files[name]["pid"]}; wait $!;'
        f' echo $? > {files[name]["status"]}) &'
        for name, (executable, args) in nodes.items()
    ]
    # The simulators serve until stopped: one that ends before the evaluator was stopped from
    # outside, and the evaluator would wait for its frames until `timeout`.
    watched = ['evaluator', *(name for name, (e, _) in nodes.items() if e == 'simulator')]
    ended = ' || '.join(f'[ -f {files[name]["status"]} ]' for name in watched)
    running = ' || '.join(f'[ ! -f {files[name]["status"]} ]' for name in nodes)

    def signal_all(sig: str) -> str:
        # only this graph's nodes: a pattern (pkill -f) would stop another graph's on the machine
        return ' '.join(f'pkill -{sig} -P $(cat {files[name]["pid"]});' for name in nodes)

    script = (
        ' '.join(launches)
        + f' until {ended}; do sleep 0.2; done;'
        + ' { ' + ' '.join(f'[ -f {files[name]["status"]} ] && echo {name};' for name in watched)
        + f' true; }} > {tmp_path / "ended_first"}; {signal_all("INT")}'
        + f' i=0; while [ $i -lt 150 ] && {{ {running}; }}; do sleep 0.2; i=$((i + 1)); done;'
        + f' {signal_all("KILL")} wait'
    )
    env = ros_env(ROS_DOMAIN_ID=str(domain))
    if len(real) < len(nodes):  # Fast DDS meets Cyclone's unicast discovery on loopback
        env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    subprocess.run(ros_script(script), env=env, timeout=600)
    statuses = {name: files[name]['status'].read_text().strip() for name in nodes
                if files[name]['status'].exists()}
    hung = [name for name, status in statuses.items() if status == '124']  # `timeout` ended it
    assert not hung, (
        f'the graph hung: {", ".join(hung)} still running after {GRAPH_BUDGET_S} s (a run takes'
        ' 4-10 s): ' + '\n'.join(f'{name}: ' + files[name]['log'].read_text() for name in nodes)
    )
    early = [n for n in (tmp_path / 'ended_first').read_text().split() if n != 'evaluator']
    assert not early, f'{", ".join(early)} ended before the evaluator: ' + '\n'.join(
        files[name]['log'].read_text() for name in early
    )
    for name in nodes:  # 137: still running 30 s after SIGINT, killed
        assert files[name]['status'].read_text().strip() == '0', files[name]['log'].read_text()


def _assert_same_metrics(summary: dict, reference: dict) -> None:
    assert summary['real']['accounting']['adds_up']
    assert summary['real']['accounting']['scored'] == 132
    for key in ('CD_d', 'HD_d', 'L_s', 'frames_in_window'):
        assert summary['engines']['mujoco'][key] == reference['engines']['mujoco'][key], key


@pytest.mark.slow
def test_the_nodes_as_separate_real_rclpy_processes_give_the_embedded_metrics(
    tmp_path, embedded_reference
):
    """
    Run the docs' node-by-node `ros2 run` commands on real rclpy over Fast DDS.

    As the installed console scripts run them, one process per node, in any start order: the
    embedded in-process run's numbers.
    """
    nodes = _ros2_run_nodes(tmp_path / 'ros')
    _node_graph(tmp_path, set(nodes), nodes)
    _assert_same_metrics(_summary(tmp_path / 'ros'), embedded_reference)


@pytest.mark.slow
@pytest.mark.parametrize('real', [{'evaluator'}, {'simulator'}, {'trajectory_publisher'}])
def test_mixed_graphs_of_real_and_embedded_nodes_give_the_embedded_metrics(
    tmp_path, embedded_reference, real
):
    """One node on real rclpy (Fast DDS), three embedded (Cyclone DDS): the same numbers."""
    _node_graph(tmp_path, real, _ros2_run_nodes(tmp_path / 'ros'))
    _assert_same_metrics(_summary(tmp_path / 'ros'), embedded_reference)


@pytest.mark.slow
def test_the_launch_files_command_lines_give_the_same_metrics_on_both_runtimes(
    monkeypatch, tmp_path
):
    """
    The launch file's nodes, with the command lines launch_ros builds, on real rclpy and embedded.

    The launch file is loaded against the stand-in of the launch API (test_launch_config.py); its
    command lines (remaps, the config file, the launch arguments as a params file) run once with
    every node on real rclpy over Fast DDS and once on the embedded runtime over Cyclone DDS.
    """
    from test_launch_config import _command_line, _launched_nodes

    summaries = []
    for runtime in ('real', 'embedded'):
        out = tmp_path / runtime
        out.mkdir()
        nodes = {}
        for node in _launched_nodes(monkeypatch, {'output_dir': str(out / 'results')}):
            executable, *args = _command_line(node, out)
            nodes[node.kwargs['name']] = (executable, shlex.join(args))
        assert set(nodes) >= {'trajectory_publisher', 'recorder', 'evaluator'}
        _node_graph(out, set(nodes) if runtime == 'real' else set(), nodes)
        summaries.append(_summary(out / 'results'))
    real, embedded = summaries
    assert real['real']['accounting']['adds_up'], real['real']['accounting']
    assert set(real['engines']) == set(embedded['engines'])
    for engine in real['engines']:
        for key in ('CD_d', 'HD_d', 'L_s', 'frames_in_window'):
            assert real['engines'][engine][key] == embedded['engines'][engine][key], key


def _summary(output: Path) -> dict:
    return json.loads((output / 'summary.json').read_text())


_EMBEDDED_TALKER = """
import time
from cloth_bench_ros.runtime import embedded as rclpy
rclpy.init(args=[], transport='dds')
node = rclpy.create_node('talker', namespace='cloth_bench')
node.declare_parameter('count', 0)
for k in range(1, 150):
    node.get_logger().info(f'hello {k}')
    node.set_parameters([rclpy.Parameter('count', value=k)])
    time.sleep(0.2)
"""
_REAL_LISTENER = """
import json, time, rclpy
from rcl_interfaces.msg import Log, ParameterEvent
rclpy.init()
node = rclpy.create_node('listener')
logs, events = [], []
node.create_subscription(Log, '/rosout', logs.append, 100)
node.create_subscription(ParameterEvent, '/parameter_events', events.append, 100)
end = time.monotonic() + 25
mine, changes = [], []
while time.monotonic() < end and (len(mine) < 3 or len(changes) < 3):
    rclpy.spin_once(node, timeout_sec=0.1)
    mine = [m for m in logs if m.name == 'cloth_bench.talker']
    changes = [p for m in events if m.node == '/cloth_bench/talker' for p in m.changed_parameters]
services = node.get_service_names_and_types_by_node('talker', '/cloth_bench')
# A Fast DDS client of a Cyclone service: rmw_fastrtps and rmw_cyclonedds carry the request id
# differently (inline QoS / a payload header), so no answer is expected; the talker must live on.
from rcl_interfaces.srv import ListParameters
client = node.create_client(ListParameters, '/cloth_bench/talker/list_parameters')
future = client.call_async(ListParameters.Request())
rclpy.spin_until_future_complete(node, future, timeout_sec=2.0)
logs_before = len([m for m in logs if m.name == 'cloth_bench.talker'])
end = time.monotonic() + 3
while time.monotonic() < end:
    rclpy.spin_once(node, timeout_sec=0.1)
print(json.dumps({
    'logs': [[m.level, m.msg] for m in mine[:3]],
    'changed': [[p.name, p.value.type] for p in changes[:3]],
    'nodes': sorted(node.get_node_names_and_namespaces()),
    'services': sorted([name, types] for name, types in services),
    'answered': future.done(),
    'talker logs on': len([m for m in logs if m.name == 'cloth_bench.talker']) > logs_before,
}))
"""


@pytest.mark.slow
def test_a_real_rclpy_node_reads_the_embedded_nodes_rosout_and_parameter_events(tmp_path):
    """An embedded node on Cyclone DDS, a real rclpy node on Fast DDS: logs, events, names."""
    domain = random.randint(1, 101)
    loopback = ' '.join(f'{k}={shlex.quote(v)}' for k, v in loopback_environment(domain).items())
    (tmp_path / 'talker.py').write_text(_EMBEDDED_TALKER)
    (tmp_path / 'listener.py').write_text(_REAL_LISTENER)
    script = (
        f'(env {loopback} CLOTH_BENCH_EMBEDDED=1 timeout 60 {_embedded_python()[0]}'
        f' {tmp_path / "talker.py"} > {tmp_path / "talker.log"} 2>&1 &) ;'
        f' ROS_DOMAIN_ID={domain} ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST timeout 60'
        f' {ROS_PYTHON} {tmp_path / "listener.py"};'
        f" pkill -f '{tmp_path / 'talker.py'}'"
    )
    out = subprocess.run(
        ros_script(script), capture_output=True, text=True, env=ros_env(), timeout=120
    )
    heard = json.loads(out.stdout.strip().splitlines()[-1])
    assert [level for level, _ in heard['logs']] == [20, 20, 20], out.stderr
    assert all(msg.startswith('hello ') for _, msg in heard['logs'])
    assert heard['changed'] == [['count', 2]] * 3  # INTEGER
    assert ['talker', '/cloth_bench'] in heard['nodes']
    # the parameter services, as `ros2 service list -t` would show them
    expected = {
        f'/cloth_bench/talker/{name}': [f'rcl_interfaces/srv/{kind}']
        for name, kind in (
            ('describe_parameters', 'DescribeParameters'),
            ('get_parameter_types', 'GetParameterTypes'),
            ('get_parameters', 'GetParameters'),
            ('list_parameters', 'ListParameters'),
            ('set_parameters', 'SetParameters'),
            ('set_parameters_atomically', 'SetParametersAtomically'),
        )
    }
    assert dict(heard['services']) == expected
    print(f"a real Fast DDS client's call answered: {heard['answered']}")
    assert heard['talker logs on'], 'the embedded node stopped after a Fast DDS request'


def test_the_service_types_hash_as_the_installed_rcl_interfaces_says():
    """The RIHS01 hashes the service endpoints announce equal those of the installed .json."""
    from cloth_bench_ros.data.messages import SERVICE_DEFINITIONS, type_hash

    share = ROS_PYTHON.parent.parent / 'share' / 'rcl_interfaces' / 'srv'
    compared = 0
    for srv in SERVICE_DEFINITIONS:
        name = srv.rsplit('/', 1)[1]
        hashes = json.loads((share / f'{name}.json').read_text())['type_hashes']
        installed = {h['type_name']: h['hash_string'] for h in hashes}
        for part in ('_Request', '_Response'):
            assert type_hash(srv + part) == installed[srv + part]
            compared += 1
    assert compared == 12


_INTROSPECTION = """
import json, sys, time
from cloth_bench_ros.runtime import (
    DurabilityPolicy, EMBEDDED, PoseArray, QoSProfile, rclpy, ReliabilityPolicy,
)
if EMBEDDED:
    rclpy.init(args=[], transport='dds')
else:
    rclpy.init(args=[])
mine, theirs, theirs_node = sys.argv[1:4]
node = rclpy.create_node(mine, namespace='probe')
qos = QoSProfile(
    depth=7,
    reliability=ReliabilityPolicy.BEST_EFFORT if EMBEDDED else ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE if EMBEDDED else DurabilityPolicy.TRANSIENT_LOCAL,
)
node.create_publisher(PoseArray, f'/from_{mine}', qos)
seen, end = [], time.monotonic() + 30
while time.monotonic() < end and not seen:
    rclpy.spin_once(node, timeout_sec=0.1)
    seen = [i for i in node.get_publishers_info_by_topic(f'/from_{theirs}')
            if i.node_name == theirs_node]
names = node.get_node_names_and_namespaces()
end = time.monotonic() + 3  # stay for the other side
while time.monotonic() < end:
    rclpy.spin_once(node, timeout_sec=0.1)
print(json.dumps([[i.node_name, i.node_namespace, i.topic_type, int(i.qos_profile.reliability),
                   int(i.qos_profile.durability)] for i in seen]
                 + [sorted([list(n) for n in names])]))
"""


@pytest.mark.slow
def test_graph_introspection_both_ways_between_real_and_embedded_nodes(tmp_path):
    """Each side names the other's node, its topic's type and its QoS (Fast DDS <-> Cyclone)."""
    domain = random.randint(1, 101)
    loopback = ' '.join(f'{k}={shlex.quote(v)}' for k, v in loopback_environment(domain).items())
    script_file = tmp_path / 'introspect.py'
    script_file.write_text(_INTROSPECTION)
    script = (
        f'(env {loopback} PYTHONPATH={ROOT} timeout 60 {_embedded_python()[0]} {script_file}'
        f' embedded real real > {tmp_path / "embedded.json"} 2> {tmp_path / "embedded.log"} &) ;'
        f' ROS_DOMAIN_ID={domain} ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST timeout 60'
        f' {ROS_PYTHON} {script_file} real embedded embedded > {tmp_path / "real.json"};'
        ' sleep 4'
    )
    subprocess.run(ros_script(script), env=ros_env(), timeout=120)
    real_saw = json.loads((tmp_path / 'real.json').read_text())
    embedded_saw = json.loads((tmp_path / 'embedded.json').read_text() or 'null')
    assert embedded_saw, (tmp_path / 'embedded.log').read_text()
    # reliability 1 reliable, 2 best effort; durability 1 transient local, 2 volatile
    assert real_saw[0] == ['embedded', '/probe', 'geometry_msgs/msg/PoseArray', 2, 2]
    assert embedded_saw[0] == ['real', '/probe', 'geometry_msgs/msg/PoseArray', 1, 1]
    assert ['embedded', '/probe'] in real_saw[-1] and ['real', '/probe'] in embedded_saw[-1]
