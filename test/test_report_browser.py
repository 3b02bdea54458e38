"""
`cloth-bench report` opened by a real browser: headless Chromium (Debian's `chromium`).

A small sweep on the real engines, then its report, opened as a file:// page by Chromium without
network (no proxy, no resolver, background networking off, a fresh profile), driven over the
DevTools protocol on a loopback port with the `websockets` library: the page loads with no
console error and no request leaves file://, every image decodes with a non-zero size, every
number of every table equals the result it was made from (results.jsonl and each run's
summary.json) to the digits shown, and a screenshot is kept in the test's tmp directory.
"""

from __future__ import annotations

import asyncio
import base64
import json
from pathlib import Path
import re
import shutil
import subprocess
import time

from bag_fixtures import write_hanging_cloth_bag
from cloth_bench_ros.cli import main
from cloth_bench_ros.metric_choice import METRICS
from cloth_bench_ros.sweep import study as sw
import pytest

CHROMIUM = shutil.which('chromium') or shutil.which('chromium-browser')
websockets = pytest.importorskip('websockets')
pytestmark = pytest.mark.skipif(
    CHROMIUM is None,
    reason="Debian's chromium is not installed (./quickstart.sh test installs it)",
)
FLAGS = [
    '--headless',
    '--no-sandbox',
    '--disable-gpu',
    '--disable-background-networking',
    '--disable-component-update',
    '--disable-sync',
    '--no-first-run',
    '--proxy-server=127.0.0.1:9',  # a fetch that tried the network would fail, never leave
    '--host-resolver-rules=MAP * ~NOTFOUND',
    '--window-size=1280,2400',
]
ENGINE_NAMES = {'MuJoCo': 'mujoco', 'Bullet': 'bullet'}
# Report column -> (summary.json path under engines.<engine>, results.jsonl key, scale)
SUMMARY_COLUMNS = {
    'step mean ms': (('step_time', 'mean'), 'step_time_mean', 1e3),
    'step p50 ms': (('step_time', 'p50'), 'step_time_p50', 1e3),
    'step p99 ms': (('step_time', 'p99'), 'step_time_p99', 1e3),
    'step max ms': (('step_time', 'max'), 'step_time_max', 1e3),
    'latency p50 ms': (('latency', 'p50'), 'latency_p50', 1e3),
    'latency p99 ms': (('latency', 'p99'), 'latency_p99', 1e3),
    'latency max ms': (('latency', 'max'), 'latency_max', 1e3),
    'L_s (m)': (('L_s',), 'L_s', 1.0),
    'CD_d (m)': (('CD_d',), 'CD', 1.0),
    'CD (m)': (('CD_d',), 'CD', 1.0),
}


@pytest.fixture(scope='module')
def report(tmp_path_factory):
    bags = tmp_path_factory.mktemp('browser_bags')
    write_hanging_cloth_bag(bags / 'towel_dynamic')
    out = tmp_path_factory.mktemp('browser_sweep')
    cells = sw.paper_cells(['mujoco', 'bullet'], [100.0], ['towel'], ['dynamic'], [0], bags,
                           grid=(6, 8), all_metrics=True)  # every metric's table has numbers
    outcome = sw.run_sweep(cells, out, workers=1, progress=False)
    assert outcome.errors == 0
    rep = tmp_path_factory.mktemp('browser_report')
    assert main(['report', str(out), '--output', str(rep)]) == 0
    return out, rep


class DevTools:
    """The few DevTools-protocol calls the test needs, over one browser WebSocket (flat mode)."""

    def __init__(self, ws) -> None:
        self.ws, self.next_id, self.events = ws, 0, []

    async def call(self, method: str, session: str | None = None, **params):
        self.next_id += 1
        ident = self.next_id
        msg = {'id': ident, 'method': method, 'params': params}
        if session:
            msg['sessionId'] = session
        await self.ws.send(json.dumps(msg))
        while True:
            reply = json.loads(await asyncio.wait_for(self.ws.recv(), timeout=60))
            if reply.get('id') == ident:
                assert 'error' not in reply, reply
                return reply['result']
            self.events.append(reply)

    async def wait_for(self, method: str, timeout: float = 60.0) -> dict:
        for event in self.events:
            if event.get('method') == method:
                return event
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            event = json.loads(await asyncio.wait_for(self.ws.recv(), timeout=timeout))
            self.events.append(event)
            if event.get('method') == method:
                return event
        raise TimeoutError(method)


PAGE_FACTS = """JSON.stringify({
  images: [...document.images].map(i => ({src: i.getAttribute('src'), complete: i.complete,
                                          width: i.naturalWidth, height: i.naturalHeight})),
  tables: [...document.querySelectorAll('table')].map(t => ({
    head: [...t.querySelectorAll('thead th')].map(c => c.textContent.trim()),
    rows: [...t.querySelectorAll('tbody tr')].map(r =>
      [...r.querySelectorAll('td')].map(c => c.textContent.trim()))})),
})"""


