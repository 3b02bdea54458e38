"""The blocks of a report: tables (Markdown, HTML, CSV) and the document that holds them."""

from __future__ import annotations

from dataclasses import dataclass, field
import html
from pathlib import Path
from typing import Callable, Sequence

from cloth_bench_ros.core.table import inline_html, Table
from cloth_bench_ros.safe_io import atomic_write_text

# ("h", level, text) | ("p", text) | ("table", Table) | ("figure", Figure) | ("img", file, caption)
Block = tuple


@dataclass
class Figure:
    """A figure drawn when the report is written: draw(path) saves it (None: nothing to show)."""

    name: str  # file name in the report directory
    caption: str
    draw: Callable[[Path], 'Path | None']


def heading(level: int, text: str) -> Block:
    return ('h', level, text)


def paragraph(text: str) -> Block:
    return ('p', text)


def table_block(table: Table) -> Block:
    return ('table', table)


def figure_block(name: str, caption: str, draw: Callable[[Path], 'Path | None']) -> Block:
    return ('figure', Figure(name, caption, draw))


@dataclass
class Document:
    """A report as a list of blocks, which section builders return and `write_document` writes."""

    title: str
    blocks: list = field(default_factory=list)

    def extend(self, blocks: list) -> None:
        self.blocks.extend(blocks)

    def tables(self) -> list[Table]:
        return [b[1] for b in self.blocks if b[0] == 'table']

    def markdown(self) -> str:
        out = [f'# {self.title}', '']
        for b in self.blocks:
            if b[0] == 'h':
                out += ['#' * b[1] + ' ' + b[2], '']
            elif b[0] == 'p':
                out += [b[1], '']
            elif b[0] == 'table':
                out += [b[1].markdown(), '']
            elif b[0] == 'img':
                out += [f'![{b[2]}]({b[1]})', '', f'*{b[2]}*', '']
        return '\n'.join(out)

    def html(self) -> str:
        body = [f'<h1>{html.escape(self.title)}</h1>']
        for b in self.blocks:
            if b[0] == 'h':
                body.append(f'<h{b[1]}>{html.escape(b[2])}</h{b[1]}>')
            elif b[0] == 'p':
                body.append(f'<p>{inline_html(b[1])}</p>')
            elif b[0] == 'table':
                body.append(b[1].html())
            elif b[0] == 'img':
                body.append(
                    f'<figure><img src="{html.escape(b[1])}" alt="{html.escape(b[2])}">'
                    f'<figcaption>{inline_html(b[2])}</figcaption></figure>'
                )
        style = (
            'body{font-family:sans-serif;max-width:1200px;margin:2em auto;padding:0 1em}'
            'table{border-collapse:collapse;margin:1em 0;font-size:0.9em}'
            'th,td{border:1px solid #ccc;padding:3px 6px}td.num{text-align:right}'
            'th{background:#f0f0f0}img{max-width:100%}figcaption{font-style:italic}'
        )
        return (
            '<!DOCTYPE html>\n<html><head><meta'
            f' charset="utf-8"><title>{html.escape(self.title)}</title>'
            f'<style>{style}</style></head>\n<body>\n'
            + '\n'.join(body)
            + '\n</body></html>\n'
        )


def write_document(
    doc: Document,
    out_dir: Path,
    csv_only: Sequence[Table] = (),
    names: tuple[str, str] = ('report.md', 'report.html'),
) -> tuple[Path, Path, list[Path]]:
    """
    Draw the figures, write the CSV tables, report.md and report.html into out_dir.

    One CSV per table (and per `csv_only` table); the documents are written atomically.
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    for t in csv_only:
        t.write_csv(out_dir / f'{t.name}.csv')
    images: list[Path] = []
    blocks = []
    for b in doc.blocks:
        if b[0] == 'figure':
            path = b[1].draw(out_dir / b[1].name)
            if path is None:
                continue
            images.append(path)
            b = ('img', path.name, b[1].caption)
        elif b[0] == 'table':
            b[1].write_csv(out_dir / f'{b[1].name}.csv')
        blocks.append(b)
    doc.blocks = blocks
    md_path, html_path = out_dir / names[0], out_dir / names[1]
    atomic_write_text(md_path, doc.markdown())
    atomic_write_text(html_path, doc.html())
    return md_path, html_path, images
