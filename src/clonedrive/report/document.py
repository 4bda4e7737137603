"""A small document model for the write-up and its two renderings: Markdown that links the
figure PNGs beside it, and one self-contained HTML file with every figure embedded as a
``data:`` URI.

Text may carry two inline marks, ``**bold**`` and ```code```, which both renderings
understand; everything else is plain text (escaped in HTML).
"""

from __future__ import annotations

import base64
import html
import os
import re
from dataclasses import dataclass, field
from pathlib import Path


@dataclass(frozen=True)
class Paragraph:
    text: str


@dataclass(frozen=True)
class Bullets:
    items: tuple[str, ...]


@dataclass(frozen=True)
class Note:
    """A remark in place of something missing (a section's inputs, a figure)."""

    text: str


@dataclass(frozen=True)
class Table:
    headers: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]
    #: one letter per column, "l" or "r" (numbers); default: all left
    align: str = ""
    #: rows (0-based) drawn as totals (bold, a rule above)
    total_rows: tuple[int, ...] = ()


@dataclass(frozen=True)
class Figure:
    path: Path  # a PNG file
    caption: str
    max_width_px: int | None = None  # HTML: show at most this wide (default: the page width)


@dataclass(frozen=True)
class Gallery:
    """Figures shown side by side in HTML (one after the other in Markdown)."""

    figures: tuple[Figure, ...]


Block = Paragraph | Bullets | Note | Table | Figure | Gallery


@dataclass
class Section:
    title: str
    level: int = 2  # 2 = "##", 3 = "###"
    blocks: list[Block] = field(default_factory=list)

    @property
    def anchor(self) -> str:
        return re.sub(r"[^a-z0-9]+", "-", self.title.lower()).strip("-")


@dataclass
class Document:
    title: str
    intro: list[Block] = field(default_factory=list)
    sections: list[Section] = field(default_factory=list)

    def figures(self) -> list[Figure]:
        found: list[Figure] = []
        for blocks in [self.intro, *(section.blocks for section in self.sections)]:
            for block in blocks:
                if isinstance(block, Figure):
                    found.append(block)
                elif isinstance(block, Gallery):
                    found.extend(block.figures)
        return found


# --- Markdown ---------------------------------------------------------------------------------


def to_markdown(document: Document, base_dir: str | os.PathLike) -> str:
    """The document as Markdown; figure paths are written relative to ``base_dir`` (the folder
    the ``.md`` file goes into)."""
    base = Path(base_dir)
    lines = [f"# {document.title}", ""]
    for block in document.intro:
        lines += _markdown_block(block, base)
    contents = [f"- [{section.title}](#{section.anchor})" for section in document.sections
                if section.level == 2]
    if contents:
        lines += ["**Contents**", "", *contents, ""]
    for section in document.sections:
        lines += [f"{'#' * section.level} {_flat(section.title)}", ""]
        for block in section.blocks:
            lines += _markdown_block(block, base)
    return "\n".join(lines).rstrip() + "\n"


def _markdown_block(block: Block, base: Path) -> list[str]:
    if isinstance(block, Paragraph):
        return [_flat(block.text), ""]
    if isinstance(block, Note):
        return [f"> *{_flat(block.text)}*", ""]
    if isinstance(block, Bullets):
        return [*(f"- {_flat(item)}" for item in block.items), ""]
    if isinstance(block, Table):
        return _markdown_table(block)
    if isinstance(block, Figure):
        link = Path(os.path.relpath(block.path, base)).as_posix()
        return [f"![{_one_line(block.caption)}]({link})", "", f"*{_flat(block.caption)}*", ""]
    if isinstance(block, Gallery):
        lines: list[str] = []
        for figure in block.figures:
            lines += _markdown_block(figure, base)
        return lines
    raise TypeError(f"unknown block {type(block).__name__}")


def _markdown_table(table: Table) -> list[str]:
    def cells(values, bold=False):
        text = [_flat(value).replace("|", "\\|") for value in values]
        if bold:
            text = [f"**{value}**" if value else value for value in text]
        return "| " + " | ".join(text) + " |"

    align = table.align.ljust(len(table.headers), "l")
    rule = "|" + "|".join("---:" if a == "r" else "---" for a in align) + "|"
    lines = [cells(table.headers), rule]
    lines += [cells(row, bold=index in table.total_rows) for index, row in enumerate(table.rows)]
    return [*lines, ""]


def _one_line(text: str) -> str:
    return _flat(text.replace("[", "(").replace("]", ")"))


def _flat(text: str) -> str:
    """``text`` on one line, its raw HTML tags shown as text: names in it (a recording's, a
    track's) are the user's, and a newline there could start a heading, a list or a table
    row, a ``<`` a tag (outside code spans, which show it as it is)."""
    parts = _CODE_SPAN.split(" ".join(text.split()))
    return "".join(part if index % 2 else part.replace("<", "&lt;")
                   for index, part in enumerate(parts))


_CODE_SPAN = re.compile(r"(`[^`]*`)")


# --- HTML -------------------------------------------------------------------------------------

