"""
config/*.yaml follow rcl's rules and every launch argument reaches its node.

launch and launch_ros are not installable here (launch_ros is not on PyPI; PyPI's `launch` is a
2017 pre-release), so launch/benchmark.launch.py is loaded against a small stand-in of the launch
API, and each Node's command line is built as ros2/launch_ros @ f9ab937 builds it
(launch_ros/actions/node.py: `-r __node:=`, `-r __ns:=`, then each parameter file as
`--params-file`, each dict written to a file keyed by the node's full name when name and
namespace are given, else `/**`; utilities/evaluate_parameters.py: string values re-read as
YAML). The nodes are then created in the embedded runtime from exactly that command line.
"""

import importlib.util
from pathlib import Path
import sys
import types

from cloth_bench_ros.runtime import embedded as rclpy
from cloth_bench_ros.runtime.params_file import load_params_file, PARAMS_KEY
import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]


def _yaml_files():
    return sorted((ROOT / 'config').rglob('*.yaml'))


def _holds_ros_parameters(node) -> bool:
    if isinstance(node, dict):
        return PARAMS_KEY in node or any(_holds_ros_parameters(v) for v in node.values())
    return False


@pytest.mark.parametrize('path', _yaml_files(), ids=lambda p: str(p.relative_to(ROOT)))
def test_every_parameter_file_under_config_follows_rcl(path):
    """As rcl_yaml_param_parser's parse.c: node keys, values and structure."""
    doc = yaml.safe_load(path.read_text())
    if not _holds_ros_parameters(doc):
        assert PARAMS_KEY not in path.read_text(), f'{path} mentions {PARAMS_KEY} but holds none'
        return  # an engine preset or the synth model: not a ROS parameter file
    overrides = load_params_file(path)
    assert overrides.entries, f'{path}: no node keys'


# --- a stand-in of the launch API, enough for launch/benchmark.launch.py ---------------------


class _Action:
    def __init__(self, *args, **kwargs):
        self.args, self.kwargs = args, kwargs


class _LaunchConfiguration:
    def __init__(self, name):
        self.name = name

    def perform(self, context):
        return context.launch_configurations[self.name]


def _launch_modules(share: Path) -> dict:
    def module(name, **attrs):
        mod = types.ModuleType(name)
        mod.__dict__.update(attrs)
        return mod

    classes = {
        n: type(n, (_Action,), {})
        for n in (
            'LaunchDescription',
            'DeclareLaunchArgument',
            'EmitEvent',
            'OpaqueFunction',
            'RegisterEventHandler',
            'OnProcessExit',
            'Shutdown',
            'Node',
        )
    }
    return {
        'ament_index_python': module('ament_index_python'),
        'ament_index_python.packages': module(
            'ament_index_python.packages', get_package_share_directory=lambda pkg: str(share)
        ),
        'launch': module('launch', LaunchDescription=classes['LaunchDescription']),
        'launch.actions': module(
            'launch.actions',
            **{
                n: classes[n]
                for n in (
                    'DeclareLaunchArgument',
                    'EmitEvent',
                    'OpaqueFunction',
                    'RegisterEventHandler',
                )
            },
        ),
        'launch.event_handlers': module(
            'launch.event_handlers', OnProcessExit=classes['OnProcessExit']
        ),
        'launch.events': module('launch.events', Shutdown=classes['Shutdown']),
        'launch.substitutions': module(
            'launch.substitutions', LaunchConfiguration=_LaunchConfiguration
        ),
        'launch_ros': module('launch_ros'),
        'launch_ros.actions': module('launch_ros.actions', Node=classes['Node']),
    }


