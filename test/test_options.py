"""cloth_bench_ros/options.py: one declaration per option, and everything made from it agrees."""

import argparse
import ast
from fractions import Fraction
from pathlib import Path
import re

from cloth_bench_ros.cli import build_parser
from cloth_bench_ros.errors import InputError
from cloth_bench_ros.options import Option, OPTIONS
from cloth_bench_ros.runtime import declare_option
from cloth_bench_ros.runtime import embedded as rclpy
import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / 'cloth_bench_ros'
FLAGS = {o.flag: o for o in OPTIONS.values() if o.flag}
# Files whose literals are the declarations themselves.
NOT_YET = {
    'cloth_bench_ros/options.py',  # the declarations themselves
}
# The same spelling for another value, and rank's replay flags (its own defaults for a recording)
OTHER_VALUES = {
    ('cloth-bench synth', '--rate'),  # the reference's step rate (default: its file's)
    ('cloth-bench import', '--clean'),  # a switch: clean before writing
    ('cloth-bench converge', '--duration'),  # of the reference's quintic part, not of a run
    ('cloth-bench bag rewrite', '--change-of-phase-frame'),  # N or "detected"
    ('cloth-bench rank', '--topic'),
    ('cloth-bench rank', '--targets-topic'),
    ('cloth-bench rank', '--clean'),
}


@pytest.fixture
def context():
    ctx = rclpy.Context()
    yield ctx
    ctx.shutdown()


def _actions(parser: argparse.ArgumentParser, path: str = 'cloth-bench'):
    """Yield (command, action) for every option of every subcommand."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _actions(sub, f'{path} {name}')
        else:
            yield path, action


def _declared_flags():
    return [
        (path, action, FLAGS[flag])
        for path, action in _actions(build_parser())
        for flag in action.option_strings
        if flag in FLAGS
    ]


def test_help_shows_the_unit_range_and_default():
    assert OPTIONS['rate_hz'].help_text() == 'simulator rate; range [1, 10000] Hz; default 100'
    assert 'range (0, inf] s; default 1' in OPTIONS['align_window'].help_text()
    assert OPTIONS['seed'].range_text() == f'[0, {2**63 - 1}]'
    text = build_parser()._subparsers._group_actions[0].choices['run'].format_help()
    flat = ' '.join(text.split())
    assert '--rate RATE simulator rate; range [1, 10000] Hz; default 100' in flat
    assert '--voxel M voxel down-sampling size (0: off); range [0, inf] m; default 0' in flat


def test_every_flag_of_a_declared_option_is_made_from_its_declaration():
    """Its default and range are the declared ones; its help ends with the declared unit/range."""
    seen = set()
    for path, action, option in _declared_flags():
        if action.nargs is not None or isinstance(action, argparse._AppendAction):
            continue  # a repeatable flag (sweep --rate) is a list of values, not this option
        if (path, option.flag) in OTHER_VALUES:
            continue
        seen.add(option.name)
        assert getattr(action, 'declared', None) is option, (path, option.flag)
        assert action.default == option.check(option.default), (path, action.dest)
        tail = option.help_text().split('; ')[1:]
        assert action.help.endswith('; '.join(['', *tail])), path
        if option.type in (float, int) and not option.choices:
            with pytest.raises(argparse.ArgumentTypeError):
                action.type('nan')
    assert {'rate_hz', 'seed', 'cloth', 'primitive', 'voxel', 'align_step', 'trial'} <= seen


def test_the_run_flags_and_the_node_parameters_have_one_default_range_and_help(context):
    """A node's ParameterDescriptor and the `run` flag come from the same Option."""
    from cloth_bench_ros.nodes.trajectory_publisher import TrajectoryPublisher

    rclpy.init(args=['prog'], context=context)
    node = TrajectoryPublisher(context=context)
    run = {
        option.name: action for path, action, option in _declared_flags() if path.endswith(' run')
    }
    for name in ('rate_hz', 'primitive'):
        descriptor = node.describe_parameter(name)
        flag = run[name]
        assert descriptor.description == flag.help == OPTIONS[name].help_text()
        assert node.get_parameter(name).value == flag.default == OPTIONS[name].default
    rate = node.describe_parameter('rate_hz').floating_point_range[0]
    assert (rate.from_value, rate.to_value) == (OPTIONS['rate_hz'].low, OPTIONS['rate_hz'].high)
    assert node.describe_parameter('rate_hz').dynamic_typing  # `-p rate_hz:=1000` is accepted


def test_declare_option_checks_by_the_declaration_and_takes_an_integer_for_a_float(context):
    rclpy.init(
        args=['prog', '--ros-args', '-p', 'rate_hz:=1000', '-p', 'grid_nx:=-3',
              '-p', 'voxel:=fine'],
        context=context,
    )
    node = rclpy.create_node('probe', context=context)
    assert declare_option(node, 'rate_hz') == 1000.0
    # the descriptor's range refuses it, as rclpy's does (its reason, named by node and parameter)
    refused = r'probe: parameter grid_nx: .*out of range. Min: 0, Max: 201'
    with pytest.raises(InputError, match=refused):
        declare_option(node, 'grid_nx')
    with pytest.raises(InputError, match='probe: parameter voxel'):
        declare_option(node, 'voxel')
    assert declare_option(node, 'grid_nz') == 0
    side = node.describe_parameter('grid_nz').integer_range[0]
    assert (side.from_value, side.to_value) == (0, 201)


