"""
Compare two records of benchmarks/compare_commands.py, command by command, after normalising.

Normalised, and nothing else: the record's own folder, the repository, the interpreter and
temporary folders (as <RECORD>, <REPO>, <PYTHON>, <TMP>); dates; wall-clock and step timings (JSON,
YAML and Optuna-journal keys, CSV, Markdown, HTML and fixed-width table columns matching
TIMING_NAME or under a timing header, a real-time run's counters, durations on lines of timing,
the load average) and the verdicts drawn from them (a deadline met, rank's recommendation);
Optuna's random worker ids; progress bars. Figures are not compared (their numbers are in the
files beside them). A line with "is deprecated, use" is set apart as a deprecation note.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
import datetime
import difflib
import io
import json
import math
from pathlib import Path
import re
from typing import Any, Iterator

import numpy as np
import yaml

DEPRECATION = 'is deprecated, use'
MASK = '<t>'
# JSON keys, CSV and table columns whose values are wall-clock or step timings (whole subtree),
# verdicts on them (meets_deadline, rank's recommendation), Optuna's dates and random worker ids;
# a name is lower-cased, spaces and dashes as _, before matching
TIMING_NAME = re.compile(
    r'^(step_time|step_times|step_(mean|max|min|p\d+)|latency|send_lag|loadavg|load_avg|cpu_busy'
    r'|cpu_steal|cpu_s|real_time_factor|rtf|deadline_misses|p50|p99|p999|compute_s/s|date'
    r'|(due|sent|received)_ns|lat_p[\d.]+|lat_max|load_/_cores|skipped_targets|cd_realtime'
    r'|meets_deadline|recommendation|datetime|worker_id|seconds)(_\w*)?$')
WALL_NAME = re.compile(r'(^|_)(wall|elapsed)(_|$)')
# a real-time run's record (a dict with one of these keys): its counters follow the wall clock
REALTIME_RECORD = frozenset({'realtime', 'latency_p99'})
REALTIME_COUNTS = frozenset({'skipped', 'lost', 'stepped', 'states', 'sent', 'realtime'})
# a text table's header over timing columns (masked in the rows under it), and those columns
TIMING_HEADER = re.compile(r'\bstep mean\b|\bp50\b.*\bp99\b')
SECONDS_HEADER = re.compile(r'^run +settings +s +hang mm')
TIMING_COLUMN = frozenset({'step', 'lat', 'p50', 'p99', 'wall', 'elapsed'})
RESULT_COLUMN = frozenset({'status', 'cd', 'hd', 'cd_d', 'hd_d', 'l_s', '(m)', 'lockstep'})
DATE = re.compile(r'\d{4}-\d{2}-\d{2}([T _]\d{2}[:\-]\d{2}([:\-]\d{2}(\.\d+)?)?)?')
TMP = re.compile(r'/tmp/[^\s\'",:;)\]}]+')
# "12.3 s", "4.5 ms", "1.2 min", "2 core-min" on a line that speaks of time taken
DURATION = re.compile(r'(?<![\w.])\d+(\.\d+)?(e[-+]?\d+)?\s*(s|ms|min|h|core-min|core-s)\b')
TIMING_LINE = re.compile(r'\b(took|wall|elapsed|in \d+(\.\d+)? ?s\b|per second|step time|p50|p99)',
                         re.IGNORECASE)
# phrases whose numbers or words follow the machine and its load, not the physics
VARYING = re.compile(r'\d+ start-up objects frozen|[\d.]+ h of cell compute'
                     r'|load average[a-z -]{0,40} [\d.]+ \(median[;,] [\d.]+-[\d.]+\)'
                     r'|; [\d.]+ (s|min|h);')
VERDICT = re.compile(r'(deadline )(met|not met)|( at [\d.]+ Hz \(p99 < [^)]*\): ).*$')
UNCOMPARED = frozenset({'.png', '.jpg', '.jpeg', '.gif', '.svg', '.pdf', '.mp4', '.webm'})
# Logs of other programs' own chatter (Dask's workers: heartbeats, shutdown races): not an output.
UNCOMPARED_NAMES = frozenset({'workers.log'})
SHOWN = 3  # differences shown per file


@dataclass
class Paths:
    """The absolute paths a record names, each replaced by its placeholder (longest first)."""

    replacements: list[tuple[str, str]]

    @classmethod
    def of(cls, record: Path) -> Paths:
        about = json.loads((record / 'record.json').read_text())
        pairs = [(about['record'], '<RECORD>'), (about['repo'], '<REPO>'),
                 (str(Path(about['python']).parent.parent), '<PYTHON>')]
        return cls(sorted(pairs, key=lambda p: -len(p[0])))

    def text(self, value: str) -> str:
        for path, name in self.replacements:
            value = value.replace(path, name)
        return DATE.sub('<DATE>', TMP.sub('<TMP>', value))


@dataclass
class Outcome:
    """What comparing one command found."""

    differences: list[str] = field(default_factory=list)
    deprecations: list[str] = field(default_factory=list)
    uncompared: int = 0


def normalise_lines(text: str, paths: Paths, deprecations: list[str],
                    timings: bool = True) -> list[str]:
    """Return the lines of a text output with paths, dates, timings and progress bars masked."""
    if not timings:  # a help text: its defaults and ranges are all to compare
        return [paths.text(line) for line in text.split('\n') if DEPRECATION not in line]
    lines = []
    previous = ''
    spans: Spans | None = None  # a fixed-width table's columns
    cells: set[int] = set()  # a Markdown table's timing columns
    for raw in text.replace('\r\n', '\n').split('\n'):
        line = paths.text(raw.rsplit('\r', 1)[-1])  # a progress bar redraws with \r
        if DEPRECATION in line:
            deprecations.append(line.strip())
            continue
        if line.startswith('|'):
            row = line.split('|')
            if not previous.startswith('|'):  # a table's header
                cells = {i for i, cell in enumerate(row) if is_timing(cell)}
            elif cells and not set(line) <= set('|-: '):
                line = '|'.join(f' {MASK} ' if i in cells else c for i, c in enumerate(row))
        elif not line.strip():
            spans, cells = None, set()
        elif (TIMING_HEADER.search(line) or SECONDS_HEADER.search(line)) and not re.search(
                r'(^|\s)[-+]?\.?\d', line):
            spans = _header_spans(line)
        elif spans is not None and re.search(r'[:;]', line):
            spans = None  # the table's legend
        elif spans is not None and not set(line.strip()) <= set('-=+| '):
            line = _mask_columns(line, spans)
        previous = line
        line = mask_timing_phrases(line).rstrip()
        lines.append(re.sub(r'\s+', ' ', line) if MASK in line else line)  # widths vary
    return lines


def html_rows(text: str) -> str:
    """Write each HTML table row as a Markdown one, so its timing columns are found alike."""
    lines = []
    for line in text.split('\n'):
        cells = re.findall(r'<t[hd](?:\s[^>]*)?>(.*?)</t[hd]>', line)
        if cells:
            lines += [''] if '<th' in line else []  # a new table starts
            lines.append('| ' + ' | '.join(cells) + ' |')
        elif not re.fullmatch(r'\s*(</?(table|thead|tbody|tfoot)(\s[^>]*)?>\s*)+', line):
            lines.append(line)  # a line between a table's rows is only its structure
    return '\n'.join(lines)


def mask_timing_phrases(line: str) -> str:
    """Mask a timing line's durations, the load-dependent phrases, the verdicts on step times."""
    if TIMING_LINE.search(line):
        line = DURATION.sub(MASK, line)
    line = VERDICT.sub(lambda m: (m.group(1) or m.group(3)) + MASK, line)
    return VARYING.sub(lambda m: re.sub(r'\d+(\.\d+)?', MASK, m.group()), line)