def _launched_nodes(monkeypatch, launch_args: dict) -> list:
    for name, mod in _launch_modules(ROOT).items():
        monkeypatch.setitem(sys.modules, name, mod)
    spec = importlib.util.spec_from_file_location(
        'benchmark_launch', ROOT / 'launch' / 'benchmark.launch.py'
    )
    launch_file = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(launch_file)
    description = launch_file.generate_launch_description()
    entities = description.args[0]
    defaults = {
        e.args[0]: e.kwargs['default_value']
        for e in entities
        if type(e).__name__ == 'DeclareLaunchArgument'
    }
    (opaque,) = [e for e in entities if type(e).__name__ == 'OpaqueFunction']
    context = types.SimpleNamespace(launch_configurations={**defaults, **launch_args})
    return [e for e in opaque.kwargs['function'](context) if type(e).__name__ == 'Node']


def _evaluated(value):
    """As launch_ros evaluate_parameter_dict: strings read as YAML, lists become tuples."""
    if isinstance(value, str):
        return yaml.safe_load(value or "''")
    if isinstance(value, (list, tuple)):
        return tuple(_evaluated(v) for v in value)
    return value


def _command_line(node, tmp_path) -> list[str]:
    """Return the --ros-args launch_ros's Node gives the executable (launch_ros node.py)."""
    kw = node.kwargs
    assert kw.get('output') == 'screen', f'{kw["executable"]}: node output not shown'
    name, namespace = (
        kw.get('name'),
        '/' + kw['namespace'].lstrip('/') if kw.get('namespace') else None,
    )
    args = ['--ros-args']
    if name:
        args += ['-r', f'__node:={name}']
    if namespace:
        args += ['-r', f'__ns:={namespace}']
    for i, params in enumerate(kw.get('parameters', [])):
        if isinstance(params, dict):
            key = f'{namespace.rstrip("/")}/{name}' if name and namespace else '/**'
            path = tmp_path / f'launch_params_{kw["executable"]}_{name}_{i}'
            path.write_text(
                yaml.dump(
                    {key: {PARAMS_KEY: {k: _evaluated(v) for k, v in params.items()}}},
                    default_flow_style=False,
                )
            )
            params = str(path)
        args += ['--params-file', str(params)]
    return [kw['executable'], *args]


def _start(node, tmp_path):
    from cloth_bench_ros.nodes.evaluator import Evaluator
    from cloth_bench_ros.nodes.recorder import Recorder
    from cloth_bench_ros.nodes.simulator import Simulator
    from cloth_bench_ros.nodes.trajectory_publisher import TrajectoryPublisher

    classes = {
        'trajectory_publisher': TrajectoryPublisher,
        'recorder': Recorder,
        'evaluator': Evaluator,
        'simulator': Simulator,
    }
    context = rclpy.Context()
    rclpy.init(args=_command_line(node, tmp_path), context=context)
    return classes[node.kwargs['executable']](context=context), context


def test_every_launch_argument_reaches_its_node(monkeypatch, tmp_path):
    """The launch arguments beat config/benchmark.yaml under rclpy's order (node.cpp)."""
    bag = ROOT / 'bags' / 'towel_dynamic'
    args = {
        'engines': 'mujoco,bullet',
        'rate_hz': '1000',
        'pacing': 'realtime',
        'seed': '7',
        'output_dir': str(tmp_path / 'out'),
        'bag': str(bag),
        'cloth': 'towel',
        'primitive': 'dynamic',
        'cloth_size': '0.4,0.6',
        'cloth_mass': '0.2',
    }
    started = {}
    try:
        for node in _launched_nodes(monkeypatch, args):
            instance, context = _start(node, tmp_path)
            started[instance.get_name()] = (instance, context)
        tp = started['trajectory_publisher'][0]
        assert (tp.pacing, tp.engines) == ('realtime', ['mujoco', 'bullet'])
        assert tp.wait_for_recorder and tp.wait_for_evaluator
        assert tp.targets.rate_hz == 1000.0 and not tp.get_parameter('use_sim_time').value
        recorder = started['recorder'][0]
        assert Path(recorder.bag.path) == bag and recorder.get_parameter('use_sim_time').value
        # its frames end at the run's last target, not at the params file's rate's
        assert recorder.get_parameter('rate_hz').value == 1000.0
        assert recorder.get_parameter('primitive').value == 'dynamic'
        ev = started['evaluator'][0]
        assert (ev.output_dir, ev.realtime, ev.run_info['seed'], ev.engines) == (
            str(tmp_path / 'out'),
            True,
            7,
            ['mujoco', 'bullet'],
        )
        for engine in ('mujoco', 'bullet'):
            sim = started[f'simulator_{engine}'][0]
            assert (sim.engine_name, sim.seed, sim.get_namespace()) == (engine, 7, '/cloth_bench')
            assert sim.engine.dt == pytest.approx(1e-3)
        assert tp.get_parameter('cloth_size').value == '0.4,0.6'
        for name in ('recorder', 'evaluator', 'simulator_mujoco', 'simulator_bullet'):
            instance = started[name][0]
            sized = [instance.get_parameter(p).value for p in ('cloth_size', 'cloth_mass')]
            assert sized == ['0.4,0.6', 0.2], name
    finally:
        for instance, context in started.values():
            getattr(instance, 'close', lambda: None)()
            context.shutdown()