@pytest.mark.parametrize('argv', [['run', '--rate', '0'], ['run', '--trial', '-1'],
                                  ['trajectory', '--rate', '1e9'], ['run', '--voxel', '-1']])
def test_a_value_outside_the_declared_range_is_exit_2(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(argv)
    assert exc.value.code == 2
    assert 'is outside' in capsys.readouterr().err


def test_no_literal_default_of_a_declared_option_outside_its_declaration():
    """No node declares a declared option itself; no `rate_hz ... = 100.0` stands elsewhere."""
    names = '|'.join(OPTIONS)
    declared_again = re.compile(rf"declare_(?:parameter|float)\(\s*\w+,?\s*'({names})'")
    literal = re.compile(
        r'\b(rate_hz|align_window|align_step|voxel|wanted_rate)\b\s*(?::\s*\w+\s*)?=\s*[\d.]+'
    )
    flag_default = re.compile(
        r"'--(rate|seed|voxel|align-window|align-step)',[^)]*default=[\d.]+", re.S
    )
    found = []
    for path in PACKAGE.rglob('*.py'):
        rel = path.relative_to(ROOT).as_posix()
        if rel in NOT_YET:
            continue
        text = path.read_text()
        for pattern in (declared_again, literal, flag_default):
            found += [f'{rel}: {m.group(0)}' for m in pattern.finditer(text)]
    assert found == []


def _docs_table() -> dict[str, list[str]]:
    """Return parameter name -> the defaults the docs/ros2.md table gives it (one per node)."""
    rows = {}
    for line in (ROOT / 'docs' / 'ros2.md').read_text().splitlines():
        cells = [c.strip() for c in line.strip().strip('|').split('|')]
        if len(cells) != 4 or not cells[1].startswith('`'):
            continue
        names = re.findall(r'`([^`]*)`', cells[1])
        defaults = re.findall(r'`([^`]*)`', cells[2])
        if len(names) == len(defaults):
            for name, default in zip(names, defaults):
                rows.setdefault(name, []).append(default)
    return rows


def _same(option: Option, text: str) -> bool:
    if option.type is float:
        return float(Fraction(text)) == pytest.approx(option.default)
    value = yaml.safe_load(text)
    return (value if value is not None else '') == option.default


def test_the_docs_parameter_table_agrees_with_the_declarations():
    table = _docs_table()
    checked = [name for name in OPTIONS if name in table]
    assert {'rate_hz', 'seed', 'voxel', 'align_step', 'grid_nx', 'trial'} <= set(checked)
    for name in checked:
        for text in table[name]:
            assert _same(OPTIONS[name], text), f'docs/ros2.md: {name} default {text}'


def test_the_launch_file_and_the_config_agree_with_the_declarations():
    tree = ast.parse((ROOT / 'launch' / 'benchmark.launch.py').read_text())
    defaults = next(
        ast.literal_eval(node.value)
        for node in ast.walk(tree)
        if isinstance(node, ast.Assign)
        and getattr(node.targets[0], 'id', '') == 'defaults'
    )
    launch = [name for name in defaults if name in OPTIONS]
    assert {'rate_hz', 'seed', 'cloth', 'primitive'} <= set(launch)
    for name in launch:
        assert _same(OPTIONS[name], defaults[name]), f'launch: {name}'
    config = yaml.safe_load((ROOT / 'config' / 'benchmark.yaml').read_text())
    common = config['/**']['ros__parameters']
    shared = [name for name in common if name in OPTIONS]
    assert {'rate_hz', 'seed', 'topic', 'change_of_phase_frame'} <= set(shared)
    for name in shared:
        assert common[name] == OPTIONS[name].default, f'config/benchmark.yaml: {name}'


def test_every_parameter_of_every_node_is_read_only_and_a_change_is_refused(context):
    """A running node reads its parameters once: each descriptor says read-only, rclpy refuses."""
    from cloth_bench_ros.nodes.evaluator import Evaluator
    from cloth_bench_ros.nodes.recorder import Recorder
    from cloth_bench_ros.nodes.simulator import Simulator
    from cloth_bench_ros.nodes.trajectory_publisher import TrajectoryPublisher
    from cloth_bench_ros.paths import bundled_bag

    bag = bundled_bag('towel', 'dynamic')
    rclpy.init(args=['prog', '--ros-args', '-p', f'bag:={bag}', '-p', 'grid_nx:=4',
                     '-p', 'grid_nz:=5'], context=context)
    settable = {'use_sim_time'}  # rclpy's time source follows it
    for node_class in (TrajectoryPublisher, Simulator, Evaluator, Recorder):
        node = node_class(context=context)
        try:
            names = [n for n in node.list_parameters([], 0).names if n not in settable]
            assert len(names) >= 4, node_class
            for name in names:
                assert node.describe_parameter(name).read_only, (node_class.__name__, name)
            refused = node.set_parameters([rclpy.Parameter(names[0], value=0)])[0]
            assert not refused.successful and 'read-only' in refused.reason
        finally:
            node.destroy_node()