Spans = tuple[int, list[tuple[int, int]], set[int]]


def _header_spans(header: str) -> Spans:
    """Where the timing columns start, result columns after that, and lone timing columns' ends."""
    words = [(m.start(), m.end(), m.group()) for m in re.finditer(r'\S+', header)]
    if SECONDS_HEADER.search(header):  # converge's: one right-aligned column of wall seconds
        return len(header) + 1000, [], {e for _, e, w in words if w == 's'}
    start = next((s for s, _, w in words if w.lower() in TIMING_COLUMN), len(header))
    return start, [(s, e) for s, e, w in words if s >= start and w.lower() in RESULT_COLUMN], set()


def _mask_columns(line: str, spans: Spans) -> str:
    """Mask the row's words from the timing columns on (but results) and in lone ones."""
    start, kept, lone_ends = spans
    out = line
    for match in reversed(list(re.finditer(r'\S+', line))):
        under_result = any(match.start() < end and begin < match.end() for begin, end in kept)
        if (match.end() > start and not under_result) or match.end() in lone_ends:
            out = out[:match.start()] + MASK.ljust(match.end() - match.start()) + out[match.end():]
    return out


def is_timing(name: str) -> bool:
    """Whether a key or column names a wall-clock or step timing."""
    name = re.sub(r'\s*\((ms|s|m)\)\s*$', '', name.strip().lower())
    name = re.sub(r'[\s-]+', '_', name.removesuffix(' ms'))
    return bool(TIMING_NAME.match(name) or WALL_NAME.search(name))


