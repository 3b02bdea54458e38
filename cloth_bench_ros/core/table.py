"""A named table (headers, rows, column alignment) as Markdown, HTML and CSV text."""

from __future__ import annotations

import csv
from dataclasses import dataclass
import html
import io
from pathlib import Path
import re

from cloth_bench_ros.safe_io import atomic_write_text


@dataclass
class Table:
    """A table: rendered to Markdown and HTML, and written as CSV (file stem `name`)."""

    name: str  # file stem of its CSV
    headers: list[str]
    rows: list[list[str]]
    align: str = ''  # per column: l or r

    def markdown(self) -> str:
        align = self.align or 'l' * len(self.headers)
        sep = ['---:' if a == 'r' else '---' for a in align]
        esc = lambda s: str(s).replace('|', '/')  # noqa: E731
        lines = [
            '| ' + ' | '.join(esc(h) for h in self.headers) + ' |',
            '| ' + ' | '.join(sep) + ' |',
        ]
        lines += ['| ' + ' | '.join(esc(c) for c in row) + ' |' for row in self.rows]
        return '\n'.join(lines)

    def html(self) -> str:
        align = self.align or 'l' * len(self.headers)
        head = ''.join(f'<th>{inline_html(h)}</th>' for h in self.headers)
        body = ''.join(
            '<tr>'
            + ''.join(
                f'<td class="{"num" if a == "r" else ""}">{inline_html(c)}</td>'
                for c, a in zip(row, align)
            )
            + '</tr>\n'
            for row in self.rows
        )
        return f'<table>\n<thead><tr>{head}</tr></thead>\n<tbody>\n{body}</tbody>\n</table>'

    def write_csv(self, path: Path) -> None:
        buffer = io.StringIO()
        w = csv.writer(buffer)
        w.writerow([_plain(h) for h in self.headers])
        w.writerows([[_plain(c) for c in row] for row in self.rows])
        atomic_write_text(path, buffer.getvalue())


def _plain(text) -> str:
    return str(text).replace('**', '')


def inline_html(text) -> str:
    """Text with **bold** and `code` as HTML, everything else escaped."""
    out = html.escape(str(text))
    out = re.sub(r'\*\*(.+?)\*\*', r'<b>\1</b>', out)
    return re.sub(r'`(.+?)`', r'<code>\1</code>', out)