async def _open(page: Path, profile: Path, shot: Path) -> tuple[dict, list]:
    proc = subprocess.Popen(
        [CHROMIUM, *FLAGS, f'--user-data-dir={profile}', '--remote-debugging-port=0',
         'about:blank'],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        port_file = profile / 'DevToolsActivePort'
        deadline = time.monotonic() + 60
        while not (port_file.is_file() and len(port_file.read_text().split()) == 2):
            assert time.monotonic() < deadline and proc.poll() is None, 'chromium did not start'
            await asyncio.sleep(0.1)
        port, path = port_file.read_text().split()
        async with websockets.connect(f'ws://127.0.0.1:{port}{path}', max_size=None) as ws:
            cdp = DevTools(ws)
            target = await cdp.call('Target.createTarget', url='about:blank')
            session = (
                await cdp.call('Target.attachToTarget', targetId=target['targetId'], flatten=True)
            )['sessionId']
            for domain in ('Page', 'Runtime', 'Log', 'Network'):
                await cdp.call(f'{domain}.enable', session)
            await cdp.call('Page.navigate', session, url=page.as_uri())
            await cdp.wait_for('Page.loadEventFired')
            facts = await cdp.call(
                'Runtime.evaluate', session, expression=PAGE_FACTS, returnByValue=True
            )
            shot.write_bytes(base64.b64decode(
                (await cdp.call('Page.captureScreenshot', session, captureBeyondViewport=True))[
                    'data'
                ]
            ))
            return json.loads(facts['result']['value']), cdp.events
    finally:
        proc.terminate()
        proc.wait(timeout=30)


def _matches(text: str, value: float) -> bool:
    """Return True if `text` is `value` to the digits it shows (3 decimals, 3 significant, ...)."""
    number = re.match(r'-?\d+(?:\.(\d+))?(?:e([-+]\d+))?', text)
    assert number, text
    decimals = len(number.group(1) or '')
    exponent = int(number.group(2) or 0)
    return abs(float(number.group(0)) - value) <= 0.5001 * 10.0 ** (exponent - decimals)


def _lookup(summary: dict, keys: tuple[str, ...]) -> float:
    value = summary
    for key in keys:
        value = value[key]
    return float(value)


def test_the_report_in_headless_chromium(report, tmp_path):
    out, rep = report
    shot = tmp_path / 'report.png'
    facts, events = asyncio.run(_open(rep / 'report.html', tmp_path / 'profile', shot))
    # No console error, no exception, no request off the machine.
    errors = [
        e for e in events
        if e.get('method') == 'Runtime.exceptionThrown'
        or (e.get('method') == 'Runtime.consoleAPICalled' and e['params']['type'] == 'error')
        or (e.get('method') == 'Log.entryAdded' and e['params']['entry']['level'] == 'error')
    ]
    assert errors == []
    urls = [e['params']['request']['url'] for e in events
            if e.get('method') == 'Network.requestWillBeSent']
    assert urls and all(u.startswith(('file://', 'data:')) for u in urls), urls
    # Every image decodes with a non-zero size; the error-on-the-cloth views are among them.
    images = facts['images']
    assert len(images) >= 5
    for image in images:
        assert image['complete'] and image['width'] > 0 and image['height'] > 0, image
    assert sum('cloth_error_' in i['src'] for i in images) == 2
    # Every table number equals what it was made from.
    rows = {r['engine']: r for r in sw.load_rows(out)}
    summaries = {
        engine: json.loads((out / row['frames_csv']).with_name('summary.json').read_text())[
            'engines'
        ][engine]
        for engine, row in rows.items()
    }
    checked = 0
    for table in facts['tables']:
        head = table['head']
        for cells in table['rows']:
            if '(ours)' in ' '.join(head):  # Table III: metric rows, an engine per column
                metric = cells[head.index('metric')]
                for label, engine in ENGINE_NAMES.items():
                    text = cells[head.index(f'{label} (ours)')]
                    key = metric.split('_')[0]
                    assert _matches(text, rows[engine][key]), (metric, label, text)
                    assert _matches(text, summaries[engine][metric]), (metric, label, text)
                    checked += 1
                continue
            if any(h.startswith('rank (') for h in head):  # every metric, ranked: one run each
                engine = ENGINE_NAMES[cells[head.index('engine')].split()[0]]
                for m in METRICS.values():
                    text, value = cells[head.index(m.name)], rows[engine].get(m.key)
                    if text != '-' and value is not None:
                        assert _matches(text, value), (m.name, engine, text)
                        checked += 1
                continue
            engine = ENGINE_NAMES[cells[head.index('engine')]]
            for column, (path, key, scale) in SUMMARY_COLUMNS.items():
                if column in head:
                    text = cells[head.index(column)]
                    assert _matches(text, rows[engine][key] * scale), (column, engine, text)
                    assert _matches(text, _lookup(summaries[engine], path) * scale), (column, text)
                    checked += 1
            if 'deadline misses' in head:
                text = cells[head.index('deadline misses')]
                row = rows[engine]
                assert text.startswith(f'{row["deadline_misses"]} / {row["latency_count"]} ')
                assert summaries[engine]['deadline_misses'] == row['deadline_misses']
                checked += 1
    assert checked >= 30
    assert shot.stat().st_size > 10_000 and shot.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
