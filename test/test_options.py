"""cloth_bench_ros/options.py: one declaration per option, and everything made from it agrees."""

import argparse
import ast
from fractions import Fraction
from pathlib import Path
import re

from cloth_bench_ros.cli import build_parser
from cloth_bench_ros.command_options import COMMAND_FLAGS
from cloth_bench_ros.errors import InputError
from cloth_bench_ros.options import FLAGS as FLAGS_DECLARED, NODE_PARAMETERS, Option, OPTIONS
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
    'cloth_bench_ros/command_options.py',
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
    """Return (command, action, option) of every flag made from a node parameter's declaration."""
    return [
        (path, action, OPTIONS[action.declared.name])
        for path, action in _actions(build_parser())
        if getattr(action, 'declared', None) is not None and action.declared.name in OPTIONS
        and action.option_strings and action.help != argparse.SUPPRESS
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
        seen.add(option.name)
        # the declaration itself, or a variant with another flag or help only
        assert action.declared.variant(flag=option.flag, help=option.help) == option, path
        assert action.default == option.check(option.default), (path, action.dest)
        tail = action.declared.help_text().split('; ')[1:]
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


def _literal(value) -> str | None:
    """Return a pattern of a distinctive default as code writes it (not 0, '', False or None)."""
    if isinstance(value, bool) or value in (None, '', 0):
        return None
    if isinstance(value, float):
        whole = rf'|{value:g}\b(?!\.)' if value.is_integer() else ''
        return re.escape(repr(value)) + r'\b' + whole
    if isinstance(value, int):
        return rf'{value}\b(?!\.)'
    return rf"""['"]{re.escape(value)}['"]""" if isinstance(value, str) else None


def test_no_literal_default_of_a_declared_option_outside_its_declaration():
    """
    No module writes a declared option's default itself: they read the declaration.

    Neither a node declaring a declared option by hand, nor `name: T = default`, `name=default`,
    `'name': default` or `.get('name', default)` of any declared option anywhere in the package.
    """
    names = '|'.join(OPTIONS)
    declared = rf"declare_(?:parameter|float|fixed)\(\s*(?:\w+,\s*)?'({names})'"
    patterns = [re.compile(declared)]
    for option in [*OPTIONS.values(), *FLAGS_DECLARED.values(), *COMMAND_FLAGS.values(),
                   *NODE_PARAMETERS.values()]:
        literal = _literal(option.default)
        if literal:
            patterns.append(re.compile(
                rf"""(\b{option.name}\s*:\s*[\w\[\]., |]+=\s*|\b{option.name}=|"""
                rf"""['"]{option.name}['"]\s*[,:]\s*)({literal})"""
            ))
    assert len(patterns) > 15
    found = []
    for path in PACKAGE.rglob('*.py'):
        rel = path.relative_to(ROOT).as_posix()
        if rel in NOT_YET:
            continue
        text = path.read_text()
        for pattern in patterns:
            found += [f'{rel}: {m.group(0)}' for m in pattern.finditer(text)]
    assert found == []
    planted = ['rate_hz: float = 100.0', "r.get('pacing', 'lockstep')", 'live_port=8765',
               "{'align_window': 1.0}", "self.declare_parameter('seed', 0)"]
    assert [t for t in planted if not any(p.search(t) for p in patterns)] == []


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
    if option.type is float and not isinstance(option.default, list):
        return float(Fraction(text)) == pytest.approx(option.default)
    value = yaml.safe_load(text)
    return (value if value is not None else '') == option.default


def test_the_docs_parameter_table_agrees_with_the_declarations():
    table = _docs_table()
    declared = {**OPTIONS, **NODE_PARAMETERS}
    assert set(declared) - set(table) == set()  # every node parameter is in the table
    for name, option in declared.items():
        for text in table[name]:
            assert _same(option, text), f'docs/ros2.md: {name} default {text}'


def test_the_launch_file_and_the_config_agree_with_the_declarations():
    tree = ast.parse((ROOT / 'launch' / 'benchmark.launch.py').read_text())
    defaults = next(
        ast.literal_eval(node.value)
        for node in ast.walk(tree)
        if isinstance(node, ast.Assign)
        and getattr(node.targets[0], 'id', '') == 'defaults'
    )
    declared = {**OPTIONS, **NODE_PARAMETERS}
    # a launch argument is a string: a list parameter ('engines') is spelled otherwise there; and
    # the launch writes its results into cloth_bench_results where a bare evaluator writes none
    launch = [name for name in defaults if name in declared and name != 'output_dir'
              and not isinstance(declared[name].default, list)]
    assert {'rate_hz', 'seed', 'cloth', 'primitive', 'pacing', 'live_port'} <= set(launch)
    for name in launch:
        assert _same(declared[name], defaults[name]), f'launch: {name}'
    checked = set()
    for path in sorted((ROOT / 'config').glob('*.yaml')):  # every parameter file, every section
        for section, body in (yaml.safe_load(path.read_text()) or {}).items():
            params = body.get('ros__parameters', {}) if isinstance(body, dict) else {}
            for name in (n for n in params if n in declared):
                checked.add(name)
                assert params[name] == declared[name].default, f'{path.name} {section}: {name}'
    assert {'rate_hz', 'seed', 'topic', 'change_of_phase_frame', 'pacing'} <= checked


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


# Flags not made from a declaration: argparse's own --help and the global --verbose.
UNDECLARED = {'--help', '--verbose'}


def test_every_flag_of_every_command_is_made_from_a_declaration():
    """No parser adds a flag by hand: each carries the Option it was made from."""
    missing = [
        f'{path} {action.option_strings or action.dest}'
        for path, action in _actions(build_parser())
        if not set(action.option_strings) & UNDECLARED and not hasattr(action, 'declared')
    ]
    assert missing == []


def test_help_shows_every_declared_unit_and_range():
    """`--help` of every command: each flag's help names its unit and its range."""
    count = 0
    for path, action in _actions(build_parser()):
        option = getattr(action, 'declared', None)
        if option is None or action.help in (None, argparse.SUPPRESS):
            continue  # an old name (a note on stderr) has no help of its own
        help_text = action.help.replace('%%', '%')
        if option.range_text():
            count += 1
            assert f'range {option.range_text()}' in help_text, (path, action.option_strings)
        elif option.unit:
            assert option.unit in help_text, (path, action.option_strings)
    assert count > 30
    text = build_parser()._subparsers._group_actions[0].choices['hil'].format_help()
    assert 'range [0, 3600] s; default 30' in ' '.join(text.split())  # --live-wait


def _node_parameters(context) -> dict[str, list]:
    """Return name -> [(node, descriptor, default)] of every declared option of every node."""
    from cloth_bench_ros.nodes.evaluator import Evaluator
    from cloth_bench_ros.nodes.recorder import Recorder
    from cloth_bench_ros.nodes.simulator import Simulator
    from cloth_bench_ros.nodes.trajectory_publisher import TrajectoryPublisher
    from cloth_bench_ros.paths import bundled_bag

    bag = bundled_bag('towel', 'dynamic')
    rclpy.init(args=['prog', '--ros-args', '-p', f'bag:={bag}'], context=context)
    found: dict[str, list] = {}
    for node_class in (TrajectoryPublisher, Simulator, Evaluator, Recorder):
        node = node_class(context=context)
        try:
            for name in node.list_parameters([], 0).names:
                if name in OPTIONS:
                    found.setdefault(name, []).append(
                        (node.get_name(), node.describe_parameter(name),
                         node.get_parameter(name).value)
                    )
        finally:
            node.destroy_node()
    return found


def test_every_flag_that_is_a_node_parameter_has_its_default_range_and_help(context):
    """The CLI flag and each node's ParameterDescriptor of one option say the same."""
    nodes = _node_parameters(context)
    flags = [(path, action) for path, action in _actions(build_parser())
             if getattr(action, 'declared', None) is not None
             and getattr(action, 'declared', None).name in nodes]
    both = {action.declared.name for _, action in flags}
    assert {'rate_hz', 'seed', 'cloth', 'primitive', 'pacing', 'voxel', 'live_port',
            'duration', 'change_of_phase_frame', 'align_step'} <= both
    for name in both:
        option = OPTIONS[name]
        for node, descriptor, value in nodes[name]:
            assert descriptor.description == option.help_text(), (node, name)
            assert value == option.default, (node, name)
            ranges = descriptor.floating_point_range or descriptor.integer_range
            if ranges:  # the declared range ('unset' -1 admitted below it)
                assert ranges[0].to_value == option.high, (node, name)
                assert ranges[0].from_value in (option.low, option.unset), (node, name)
        for path, action in flags:
            if action.declared is not option:
                continue  # a variant (another command's help or flag)
            assert action.default == option.check(option.default), (path, name)
            tail = option.help_text().removeprefix(option.help)
            assert action.help.replace('%%', '%').endswith(tail), (path, name)
            if option.range_text():
                assert f'range {option.range_text()}' in action.help, (path, name)


def _registered(option: Option) -> Option | None:
    """Return the declaration an action's Option was made from (options.py, command_options.py)."""
    return OPTIONS.get(option.name) or FLAGS_DECLARED.get(option.name) or COMMAND_FLAGS.get(
        option.name)


def test_every_flag_default_is_the_one_in_options_py():
    """
    Every action of every command, declared or not: its default is options.py's declared one.

    A flag declared beside its command (an `Option` in cli/), or a variant with its own `default`,
    writes a default outside the declarations.
    """
    found, checked = [], 0
    for path, action in _actions(build_parser()):
        option = getattr(action, 'declared', None)
        if action.default in (None, False, argparse.SUPPRESS) and option is None:
            continue
        checked += 1
        key = (path, '/'.join(action.option_strings) or action.dest)
        where = ' '.join(key)
        registered = option and _registered(option)
        if registered is None:
            found.append((key, f'{where}: default {action.default!r} not declared in options.py'))
        elif option.default != registered.default:
            found.append((key, f'{where}: default {option.default!r}, declared'
                          f' {registered.default!r}'))
    assert checked > 250
    assert found == []


def _fixed_declarations() -> list[tuple[str, str, str | None]]:
    """Return (file, name, default source or None) of each declare_fixed and declare_float call."""
    calls = []
    for path in sorted(PACKAGE.rglob('*.py')):
        for node in ast.walk(ast.parse(path.read_text())):
            if (isinstance(node, ast.Call) and getattr(node.func, 'id', '') in (
                    'declare_fixed', 'declare_float') and len(node.args) >= 2
                    and isinstance(node.args[1], ast.Constant)):
                default = ast.unparse(node.args[2]) if len(node.args) == 3 else None
                calls.append((path.relative_to(ROOT).as_posix(), node.args[1].value, default))
    return calls


def _is_literal(source: str) -> bool:
    try:
        ast.literal_eval(source)
    except ValueError:
        return False  # computed at start-up (the task's settle duration)
    return True


def test_every_node_parameter_is_declared_in_options_py():
    """
    A node's declare_fixed(node, name) takes the default of options.NODE_PARAMETERS[name].

    Only a default computed at start-up is written beside the node; no node writes a literal one,
    and every declared parameter is declared by a node.
    """
    calls = _fixed_declarations()
    assert len(calls) > 20
    literal = [f'{rel}: {name} = {default}' for rel, name, default in calls
               if default is not None and _is_literal(default)]
    assert literal == []
    undeclared = [f'{rel}: {name}' for rel, name, default in calls
                  if default is None and name not in NODE_PARAMETERS]
    assert undeclared == []
    assert set(NODE_PARAMETERS) == {name for _, name, default in calls if default is None}


def test_every_declaration_has_one_name():
    """A name is declared once, across the node parameters, the flags and the commands' flags."""
    names = [*OPTIONS, *FLAGS_DECLARED, *COMMAND_FLAGS]
    assert sorted({n for n in names if names.count(n) > 1}) == []
    # a node-only parameter may share a flag's name ('bag', 'output'): both are the one concept
    assert not set(NODE_PARAMETERS) & set(OPTIONS)


def test_the_declared_tasks_are_the_trajectory_primitives():
    """options.PRIMITIVES (the config layer's) names every core.trajectory.Primitive."""
    from cloth_bench_ros.core.trajectory import Primitive
    from cloth_bench_ros.options import PRIMITIVES

    assert tuple(p.value for p in Primitive) == PRIMITIVES


@pytest.mark.parametrize('old, new, dest, value', [
    (['import', 'data', '--out', 'bags'], '--output', 'output', 'bags'),
    (['import', 'data', '--output', 'bags', '--quiet'], '--no-progress', 'no_progress', True),
    (['synth', '--out', 'b'], '--output', 'output', 'b'),
    (['synth', '--quiet'], '--no-progress', 'no_progress', True),
    (['rank', 'bags', '--rates', '10,1000'], '--recommend-rate', 'rates', [10.0, 1000.0]),
    (['identify', '--params', 'mass,damping'], '--param', 'params', ['mass', 'damping']),
])
def test_an_old_flag_name_works_with_a_one_line_note(old, new, dest, value, capsys):
    """A renamed flag's old name gives the new flag's value, and says so once on stderr."""
    args = build_parser().parse_args(old)
    assert getattr(args, dest) == value
    flag = next(word for word in old if word.startswith('--') and word != '--output')
    assert capsys.readouterr().err.splitlines() == [
        f'cloth-bench: {flag} is deprecated, use {new}'
        + (' (repeated)' if flag in ('--rates', '--params') else '')
    ]
    assert '--out ' not in build_parser()._subparsers._group_actions[0].choices[
        old[0]].format_help()  # the old name is not in --help


def test_a_repeated_flag_replaces_its_declared_default():
    """A repeated flag (rank --recommend-rate) gives the values given, not the default's too."""
    parser = build_parser()
    assert parser.parse_args(['rank', 'b']).rates == FLAGS_DECLARED['rates'].default
    assert parser.parse_args(['rank', 'b', '--recommend-rate', '50',
                              '--recommend-rate', '500']).rates == [50.0, 500.0]


@pytest.mark.parametrize('argv, engines, sets', [
    (['run', '--engine', 'newton:vbd', '--engine', 'mujoco'], ['newton', 'mujoco'],
     ['newton.model=vbd']),
    (['run', '--engine', 'newton:vbd', '--set', 'newton.iterations=4'], ['newton'],
     ['newton.model=vbd', 'newton.iterations=4']),
    (['identify', '--engine', 'newton:xpbd'], 'newton', ['newton.model=xpbd']),
    (['sweep', '--engine', 'newton:vbd'], ['newton'], ['newton.model=vbd']),
])
def test_engine_model_is_one_syntax_on_every_command(argv, engines, sets):
    """--engine NAME:MODEL is --engine NAME with --set NAME.model=MODEL (rank's entrants, too)."""
    from cloth_bench_ros.cli.common import engine_models

    args = build_parser().parse_args(argv)
    engine_models(args)
    assert (args.engine, args.set) == (engines, sets)


@pytest.mark.parametrize('argv, message', [
    (['run', '--engine', 'newton:vbd', '--engine', 'newton:xpbd'], 'one model per engine'),
    (['stress', '--engine', 'newton:vbd'], 'stress takes engine names only'),
    (['run', '--engine', 'newton:'], 'no model after the colon'),
])
def test_engine_model_refused_in_one_line(argv, message, capsys):
    """Two models of one engine, a model where no --set is, or none after the colon: exit 2."""
    from cloth_bench_ros.cli import main

    assert main(argv) == 2
    assert message in capsys.readouterr().err


def test_the_docs_options_table_is_the_parsers():
    """docs/cli.md's table of every flag (default, list form, commands) is made from the parser."""
    from cloth_bench_ros.cli import options_table

    text = (ROOT / 'docs' / 'cli.md').read_text()
    start = text.index(options_table.BEGIN)
    shown = text[start:text.index(options_table.END) + len(options_table.END)]
    assert shown == options_table.markdown(), (
        'docs/cli.md: run python -m cloth_bench_ros.cli.options_table docs/cli.md')
    rows = options_table.rows()
    assert len(rows) > 100
    assert ('--trials', 'auto', 'value', 'identify, rank') in rows
    assert ('--recommend-rate', '10, 100, 1000', 'repeated', 'rank') in rows
