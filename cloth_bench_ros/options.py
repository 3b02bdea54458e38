"""
Each user-facing value declared once: name, type, default, range, unit, help.

A CLI flag (cli/common.add_option), a node parameter with its ParameterDescriptor
(runtime.declare_option) and the check of either (Option.check, the validation layer) are all made
from the one `Option` here. A flag's help shows the unit, the range and the default.

OPTIONS are node parameters (most with a flag too); FLAGS are the command line's own, shared by
several commands (--engine, --grid, --workers, --output, ...). A flag of one command only is
declared in command_options.py, as an `Option` too; no default is written anywhere else.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

from cloth_bench_ros import validation
from cloth_bench_ros.errors import InputError
from cloth_bench_ros.metric_choice import DEFAULT_METRIC, METRICS

PRIMITIVES = ('dynamic', 'quasi_static')  # the tasks (core.trajectory.Primitive's values)
CLOTHS = ('towel', 'chequered', 'linen')  # the cloths the presets describe
PACINGS = ('lockstep', 'realtime')
SETTLES = ('full', 'fast')  # the settle phase (engines/settle.py)


@dataclass(frozen=True)
class Option:
    """One value a user sets, as a node parameter `name` and, where it has one, a CLI `flag`."""

    name: str
    type: type  # noqa: A003  (bool, int, float or str)
    default: Any
    help: str  # noqa: A003
    flag: str | None = None
    low: float | None = None
    high: float | None = None
    low_open: bool = False  # the range is (low, high]
    unit: str = ''
    choices: tuple[str, ...] = ()
    unset: Any = None  # a node value that means "not given" (checked to None), e.g. -1
    metavar: str | None = None
    # a running node cannot change it (its ParameterDescriptor says so): every node reads its
    # parameters once, at start-up
    read_only: bool = True
    # a str value's own check, and the command line's of any type: `validate(value, label)` ->
    # the value (e.g. parse_grid: a tuple); an InputError if it is not one
    validate: Callable[[Any, str], Any] | None = None
    # the command line only: '' (a value), 'store_true', 'append' or 'optional_bool' (--x/--no-x)
    action: str = ''
    dest: str | None = None
    nargs: str | None = None
    required: bool = False

    def variant(self, **changes: Any) -> Option:
        """Return this option with some fields changed (e.g. another command's help or action)."""
        return replace(self, **changes)

    def check(self, value: Any, label: str | None = None) -> Any:
        """Return `value` checked against the declaration (InputError naming `label`)."""
        label = label or self.flag or self.name
        if self.unset is not None and not isinstance(value, bool) and value == self.unset:
            return None
        if self.choices:
            return validation.choice(value, label, self.choices)
        if self.type is float:
            return validation.number(
                value, label, self.low, self.high, low_open=self.low_open, unit=self.unit
            )
        if self.type is int:
            low = None if self.low is None else int(self.low)
            high = None if self.high is None else int(self.high)
            return validation.integer(value, label, low, high)
        if self.type is bool:
            return validation.boolean(value, label)
        if not isinstance(value, str):
            raise InputError(f'{label}: {value!r} is not a string')
        return self.validate(value, label) if self.validate else value

    def parse(self, text: str, label: str | None = None) -> Any:
        """Return the value of a command-line word, checked."""
        label = label or self.flag or self.name
        if self.validate:
            return self.validate(text, label)
        if self.type is float and not self.choices:
            return self.check(validation.parse_number(text, label), label)
        if self.type is int:
            return self.check(validation.parse_integer(text, label), label)
        return self.check(text, label)

    def range_text(self) -> str:
        """Return the range with its unit, e.g. '[1, 10000] Hz', or '' where there is none."""
        if self.choices or (self.low is None and self.high is None):
            return ''
        left = '(' if self.low_open else '['
        low = '-inf' if self.low is None else self._number(self.low)
        high = 'inf' if self.high is None else self._number(self.high)
        return f'{left}{low}, {high}]' + (f' {self.unit}' if self.unit else '')

    def _number(self, value: float) -> str:
        return str(int(value)) if self.type is int else f'{value:g}'

    def help_text(self) -> str:
        """Return the help of the flag: the meaning, unit and range, and the default."""
        parts = [self.help]
        if self.range_text():
            parts.append(f'range {self.range_text()}')
        elif self.unit:
            parts.append(f'in {self.unit}')
        if self.action in ('store_true', 'append') or 'default' in self.help:
            return '; '.join(parts)  # a switch, a list, or a default the help explains itself
        default = self.default
        if default is not None and not self.validate:
            default = self.check(default)
        if default not in (None, ''):
            parts.append(f'default {self._number(default) if self.type is float else default}')
        return '; '.join(parts)


def _declare(*options: Option) -> dict[str, Option]:
    return {o.name: o for o in options}


OPTIONS = _declare(
    Option(
        'rate_hz', float, 100.0, 'simulator rate', flag='--rate',
        low=validation.MIN_RATE_HZ, high=validation.MAX_RATE_HZ, unit='Hz',
    ),
    Option(
        'seed', int, 0, 'perturbs the initial cloth', flag='--seed',
        low=0, high=validation.MAX_SEED,
    ),
    Option('primitive', str, 'dynamic', 'the task', flag='--primitive', choices=PRIMITIVES),
    Option('cloth', str, 'towel', 'the cloth', flag='--cloth', choices=CLOTHS),
    Option(
        'grid_nx', int, 0, 'mesh vertices across the cloth (0: the engine default)',
        low=0, high=validation.MAX_GRID_SIDE,
    ),
    Option(
        'grid_nz', int, 0, 'mesh vertices down the cloth (0: the engine default)',
        low=0, high=validation.MAX_GRID_SIDE,
    ),
    # what a plain recording does not say (docs/own-recording.md)
    Option(
        'topic', str, '', "PointCloud2 topic to score (default: the project's, else the only one)",
        flag='--topic',
    ),
    Option(
        'start_time', str, '',
        'start of the motion in bag time: an absolute stamp (>= 1e9 s) or seconds from the first '
        'message (default: targets topic, else automatic)',
        flag='--start-time', metavar='S',
    ),
    Option(
        'targets_topic', str, '', 'recorded PoseArray gripper targets whose first motion is the '
        'start', flag='--targets-topic',
    ),
    Option(
        'change_of_phase_frame', int, -1,
        "first frame left out of the dynamic window (default: the bag's metadata, else the "
        'first table contact detected in the clouds)',
        flag='--change-of-phase-frame', low=0, high=validation.MAX_FRAME, unset=-1, metavar='N',
    ),
    Option(
        'clean', str, 'auto',
        "crop, table plane, outliers (auto: on for bags without the project's metadata)",
        flag='--clean', choices=('auto', 'on', 'off'),
    ),
    Option(
        'voxel', float, 0.0, 'voxel down-sampling size (0: off)', flag='--voxel', low=0.0,
        unit='m', metavar='M',
    ),
    Option(
        'table_plane', str, 'auto', 'remove the table plane; it also removes cloth lying flat on '
        'the table (auto: remove for dynamic, keep for quasi_static)', flag='--table-plane',
        choices=('auto', 'remove', 'keep'),
    ),
    Option(
        'align_window', float, 1.0, 'seconds of motion the automatic alignment compares',
        flag='--align-window', low=0.0, low_open=True, unit='s', metavar='S',
    ),
    Option(
        'align_step', float, 1.0 / 30.0, 'coarse step of the automatic alignment (refined 8x)',
        flag='--align-step', low=0.0, low_open=True, unit='s', metavar='S',
    ),
    Option(
        'trial', int, 0,
        'the repetition to score in a recording of several (0: the first usable)',
        flag='--trial', low=0, metavar='N',
    ),
    Option(
        'align', str, 'onset', 'start of a cloud-only recording: onset (fitted to the task in '
        'the clouds, no engine: every engine scored on the same frames) or simulation (searched '
        'against the first engine)', flag='--align', choices=('onset', 'simulation'),
    ),
    # how the graph runs
    Option(
        'pacing', str, 'lockstep', 'lockstep: each target waits for every engine; realtime: '
        'targets on the wall clock', flag='--pacing', choices=PACINGS,
    ),
    Option(
        'duration', float, 0.0, 'seconds of the trajectory to run (0: all; a shortened run is '
        'not scored)', flag='--duration', low=0.0, unit='s',
    ),
    # the live view (docs/live.md)
    Option(
        'live', bool, False, 'serve the run to Foxglove while it goes (WebSocket; the error on '
        'the cloth, CD/HD)', flag='--live', action='store_true',
    ),
    Option(
        'live_host', str, '127.0.0.1', 'address the live view binds (127.0.0.1: this machine '
        'only)', flag='--live-host', validate=validation.host,
    ),
    Option(
        'live_port', int, 8765, "its port (8765: Foxglove's; 0: one the system picks)",
        flag='--live-port', low=0, high=65535,
    ),
    Option(
        'live_wait', float, 30.0, 'seconds a lockstep run waits for a first viewer before it '
        'starts (then it goes on without one)', flag='--live-wait', low=0.0,
        high=validation.MAX_WAIT_S, unit='s', metavar='S',
    ),
)

# The command line's own options, shared by several commands (cli/common.add_option).
FLAGS = _declare(
    Option(
        'engines', str, None, 'engine, or engine:model, e.g. newton:vbd (repeat for several)',
        flag='--engine', action='append', metavar='ENGINE[:MODEL]',
    ),
    Option(
        'grid', str, None, "cloth mesh NXxNZ vertices, e.g. 6x8 (default: the engine's)",
        flag='--grid', validate=validation.parse_grid,
    ),
    Option(
        'presets', str, 'default', 'cloth parameters: default (config/presets), identified '
        '(fitted to the bundled MuJoCo-made references), identified-newton-vbd (fitted to the '
        'Newton VBD ones), or a directory of <engine>.yaml files (e.g. an identify --output)',
        flag='--presets',
    ),
    Option('output', str, None, 'results directory', flag='--output'),
    Option('bag', str, None, 'rosbag2 bag (default: the bundled one)', flag='--bag'),
    Option(
        'workers', int, None, 'local worker processes (default: all cores)', flag='--workers',
        low=1,
    ),
    Option(
        'scheduler', str, None, 'run on an existing Dask cluster, e.g. tcp://127.0.0.1:8786',
        flag='--scheduler',
    ),
    Option('no_progress', bool, False, 'no progress bar', flag='--no-progress',
           action='store_true'),
    Option(
        'set', str, None, 'override an engine parameter (repeatable)', flag='--set',
        action='append', metavar='ENGINE.PARAM=VALUE',
    ),
    Option(
        'metric', str, DEFAULT_METRIC, "metric to rank and compare on (default cd: the paper's "
        'CD; docs/metrics.md)', flag='--metric', choices=tuple(METRICS),
    ),
    Option('seeds', int, None, 'number of seeds', flag='--seeds', low=1),
    Option('seed_start', int, 0, 'first seed', flag='--seed-start', low=0,
           high=validation.MAX_SEED),
    Option(
        'max_frames', int, None, 'score only the first N frames of each window (faster)',
        flag='--max-frames', low=1,
    ),
    # the settings recommendation's CD tolerance (report, hil)
    Option(
        'tolerance_rel', float, 0.05, 'recommendation: CD within this fraction of the best',
        flag='--tolerance-rel', low=0.0,
    ),
    Option(
        'tolerance_abs', float, 0.002, '... or this many metres, whichever is larger',
        flag='--tolerance-abs', low=0.0, unit='m',
    ),
    Option(
        'settle', str, 'full', "the settle phase before the quintic part: full (the paper's, "
        'every target simulated) or fast (its final hold simulated for 0.3 s of 1 s; '
        'docs/benchmark.md)', flag='--settle', choices=SETTLES,
    ),
    Option('overwrite', bool, False, 'replace what exists', flag='--overwrite',
           action='store_true'),
    # checked on this machine by the command line (cli/common.device: Warp's devices)
    Option(
        'newton_device', str, None, "Newton's device: cpu, cuda, cuda:N or auto (default auto: "
        'the first CUDA device Warp finds, else cpu)', flag='--device', metavar='DEVICE',
    ),
)

# The studies' own flags (identify, rank, sweep), declared here so that each default is written
# once: the command's flag, its spec's field and the study read it. A command may add its own check
# (`variant(validate=...)`) or help; the default stays this one.
SAMPLERS = ('cmaes', 'tpe', 'gp', 'both')
FLAGS.update(_declare(
    Option(
        'sampler', str, 'tpe', 'the identification sampler: tpe (Bayesian optimisation; '
        'default), cmaes, gp (Gaussian-process BO, needs PyTorch) or both (CMA-ES and TPE, keep '
        "the best: the paper's pair, about twice the time)", flag='--sampler', choices=SAMPLERS,
    ),
    Option(
        'trials', int, 0, 'identification trials per sampler, or auto (default): 32, then '
        'doubling while a doubling improves the best by 2 % or more (at most 512; the paper ran '
        '500)', flag='--trials', low=1,
    ),
    Option(
        'fidelity', str, 'full', 'full (default): every trial over the whole motion; '
        'multi-fidelity: prune: a trial whose CD over the first quarter of the frames is above '
        'the best 30 % stops there; coarse: a trial is scored first on a mesh of half the '
        'vertices per side, and run on its own mesh only where that CD is in the best 20 % of '
        'the last 16', flag='--fidelity', choices=('full', 'prune', 'coarse'),
    ),
    Option(
        'sweep_mode', str, 'paper', "paper: the paper's layout (default); settings: sweep the "
        'settings that cost time', flag='--mode', choices=('paper', 'settings'),
    ),
    Option(
        'keep_frames', str, 'first', 'seeds whose per-frame CD/HD are kept for the plots '
        '(default: the first)', flag='--keep-frames', choices=('first', 'all', 'none'),
    ),
    Option('rank_seeds', int, 3, 'held-out seeds per held-out trial', flag='--seeds', low=1),
    Option(
        'rates', float, (10.0, 100.0, 1000.0), 'a rate whose step times decide the '
        'recommendation (repeat for several; default 10, 100, 1000)', flag='--recommend-rate',
        action='append', low=validation.MIN_RATE_HZ, high=validation.MAX_RATE_HZ, unit='Hz',
        metavar='HZ', dest='rates',
    ),
))


def declared(name: str) -> Option:
    """Return the declaration of `name`: a node parameter's, else a shared flag's."""
    return OPTIONS[name] if name in OPTIONS else FLAGS[name]


# The recorder's parameters for a recording that does not say everything, in `run --help` order.
REPLAY_OPTIONS = (
    'topic',
    'start_time',
    'targets_topic',
    'change_of_phase_frame',
    'clean',
    'voxel',
    'table_plane',
    'align_window',
    'align_step',
    'trial',
    'align',
    'motion',
)

# The motion scored: a task file of the user's, or the task's motion on a recording that does not
# match it (docs/own-recording.md).
OPTIONS.update(_declare(
    Option(
        'task', str, '', "task file (YAML: the grippers' quintic segments, settle phase and "
        'metric window; see docs/own-recording.md) instead of the shipped task of --primitive',
        flag='--task', metavar='FILE',
    ),
    Option(
        'motion', str, 'recorded', 'recorded: the engines follow the grippers that '
        '--gripper-frames or --targets-topic name, and a recording whose motion does not match '
        "the task is refused; task: the task's motion, whatever the recording holds",
        flag='--motion', choices=('recorded', 'task'),
    ),
))
# The recorded grippers the engines follow (cloth-bench run and motion; docs/own-recording.md):
# the command line turns them into a task file (data/recorded_motion.py), which the nodes take.
FLAGS.update(_declare(
    Option(
        'gripper_frames', str, '', 'the grippers as tf frames LEFT,RIGHT of /tf and /tf_static: '
        'the engines follow them', flag='--gripper-frames', metavar='LEFT,RIGHT',
    ),
    Option(
        'table_z', float, None, "the table top's height in the clouds' frame (default: the plane "
        'found in the first cloud, else no table)', flag='--table-z', unit='m', low=-100.0,
        high=100.0,
    ),
    Option(
        'transform', str, None, '4x4 matrix into world for every cloud, instead of tf',
        flag='--transform', metavar='FILE',
    ),
))
MOTION_FLAGS = ('gripper_frames', 'table_z')

# A cloth of another size than the benchmark's 0.5 x 0.7 m, and its mass (docs/identification.md).
OPTIONS.update(_declare(
    Option(
        'cloth_size', str, '',
        'width (grasped edge) and hanging length of the cloth, W,L in metres: width in '
        f'[{validation.CLOTH_WIDTH_RANGE[0]:g}, {validation.CLOTH_WIDTH_RANGE[1]:g}], length in '
        f'[{validation.CLOTH_LENGTH_RANGE[0]:g}, {validation.CLOTH_LENGTH_RANGE[1]:g}] '
        "(default: the benchmark's 0.5,0.7)",
        flag='--cloth-size', metavar='W,L',
    ),
    Option(
        'cloth_mass', float, 0.0,
        "total mass of the cloth (unset: the preset's mass per area times the cloth's area)",
        flag='--cloth-mass', low=validation.CLOTH_MASS_RANGE[0],
        high=validation.CLOTH_MASS_RANGE[1], unit='kg', unset=0.0, metavar='KG',
    ),
    Option(
        'cloth_mesh', str, '',
        'the cloth as a triangle mesh file (OBJ, PLY or STL) in its start placement, grasped at '
        "the vertices nearest the grippers' start (docs/own-recording.md; default: the grid)",
        flag='--cloth-mesh', metavar='FILE',
    ),
))

# The recording options: what every command that reads a user's recording takes (run, identify,
# rank; cli/common.recording_options), declared once, in `run --help` order.
RECORDING_FLAGS = ('task', *MOTION_FLAGS, *REPLAY_OPTIONS, 'transform')

# The nodes' engines: the simulator's, the one the recorder aligns with, and what the evaluator
# writes beside the scores.
OPTIONS.update(_declare(
    Option('engine', str, 'mujoco', 'engine name (`cloth-bench engines` lists them)',
           flag='--engine'),
    Option('align_engine', str, 'mujoco', "the automatic alignment's reference simulation"),
    Option(
        'device', str, '', "Newton's compute device: cpu, cuda, cuda:N or auto; empty: "
        "engine_params' device, else the engine's (auto)",
    ),
    Option(
        'record_comparison', str, '', 'write a comparison bag (Foxglove/RViz)',
        flag='--record-comparison', metavar='DIR',
    ),
))

# The nodes' own parameters, without a flag (the command line sets them from its own options):
# runtime.declare_fixed(node, name) reads the default here. A list's type is its items'.
NODE_PARAMETERS = _declare(
    # trajectory publisher
    Option('engines', str, [OPTIONS['engine'].default],
           'the simulators whose states lockstep waits for (the evaluator: what to score)'),
    Option('wait_for_recorder', bool, True, 'start only once the recorder is in the graph'),
    Option('wait_for_evaluator', bool, True, 'start only once the evaluator is in the graph'),
    Option('timing_log', str, '', 'realtime: directory for timeline_<engine>.csv'),
    # simulator
    Option('engine_params', str, '{}', 'YAML mapping of parameter overrides on the preset'),
    Option('presets_dir', str, '', 'directory of <engine>.yaml presets (empty: config/presets)'),
    Option('cpu', int, -1, 'pin the process to this core (-1: not)'),
    Option('realtime_priority', int, 0, 'SCHED_FIFO priority (0: not)'),
    Option('freeze_gc', bool, False, 'freeze the start-up heap, collect only after each state'),
    # recorder
    Option('mode', str, 'replay', 'replay or record', choices=('replay', 'record')),
    Option('bag', str, '', 'rosbag2 bag to replay'),
    Option('clock', str, 'sim', 'sim: frames follow /clock; wall: replay on the wall clock',
           choices=('sim', 'wall')),
    Option('rate_factor', float, 1.0, 'wall mode: replay speed'),
    Option('start_offset', float, 0.0, 'wall mode: seconds skipped at the start', unit='s'),
    Option('loop', bool, False, 'wall mode: loop at the end'),
    Option('transform', float, [0.0], '16 numbers (row-major 4x4) into world for every cloud'),
    Option('output', str, '', 'record mode: bag directory'),
    Option('record_topics', str, [''], 'record mode: "topic:package/msg/Type" entries'),
    # evaluator
    Option('output_dir', str, '', 'where summary.json and frames.csv go (empty: not written)'),
    Option('comparison_figures', bool, False, 'qualitative figure and animation into output_dir'),
    Option('devices', str, '', "the engines' devices, comma-separated, for summary.json"),
    Option('models', str, '', "the engines' models, comma-separated, for summary.json"),
)
