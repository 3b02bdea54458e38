"""ros2 launch cloth_bench_ros benchmark.launch.py [engine:=mujoco] [rate_hz:=100.0] [bag:=PATH] ...

The node graph of DESIGN.md, one process per node; the launch ends when the evaluator has
written its report.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, EmitEvent, OpaqueFunction, RegisterEventHandler
from launch.event_handlers import OnProcessExit
from launch.events import Shutdown
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def _nodes(context):
    share = get_package_share_directory("cloth_bench_ros")
    params_file = os.path.join(share, "config", "benchmark.yaml")
    arg = lambda name: LaunchConfiguration(name).perform(context)  # noqa: E731
    engines = [e.strip() for e in arg("engines").split(",") if e.strip()]
    primitive, cloth = arg("primitive"), arg("cloth")
    bag = arg("bag") or os.path.join(share, "bags", f"{cloth}_{primitive}")
    common = {"primitive": primitive, "rate_hz": float(arg("rate_hz")), "cloth": cloth, "engines": engines}
    nodes = [
        Node(package="cloth_bench_ros", executable="trajectory_publisher", namespace="cloth_bench",
             parameters=[params_file, common, {"pacing": arg("pacing"),
                                               "min_clock_subscribers": len(engines) + 2}]),
        Node(package="cloth_bench_ros", executable="recorder", namespace="cloth_bench",
             parameters=[params_file, {"bag": bag}]),
    ]
    evaluator = Node(package="cloth_bench_ros", executable="evaluator", namespace="cloth_bench",
                     parameters=[params_file, common, {"output_dir": arg("output_dir"), "pacing": arg("pacing")}])
    for engine in engines:
        nodes.append(Node(package="cloth_bench_ros", executable="simulator", name=f"simulator_{engine}",
                          namespace="cloth_bench",
                          parameters=[params_file, common, {"engine": engine, "seed": int(arg("seed"))}]))
    shutdown = RegisterEventHandler(OnProcessExit(target_action=evaluator,
                                                  on_exit=[EmitEvent(event=Shutdown(reason="report written"))]))
    return nodes + [evaluator, shutdown]


def generate_launch_description():
    defaults = {"engines": "mujoco", "rate_hz": "100.0", "primitive": "dynamic", "cloth": "towel",
                "bag": "", "seed": "0", "pacing": "lockstep", "output_dir": "cloth_bench_results"}
    return LaunchDescription(
        [DeclareLaunchArgument(name, default_value=value) for name, value in defaults.items()]
        + [OpaqueFunction(function=_nodes)]
    )