def mask_json(value: Any, paths: Paths) -> Any:
    """Return the value with timing keys masked and paths normalised, recursively."""
    if isinstance(value, dict):
        realtime = not REALTIME_RECORD.isdisjoint(value)
        return {paths.text(k) if isinstance(k, str) else k:  # keys can hold paths too
                MASK if is_timing(k) or (realtime and k in REALTIME_COUNTS)
                else mask_json(v, paths) for k, v in value.items()}
    if isinstance(value, list):
        return [mask_json(v, paths) for v in value]
    if isinstance(value, str):
        return '\n'.join(mask_timing_phrases(paths.text(line)) for line in value.split('\n'))
    if isinstance(value, (datetime.date, datetime.time)):
        return MASK  # YAML reads an unquoted date as one
    return value


def flatten(value: Any, prefix: str = '') -> Iterator[tuple[str, Any]]:
    """(JSON path, leaf value) pairs in document order."""
    if isinstance(value, dict):
        for key, item in value.items():
            yield from flatten(item, f'{prefix}.{key}')
        if not value:
            yield prefix, {}
    elif isinstance(value, list):
        for i, item in enumerate(value):
            yield from flatten(item, f'{prefix}[{i}]')
        if not value:
            yield prefix, []
    else:
        yield prefix, value


def _same_leaf(a: Any, b: Any) -> bool:
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return type(a) is type(b) and a == b


def diff_json(old: Any, new: Any) -> list[str]:
    """Return the JSON paths whose values differ (or exist on one side only)."""
    left, right = dict(flatten(old)), dict(flatten(new))
    found = []
    for key in list(left) + [k for k in right if k not in left]:
        if key not in right or key not in left or not _same_leaf(left[key], right[key]):
            found.append(f'{key or "."}: {left.get(key, "<absent>")!r} -> '
                         f'{right.get(key, "<absent>")!r}')
    return found


def diff_lines(old: list[str], new: list[str]) -> list[str]:
    """Return the differing lines, as '-old' / '+new'."""
    if old == new:
        return []
    changed = [d for d in difflib.unified_diff(old, new, lineterm='', n=0)
               if d[:1] in '+-' and not d.startswith(('+++', '---'))]
    return changed or ['(line endings)']


def load_json(path: Path, paths: Paths) -> Any:
    """Read a JSON, JSON Lines or YAML file, masked."""
    if path.suffix in ('.yaml', '.yml'):
        return mask_json(yaml.safe_load(path.read_text()), paths)
    if path.suffix in ('.jsonl', '.journal'):  # a journal: Optuna's, one JSON per line
        return [mask_json(json.loads(line), paths)
                for line in path.read_text().splitlines() if line.strip()]
    return mask_json(json.loads(path.read_text()), paths)


def load_csv(path: Path, paths: Paths) -> list[list[str]]:
    """CSV rows with timing columns masked and paths normalised."""
    rows = list(csv.reader(io.StringIO(path.read_text())))
    if not rows:
        return rows
    timing = {i for i, name in enumerate(rows[0]) if is_timing(name)}
    return [rows[0]] + [[MASK if i in timing else paths.text(cell) for i, cell in enumerate(row)]
                        for row in rows[1:]]


def diff_npz(old: Path, new: Path) -> list[str]:
    """Arrays that differ, bit for bit (NaN equal to NaN)."""
    with np.load(old, allow_pickle=False) as a, np.load(new, allow_pickle=False) as b:
        found = [f'{k}: only in one' for k in sorted(set(a.files) ^ set(b.files))]
        for key in sorted(k for k in set(a.files) & set(b.files) if not is_timing(k)):
            x, y = a[key], b[key]
            if x.shape != y.shape or x.dtype != y.dtype:
                found.append(f'{key}: {x.dtype}{x.shape} -> {y.dtype}{y.shape}')
            elif not np.array_equal(x, y, equal_nan=x.dtype.kind in 'fc'):
                found.append(f'{key}: values differ')
    return found


