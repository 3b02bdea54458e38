"""
Each command's own flags, declared once as options.Option: its parser and its study read them.

options.py holds the node parameters and the flags several commands share; a flag here belongs to
one command (or to one concept that only some commands have, such as a repeatable --rate).
"""

from __future__ import annotations

from cloth_bench_ros import validation
from cloth_bench_ros.options import Option, OPTIONS

RATE = OPTIONS['rate_hz']
REFERENCES = ('mujoco', 'newton-vbd')  # the synthetic references (config/synth*.yaml)


def _frame_or_detected(text: str, label: str) -> int | str:
    if text == 'detected':
        return 'detected'
    frame = validation.parse_integer(text, label)
    return validation.integer(frame, label, 0, validation.MAX_FRAME)


COMMAND_FLAGS = {option.name: option for option in (
    # the lists of a study: one value per flag, repeated (sweep, hil, cross-reference)
    RATE.variant(name='rate_list', default=None, action='append',
                 help='simulator rate (repeat for several)'),
    OPTIONS['cloth'].variant(name='cloth_list', default=None, action='append',
                             help='the cloth (repeat for several)'),
    OPTIONS['primitive'].variant(name='primitive_list', default=None, action='append',
                                 help='the task (repeat for several)'),
    # run, engines
    Option(
        'processes', bool, False, 'one OS process per node over DDS on loopback (default: all '
        'nodes in this process)', flag='--processes', action='store_true',
    ),
    Option(
        'figures', bool, False, 'qualitative figure (paper Fig. 4) and animation in the report '
        'directory', flag='--figures', action='store_true',
    ),
    Option(
        'warm', bool, False, "also compile what makes a first run slow (Newton: Warp's kernel "
        "cache; the metrics' numba kernels)", flag='--warm', action='store_true',
    ),
    # sweep
    Option(
        'sweep_bag_dir', str, None, 'directory of <cloth>_<task> or <cloth>_<trial>_<task> bags '
        '(default: the bundled bags)', flag='--bag-dir',
    ),
    Option(
        'step_per_target', bool, False, "internal time step = 1 / rate (the paper's frequency "
        "study) instead of the preset's", flag='--step-per-target', action='store_true',
    ),
    Option(
        'sweep_axis', str, None, 'settings mode: an axis of the factorial sweep, e.g. '
        'grid=6x8,11x15 or timestep=preset,0.005 (replaces the default axes)', flag='--axis',
        action='append', metavar='PARAM=V1,V2',
    ),
    Option(
        'retry_errors', bool, False, 'run cells recorded as errors again', flag='--retry-errors',
        action='store_true',
    ),
    Option(
        'all_metrics', bool, False, 'score every cell on every metric (docs/metrics.md), not only '
        "the paper's CD/HD and --metric's", flag='--all-metrics', action='store_true',
    ),
    Option(
        'dry_run', bool, False, 'count the cells and estimate the time, run nothing',
        flag='--dry-run', action='store_true',
    ),
    Option(
        'report', bool, False, 'render the report into <output>/report afterwards',
        flag='--report', action='store_true',
    ),
    # report, stress
    Option('results', str, None, 'results.jsonl of a sweep, or its directory', flag='results'),
    Option(
        'stress', str, None, 'stress.jsonl (or its directory) to include (default: stress.jsonl '
        'next to the results, if any)', flag='--stress',
    ),
    Option('case', str, None, 'only these cases (repeat; see --list)', flag='--case',
           action='append'),
    Option('list', bool, False, 'list the cases and exit', flag='--list', action='store_true'),
    Option(
        'max_wall_s', float, None, 'wall-time budget per case (default 120 s)',
        flag='--max-wall-s', low=0.0, low_open=True, unit='s',
    ),
    # cross-reference: the identifications ran on seed 0, so its seeds start at 1
    Option('xref_seeds', int, 5, 'seeds per engine', flag='--seeds', low=1),
    Option(
        'xref_seed_start', int, 1, 'first seed (1: identifications run on seed 0, so every seed '
        'is held out)', flag='--seed-start', low=0, high=validation.MAX_SEED,
    ),
    Option(
        'xref_output', str, 'results/cross_reference', 'results directory: results.jsonl '
        '(resumed) and cross_reference.md', flag='--output',
    ),
    # identify
    Option(
        'objective', str, 'cd', 'metric of the task window', flag='--objective',
        choices=('cd', 'hd'),
    ),
    Option(
        'params', str, None, "a parameter to fit (repeat for several; default: the engine's "
        'identified set)', flag='--param', action='append', metavar='PARAM', dest='params',
    ),
    Option(
        'span', float, 10.0, 'log-scale ranges reach this factor either side of the preset',
        flag='--span', low=1.0, low_open=True,
    ),
    Option(
        'batch', int, None, "trials in flight (default: the cluster's worker threads)",
        flag='--batch', low=1,
    ),
    Option(
        'validate_seeds', int, 5, 'held-out seeds to validate on', flag='--validate-seeds', low=0
    ),
    Option(
        'validation_bag_dir', str, None, "other trials' bags of the cloth and task for "
        'validation', flag='--bag-dir',
    ),
    # rank
    Option(
        'recordings', str, None, "rosbag2 bags, or folders of bags (the importer's output)",
        flag='recordings', nargs='+', metavar='RECORDING',
    ),
    # hil
    Option(
        'hil_config', str, 'preset', "preset (with --grid/--set) or the settings sweep's "
        'recommendation for the rate', flag='--config', choices=('preset', 'recommended'),
    ),
    Option(
        'settings', str, None, 'settings-sweep results for --config recommended (default '
        'results/settings; without a result there: config/hil_recommended.yaml)',
        flag='--settings',
    ),
    Option(
        'budget', float, None, 'recommendation: step p99 under this fraction of the period '
        '(default 0.5: the rest is the round trip)', flag='--deadline-budget', dest='budget',
        low=0.0, low_open=True,
    ),
    Option(
        'layout', str, 'auto', 'real-time layout: auto (default: the measured best this machine '
        'allows: the step loop polling on a core of its own, the controller on SCHED_FIFO) or '
        'none', flag='--layout', choices=('auto', 'none'),
    ),
    Option(
        'cpu', int, None, "pin the simulator's step loop to this core (-1: not; default: from "
        '--layout)', flag='--cpu', low=-1,
    ),
    Option(
        'fifo', int, None, 'SCHED_FIFO priority for the simulator and the controller (1-99, 0: '
        'not; default: from --layout)', flag='--fifo', low=0, high=99, metavar='PRIORITY',
    ),
    Option(
        'no_freeze_gc', bool, False, 'keep automatic garbage collection in the simulator',
        flag='--no-freeze-gc', action='store_true',
    ),
    Option(
        'busy_wait', bool, None, 'the simulator polls for targets instead of sleeping (needs a '
        'core of its own: --cpu; default: from --layout)', flag='--busy-wait',
        action='optional_bool',
    ),
    Option(
        'in_process', bool, False, 'all nodes in one process (intra-process transport)',
        flag='--in-process', action='store_true',
    ),
    Option(
        'no_lockstep', bool, False, 'skip the lockstep run that gives the CD',
        flag='--no-lockstep', action='store_true',
    ),
    Option(
        'export_recommended', str, None, 'write the recommendation of every engine, task and rate '
        'in --settings to FILE and exit', flag='--export-recommended', metavar='FILE',
    ),
    Option(
        'note', str, None, "--export-recommended: a provenance note (e.g. the sweep's command)",
        flag='--note',
    ),
    # hil --find-rate (hil/find_rate.py)
    Option(
        'find_rate', bool, False, 'find the highest rate each engine and --grid holds (misses '
        'under --miss-threshold), by bisection on a log scale', flag='--find-rate',
        action='store_true',
    ),
    Option(
        'miss_threshold', float, 0.01, 'a rate is held when under this share of deadlines is '
        'missed; over it, a run ends with what would meet its rate', flag='--miss-threshold',
        low=0.0, high=1.0, low_open=True,
    ),
    RATE.variant(name='rate_min', flag='--rate-min', default=10.0,
                 help='--find-rate: the lowest rate tried'),
    RATE.variant(name='rate_max', flag='--rate-max', default=10_000.0,
                 help='--find-rate: the highest rate tried'),
    Option(
        'rate_tolerance', float, 0.1, '--find-rate: stop when the bracket is within this '
        'fraction', flag='--rate-tolerance', low=0.0, low_open=True,
    ),
    Option(
        'repeats', int, 3, '--find-rate: runs per rate, judged on their median', flag='--repeats',
        low=1, high=99,
    ),
    # import, synth, converge, bag
    Option(
        'root', str, None, 'dataset root: <root>/<cloth>_rag_<trial>/<primitive>/cloud/'
        '<NNNNN>.ply|.pcd', flag='root',
    ),
    Option(
        'import_clean', bool, False, 'crop to the workspace, remove the table plane and outliers '
        '(core.cleaning) before writing', flag='--clean', action='store_true',
    ),
    Option(
        'reference', str, 'mujoco', 'reference model: mujoco (config/synth.yaml, default) or '
        'newton-vbd (config/synth_newton_vbd.yaml)', flag='--reference', choices=REFERENCES,
    ),
    Option(
        'synth_rate', float, None, "the reference's step rate, a multiple of 30 (default: the "
        "reference file's)", flag='--rate', low=0.0, low_open=True, unit='Hz', metavar='HZ',
    ),
    Option(
        'converge_axis', str, None, 'setting to refine (repeatable; default all three)',
        flag='--axis', action='append', choices=('iterations', 'rate', 'grid'),
    ),
    Option(
        'levels', int, 1, 'refinements per axis: iterations and rate x2 each, grid spacing /1.5',
        flag='--levels', low=1,
    ),
    Option(
        'converge_duration', float, None, 'seconds of the quintic part (default: the whole '
        'trial)', flag='--duration', low=0.0, low_open=True, unit='s', metavar='S',
    ),
    Option(
        'score', str, None, "score this engine's preset (tested grid) against every run "
        '(repeatable)', flag='--score', action='append', metavar='ENGINE',
    ),
    Option('path', str, None, 'the bag', flag='path'),
    Option('src', str, None, 'bag to read', flag='src'),
    Option('dst', str, None, 'new bag directory (must not exist or be empty)', flag='dst'),
    Option(
        'rewrite_change_of_phase_frame', int, None, 'store this change-of-phase frame in the '
        'trial (dynamic task), or the first table contact found in the clouds',
        flag='--change-of-phase-frame', metavar='N|detected', validate=_frame_or_detected,
    ),
)}
