"""
Launch the benchmark's node graph.

ros2 launch cloth_bench_ros benchmark.launch.py [engines:=mujoco,bullet] [rate_hz:=100.0]
[bag:=PATH] [live:=true] [live_port:=8765] [live_wait:=30.0] [cloth_size:=W,L]
[cloth_mass:=KG] [cloth_mesh:=FILE] [device:=cpu|cuda|cuda:N|auto] [task:=FILE] ...

The node graph (README, "The node graph"), one process per node, output on the screen; the launch
ends when the evaluator has written its report. Launch arguments win over config/benchmark.yaml:
every node has a name and a namespace, so launch_ros writes its dict parameters under the node's
full name into a params file passed after benchmark.yaml, and rclpy applies that key last.
`device` is Newton's, as `--device` on the command line (empty: its default, the first CUDA
device Warp finds, else the CPU); the evaluator records the device each engine runs on.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, EmitEvent, OpaqueFunction, RegisterEventHandler
from launch.event_handlers import OnProcessExit
from launch.events import Shutdown
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

NAMESPACE = 'cloth_bench'


def _node(executable, name, params_file, *overrides):
    return Node(
        package='cloth_bench_ros',
        executable=executable,
        name=name,
        namespace=NAMESPACE,
        output='screen',
        parameters=[params_file, *overrides],
    )


def _nodes(context):
    share = get_package_share_directory('cloth_bench_ros')
    params_file = os.path.join(share, 'config', 'benchmark.yaml')

    def arg(name):
        return LaunchConfiguration(name).perform(context)

    engines = [e.strip() for e in arg('engines').split(',') if e.strip()]
    primitive, cloth, pacing, seed = (
        arg('primitive'),
        arg('cloth'),
        arg('pacing'),
        int(arg('seed')),
    )
    bag = arg('bag') or os.path.join(share, 'bags', f'{cloth}_{primitive}')
    common = {
        'primitive': primitive,
        'task': arg('task'),  # a task file (docs/own-recording.md); '': the shipped one
        'rate_hz': float(arg('rate_hz')),
        'cloth': cloth,
        'engines': engines,
    }
    device = arg('device')
    if device and 'newton' not in engines:
        raise ValueError(f'launch argument device:={device} is the device of engine newton, '
                         f'which is not among engines:={arg("engines")}')
    from cloth_bench_ros.engines import engine_device  # here: Warp starts only for a launch

    devices = {e: engine_device(e, {'device': device} if e == 'newton' and device else {})
               for e in engines}  # `auto` resolved as the simulator resolves it, on this machine
    cloth_size = {  # a cloth of another size or mesh, its mass (docs/own-recording.md)
        'cloth_size': arg('cloth_size'),
        'cloth_mass': float(arg('cloth_mass')),
        'cloth_mesh': arg('cloth_mesh'),
    }
    nodes = [
        _node(
            'trajectory_publisher',
            'trajectory_publisher',
            params_file,
            common,
            {'pacing': pacing, 'cloth_size': cloth_size['cloth_size']},
        ),
        # The recorder sends the frames up to the last target at this rate and primitive.
        _node('recorder', 'recorder', params_file, common, {'bag': bag}, cloth_size),
    ]
    evaluator = _node(
        'evaluator',
        'evaluator',
        params_file,
        common,
        cloth_size,
        {'output_dir': arg('output_dir'), 'pacing': pacing, 'seed': seed,
         'devices': ','.join(devices.values())},
        {  # the live view in Foxglove (docs/live.md)
            'live': arg('live').lower() == 'true',
            'live_port': int(arg('live_port')),
            'live_wait': float(arg('live_wait')),
        },
    )
    for engine in engines:
        nodes.append(
            _node(
                'simulator',
                f'simulator_{engine}',
                params_file,
                common,
                cloth_size,
                {'engine': engine, 'seed': seed,
                 **({'device': device} if engine == 'newton' and device else {})},
            )
        )
    shutdown = RegisterEventHandler(
        OnProcessExit(
            target_action=evaluator, on_exit=[EmitEvent(event=Shutdown(reason='report written'))]
        )
    )
    return nodes + [evaluator, shutdown]


def generate_launch_description():
    defaults = {
        'engines': 'mujoco',
        'rate_hz': '100.0',
        'primitive': 'dynamic',
        'cloth': 'towel',
        'bag': '',
        'seed': '0',
        'pacing': 'lockstep',
        'output_dir': 'cloth_bench_results',
        'live': 'false',
        'live_port': '8765',
        'live_wait': '30.0',
        'cloth_size': '',
        'cloth_mass': '0.0',
        'cloth_mesh': '',
        'device': '',
        'task': '',
    }
    return LaunchDescription(
        [DeclareLaunchArgument(name, default_value=value) for name, value in defaults.items()]
        + [OpaqueFunction(function=_nodes)]
    )
