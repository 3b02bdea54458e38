"""
A bug planted in MuJoCo's step: `ValueError` from MujocoCloth._step, in every process.

Put this directory on PYTHONPATH of a command: Python imports this module at start-up in the
command and in every process it starts (Dask workers, node processes), and it patches the engine
module when that is first imported (importing it here would start the project in every Python).
"""

import importlib.abc
import importlib.util
import sys

PLANTED = 'planted bug in MujocoCloth._step'
_MODULE = 'cloth_bench_ros.engines.mujoco_cloth'


def _step(self, left, right):
    raise ValueError(PLANTED)


class _Plant(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name != _MODULE:
            return None
        sys.meta_path.remove(self)
        spec = importlib.util.find_spec(name)
        load = spec.loader.exec_module

        def exec_module(module):
            load(module)
            module.MujocoCloth._step = _step

        spec.loader.exec_module = exec_module
        return spec


sys.meta_path.insert(0, _Plant())
