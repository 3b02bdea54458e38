import os
from glob import glob

from setuptools import find_packages, setup

package_name = "cloth_bench_ros"


def bag_files():
    """Each bundled bag directory under bags/ goes to share/cloth_bench_ros/bags/<name>/."""
    out = [("share/" + package_name + "/bags", glob("bags/*.md"))]
    for bag in sorted(glob("bags/*/")):
        out.append(("share/" + package_name + "/" + bag.rstrip("/"), glob(os.path.join(bag, "*"))))
    return out


setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(include=[package_name, package_name + ".*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/launch", glob("launch/*.launch.py")),
        ("share/" + package_name + "/config", glob("config/*.yaml")),
        ("share/" + package_name + "/config/presets", glob("config/presets/*.yaml")),
    ]
    + bag_files(),
    package_data={package_name: ["py.typed"]},
    install_requires=["setuptools"],
    extras_require={"newton": ["warp-lang>=1.17", "newton>=1.8"]},
    zip_safe=True,
    maintainer="cloth_bench_ros developers",
    maintainer_email="cloth-bench@example.org",
    description="Sim-to-real benchmark of cloth simulators as ROS 2 nodes",
    license="MIT",
    entry_points={
        "console_scripts": [
            "trajectory_publisher = cloth_bench_ros.nodes.trajectory_publisher:main",
            "simulator = cloth_bench_ros.nodes.simulator:main",
            "recorder = cloth_bench_ros.nodes.recorder:main",
            "evaluator = cloth_bench_ros.nodes.evaluator:main",
            "cloth-bench = cloth_bench_ros.cli:main",
        ],
        "cloth_bench_ros.engines": [
            "mujoco = cloth_bench_ros.engines.mujoco_cloth:MujocoCloth",
            "bullet = cloth_bench_ros.engines.bullet_cloth:BulletCloth",
            "newton = cloth_bench_ros.engines.newton_cloth:NewtonCloth",
        ],
    },
)