def test_the_default_launch_replays_the_bundled_bag_of_the_task(monkeypatch, tmp_path):
    nodes = {
        n.kwargs['name']: n
        for n in _launched_nodes(monkeypatch, {'primitive': 'quasi_static', 'cloth': 'linen'})
    }
    recorder, context = _start(nodes['recorder'], tmp_path)
    try:
        assert Path(recorder.bag.path) == ROOT / 'bags' / 'linen_quasi_static'
    finally:
        context.shutdown()


def test_the_device_argument_reaches_newtons_simulator_and_the_evaluator_names_each(
    monkeypatch, tmp_path
):
    """device:= is Newton's (as --device); the evaluator records each engine's, `auto` resolved."""
    import warp as wp

    auto = 'cuda:0' if wp.get_cuda_device_count() else 'cpu'  # what Warp finds here
    for device, newton in (('', auto), ('cpu', 'cpu')):
        nodes = {n.kwargs['name']: n for n in _launched_nodes(
            monkeypatch, {'engines': 'newton,mujoco', 'device': device})}
        started = {}
        try:
            for name in ('evaluator', 'simulator_newton'):
                started[name] = _start(nodes[name], tmp_path)
            assert started['evaluator'][0].run_info['devices'] == {
                'newton': newton, 'mujoco': 'cpu'}
            assert started['simulator_newton'][0].engine.device == newton
        finally:
            for instance, context in started.values():
                getattr(instance, 'close', lambda: None)()
                context.shutdown()
    with pytest.raises(ValueError, match='device:=cpu is the device of engine newton, which is '
                       'not among engines:=mujoco'):
        _launched_nodes(monkeypatch, {'engines': 'mujoco', 'device': 'cpu'})


def test_ros2_run_with_the_params_file_lets_the_command_line_win(tmp_path):
    """Check that `-p bag:=...` after a params file lands in the file's `/**` entry."""
    from cloth_bench_ros.nodes.recorder import Recorder
    from cloth_bench_ros.nodes.trajectory_publisher import TrajectoryPublisher

    bag = ROOT / 'bags' / 'linen_dynamic'
    common = [
        '--ros-args',
        '-r',
        '__ns:=/cloth_bench',
        '--params-file',
        str(ROOT / 'config' / 'benchmark.yaml'),
    ]
    contexts = []
    try:
        for cls, extra in (
            (Recorder, ['-p', f'bag:={bag}', '-p', 'time_offset:=2']),
            (TrajectoryPublisher, ['-p', 'pacing:=realtime', '-p', 'rate_hz:=1000']),
        ):
            contexts.append(rclpy.Context())
            rclpy.init(args=['prog', *common, *extra], context=contexts[-1])
            node = cls(context=contexts[-1])
            if cls is Recorder:
                assert Path(node.bag.path) == bag and node.offset_ns == 2_000_000_000
                assert node.get_parameter('use_sim_time').value
            else:
                assert (node.pacing, node.targets.rate_hz) == ('realtime', 1000.0)
                assert not node.get_parameter('use_sim_time').value
    finally:
        for context in contexts:
            context.shutdown()