STYLE = """
body { font-family: -apple-system, "Segoe UI", Roboto, "DejaVu Sans", Helvetica, Arial,
       sans-serif; color: #1f2328; background: #fff; margin: 0; line-height: 1.5; }
main { max-width: 1100px; margin: 0 auto; padding: 24px 32px 64px; }
h1 { font-size: 2em; border-bottom: 2px solid #d0d7de; padding-bottom: .3em; }
h2 { font-size: 1.5em; border-bottom: 1px solid #d0d7de; padding-bottom: .25em;
     margin-top: 2em; }
h3 { font-size: 1.2em; margin-top: 1.6em; }
code { background: #f0f2f4; padding: .1em .35em; border-radius: 4px; font-size: 90%; }
nav { background: #f6f8fa; border: 1px solid #d0d7de; border-radius: 6px;
      padding: 8px 20px; display: inline-block; }
nav ul { margin: 6px 0; padding-left: 4px; list-style: none; }
table { border-collapse: collapse; margin: 12px 0 20px; font-size: 14px; }
th, td { border: 1px solid #d0d7de; padding: 5px 10px; vertical-align: top; }
th { background: #eef1f4; text-align: left; }
tbody tr:nth-child(even) { background: #f8f9fa; }
td.r, th.r { text-align: right; font-variant-numeric: tabular-nums; }
td.r { white-space: nowrap; }
tr.total td { font-weight: 600; border-top: 2px solid #8c959f; background: #eef4fb; }
.scroll { overflow-x: auto; }
figure { margin: 16px 0 24px; }
figure img { max-width: 100%; height: auto; border: 1px solid #e1e4e8; }
figcaption { color: #57606a; font-size: 14px; margin-top: 4px; }
.gallery { display: grid; grid-template-columns: repeat(auto-fill, minmax(480px, 1fr));
           gap: 12px 20px; }
.gallery figure { margin: 0; }
p.note { color: #6e5c00; background: #fff8c5; border-left: 4px solid #d4a72c;
         padding: 6px 12px; }
"""


def to_html(document: Document) -> str:
    """The document as one HTML page with its figures embedded (no external references)."""
    parts = ["<!DOCTYPE html>", '<html lang="en">', "<head>", '<meta charset="utf-8">',
             '<meta name="viewport" content="width=device-width, initial-scale=1">',
             f"<title>{html.escape(document.title)}</title>", f"<style>{STYLE}</style>",
             "</head>", "<body>", "<main>", f"<h1>{_inline(document.title)}</h1>"]
    parts += [_html_block(block) for block in document.intro]
    contents = [section for section in document.sections if section.level == 2]
    if contents:
        parts.append("<nav><strong>Contents</strong><ul>" + "".join(
            f'<li><a href="#{section.anchor}">{_inline(section.title)}</a></li>'
            for section in contents) + "</ul></nav>")
    for section in document.sections:
        level = section.level
        parts.append(f'<h{level} id="{section.anchor}">{_inline(section.title)}</h{level}>')
        parts += [_html_block(block) for block in section.blocks]
    parts += ["</main>", "</body>", "</html>"]
    return "\n".join(parts) + "\n"


def _html_block(block: Block) -> str:
    if isinstance(block, Paragraph):
        return f"<p>{_inline(block.text)}</p>"
    if isinstance(block, Note):
        return f'<p class="note">{_inline(block.text)}</p>'
    if isinstance(block, Bullets):
        return "<ul>" + "".join(f"<li>{_inline(item)}</li>" for item in block.items) + "</ul>"
    if isinstance(block, Table):
        return _html_table(block)
    if isinstance(block, Figure):
        return _html_figure(block)
    if isinstance(block, Gallery):
        return ('<div class="gallery">' + "".join(_html_figure(f) for f in block.figures)
                + "</div>")
    raise TypeError(f"unknown block {type(block).__name__}")


def _html_table(table: Table) -> str:
    align = table.align.ljust(len(table.headers), "l")

    def cell(tag: str, text: str, column: int) -> str:
        css = ' class="r"' if align[column] == "r" else ""
        return f"<{tag}{css}>{_inline(text)}</{tag}>"

    head = "<tr>" + "".join(cell("th", text, i) for i, text in enumerate(table.headers)) + "</tr>"
    body = []
    for index, row in enumerate(table.rows):
        css = ' class="total"' if index in table.total_rows else ""
        body.append(f"<tr{css}>" + "".join(cell("td", text, i) for i, text in enumerate(row))
                    + "</tr>")
    return (f'<div class="scroll"><table><thead>{head}</thead><tbody>{"".join(body)}'
            "</tbody></table></div>")


def _html_figure(figure: Figure) -> str:
    data = base64.b64encode(Path(figure.path).read_bytes()).decode("ascii")
    alt = html.escape(_one_line(figure.caption), quote=True)
    width = f' style="max-width: {int(figure.max_width_px)}px"' if figure.max_width_px else ""
    return (f'<figure{width}><img src="data:image/png;base64,{data}" alt="{alt}">'
            f"<figcaption>{_inline(figure.caption)}</figcaption></figure>")


def _inline(text: str) -> str:
    escaped = html.escape(text, quote=False)
    escaped = re.sub(r"`([^`]+)`", r"<code>\1</code>", escaped)
    return re.sub(r"\*\*([^*]+)\*\*", r"<strong>\1</strong>", escaped)