def diff_file(old: Path, new: Path, paths: tuple[Paths, Paths], outcome: Outcome) -> list[str]:
    """One output file's differences, by its kind."""
    suffix = old.suffix.lower()
    if suffix in UNCOMPARED or old.name in UNCOMPARED_NAMES:
        outcome.uncompared += 1
        return []
    if suffix in ('.json', '.jsonl', '.journal', '.yaml', '.yml'):
        return diff_json(load_json(old, paths[0]), load_json(new, paths[1]))
    if suffix == '.csv':
        left, right = load_csv(old, paths[0]), load_csv(new, paths[1])
        return diff_lines([','.join(r) for r in left], [','.join(r) for r in right])
    if suffix == '.npz':
        return diff_npz(old, new)
    try:
        texts = old.read_text(), new.read_text()
    except UnicodeDecodeError:
        return [] if old.read_bytes() == new.read_bytes() else ['bytes differ']
    if suffix in ('.html', '.htm'):
        texts = html_rows(texts[0]), html_rows(texts[1])
    return diff_lines(normalise_lines(texts[0], paths[0], outcome.deprecations),
                      normalise_lines(texts[1], paths[1], outcome.deprecations))


def files_of(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob('*') if p.is_file()}


def compare_command(old: Path, new: Path, paths: tuple[Paths, Paths]) -> Outcome:
    """Exit code, argv, stdout, stderr and every written file of one command, old against new."""
    outcome = Outcome()
    meta = [json.loads((side / 'command.json').read_text()) for side in (old, new)]
    if meta[0]['exit_code'] != meta[1]['exit_code']:
        outcome.differences.append(f'exit code {meta[0]["exit_code"]} -> {meta[1]["exit_code"]}')
    argv = [[p.text(a) for a in m['argv']] for p, m in zip(paths, meta)]
    if argv[0] != argv[1]:
        outcome.differences.append(f'argv {argv[0]} -> {argv[1]}')
    for stream in ('stdout.txt', 'stderr.txt'):
        lines = [normalise_lines((side / stream).read_text(), p, outcome.deprecations,
                                 timings=not old.name.startswith('help_'))
                 for side, p in zip((old, new), paths)]
        outcome.differences += [f'{stream[:-4]}: {d}' for d in diff_lines(*lines)[:SHOWN * 2]]
    written = [files_of(side / 'work') for side in (old, new)]
    for name in sorted(written[0] ^ written[1]):
        outcome.differences.append(f'{name}: only in {"old" if name in written[0] else "new"}')
    for name in sorted(written[0] & written[1]):
        found = diff_file(old / 'work' / name, new / 'work' / name, paths, outcome)
        outcome.differences += [f'{name}: {d}' for d in found[:SHOWN]]
        if len(found) > SHOWN:
            outcome.differences.append(f'{name}: ... {len(found) - SHOWN} more')
    return outcome


def command_names(record: Path) -> list[str]:
    """Return the commands a record holds, in the order they ran."""
    listed = json.loads((record / 'record.json').read_text()).get('commands', [])
    present = {p.parent.name for p in record.glob('*/command.json')}
    return [n for n in listed if n in present] + sorted(present - set(listed))


def compare_records(old: Path, new: Path) -> int:
    """Print one line per command; return 1 if any command differs (help texts apart), else 0."""
    paths = (Paths.of(old), Paths.of(new))
    names = command_names(old) + [n for n in command_names(new) if n not in command_names(old)]
    differing, deprecations = 0, []
    for name in names:
        missing = [side for side in (old, new) if not (side / name / 'command.json').exists()]
        if missing:
            print(f'{name:28s} DIFFERENT: not recorded in {missing[0]}')
            differing += 1
            continue
        outcome = compare_command(old / name, new / name, paths)
        deprecations += [f'{name}: {line}' for line in dict.fromkeys(outcome.deprecations)]
        uncompared = outcome.uncompared
        note = f' ({uncompared} figures or logs not compared)' if uncompared else ''
        if not outcome.differences:
            print(f'{name:28s} same{note}')
        elif name.startswith('help_'):
            print(f'{name:28s} help text changed (not counted): {outcome.differences[0]}')
        else:
            differing += 1
            print(f'{name:28s} DIFFERENT: ' + '\n' + '\n'.join(
                f'{"":30s}{d}' for d in outcome.differences[:SHOWN * 3]))
    for line in deprecations:
        print(f'deprecated (expected after a rename): {line}')
    print(f'{len(names) - differing} of {len(names)} commands the same'
          + (f', {differing} DIFFERENT' if differing else ''))
    return 1 if differing else 0
