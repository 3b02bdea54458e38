"""cloth_bench_ros: measure the sim-to-real gap of cloth simulators on ROS 2."""

__version__ = '0.1.0'
