"""The report page as a small document model, rendered to HTML and to markdown.

The same :class:`Section` list renders to ``index.html`` (self-contained: CSS inline,
figures beside it under ``figures/`` with relative links), ``index.md`` and, tables
only, ``summary.md``, so the page and the markdown show the same tables.
"""

from __future__ import annotations

import html
import re
from collections.abc import Sequence
from dataclasses import dataclass, field

from .figures import FigureFile

__all__ = ["Table", "Section", "Animation", "render_html", "render_markdown", "render_tables_markdown"]


@dataclass
class Table:
    """A table of text cells.

    Attributes
    ----------
    title : str
    columns : list of str
        Header cells (with units, e.g. ``"t_final [s]"``).
    rows : list of list of str
        Already formatted cells, ``len(columns)`` each.
    note : str
        Shown under the table (e.g. "first 500 of 1200 rows").
    """

    title: str
    columns: list[str]
    rows: list[list[str]]
    note: str = ""


@dataclass(frozen=True)
class Animation:
    """An animation embedded in the page (:func:`rbstab.report.animate.animation_html`).

    Attributes
    ----------
    title : str
    caption : str
    html : str
        The player, frames included (self-contained; shown by ``index.html`` only).
    """

    title: str
    caption: str
    html: str


@dataclass
class Section:
    """A heading and its content, in order.

    Attributes
    ----------
    title : str
    anchor : str
        HTML id (letters, digits, ``-``).
    blocks : list
        ``str`` (a paragraph), :class:`Table`, :class:`rbstab.report.figures.FigureFile`,
        :class:`Animation`, or ``list`` of str (a bullet list).
    level : int
        2 for top-level sections, 3 below.
    """

    title: str
    anchor: str
    blocks: list = field(default_factory=list)
    level: int = 2


_CSS = """
body { font-family: system-ui, -apple-system, "Segoe UI", Roboto, sans-serif; margin: 2em auto;
       max-width: 1250px; padding: 0 1em; color: #222; line-height: 1.45; }
h1 { border-bottom: 2px solid #444; padding-bottom: .2em; }
h2 { border-bottom: 1px solid #bbb; padding-bottom: .15em; margin-top: 2em; }
.scroll { overflow-x: auto; margin: .6em 0 1.2em 0; }
table { border-collapse: collapse; font-size: 13px; }
caption { text-align: left; font-weight: 600; padding: .3em 0; }
th, td { border: 1px solid #ccc; padding: 3px 7px; text-align: right; white-space: nowrap; vertical-align: top; }
th { background: #f0f0f0; }
td:first-child, th:first-child { text-align: left; }
td.text { text-align: left; white-space: normal; min-width: 14em; }
th.text { text-align: left; }
tr:nth-child(even) td { background: #fafafa; }
.note { color: #555; font-size: 13px; }
figure { margin: 1em 0 2em 0; }
figure img { max-width: 100%; border: 1px solid #ddd; }
figcaption { font-size: 13px; color: #444; }
.files a { margin-right: .4em; }
nav ul { columns: 2; }
.failed { color: #b00; font-weight: 600; }
figure.animation .anim-buttons button { min-width: 2.6em; }
"""


def _is_text(text: str) -> bool:
    """Prose (left-aligned, wrapped) rather than a number or a vector."""
    return len(text) > 40 or (" " in text.strip() and not text.startswith(("[", "diag(")))


def _cell(text: str) -> str:
    escaped = html.escape(text)
    if text in ("failed", "error"):
        return f'<td class="failed">{escaped}</td>'
    if _is_text(text):
        return f'<td class="text">{escaped}</td>'
    return f"<td>{escaped}</td>"


def _html_table(table: Table) -> str:
    prose = [any(_is_text(row[i]) for row in table.rows) for i in range(len(table.columns))]
    head = "".join(
        (f'<th class="text">{html.escape(c)}</th>' if p else f"<th>{html.escape(c)}</th>")
        for c, p in zip(table.columns, prose)
    )
    body = "\n".join("<tr>" + "".join(_cell(c) for c in row) + "</tr>" for row in table.rows)
    note = f'<p class="note">{html.escape(table.note)}</p>' if table.note else ""
    return (
        f'<div class="scroll"><table><caption>{html.escape(table.title)}</caption>\n'
        f"<thead><tr>{head}</tr></thead>\n<tbody>\n{body}\n</tbody></table></div>{note}"
    )


def _format_name(path: str) -> str:
    """``PNG``, ``PDF``, ``SVG``: the format of a figure file, as a link's text."""
    return html.escape(path.rpartition(".")[2].upper())


def _md_path(path: str) -> str:
    return path.replace("(", "%28").replace(")", "%29").replace(" ", "%20")


def _html_block(block) -> str:
    if isinstance(block, Table):
        return _html_table(block)
    if isinstance(block, FigureFile):
        src = html.escape(block.path, quote=True)
        links = " ".join(f'<a href="{html.escape(f, quote=True)}">{_format_name(f)}</a>' for f in block.files)
        files = f' <span class="files">Files: {links}</span>' if block.files and block.files != (block.path,) else ""
        return (
            f'<figure><a href="{src}"><img src="{src}" alt="{html.escape(block.title, quote=True)}"></a>'
            f"<figcaption><b>{html.escape(block.title)}.</b> {html.escape(block.caption)}{files}</figcaption></figure>"
        )
    if isinstance(block, Animation):
        return (f'<figure class="animation">{block.html}'
                f"<figcaption><b>{html.escape(block.title)}.</b> {html.escape(block.caption)}</figcaption></figure>")
    if isinstance(block, list):
        return "<ul>" + "".join(f"<li>{html.escape(item)}</li>" for item in block) + "</ul>"
    return f"<p>{html.escape(str(block))}</p>"


def render_html(title: str, intro: Sequence[str], sections: Sequence[Section]) -> str:
    """A complete, self-contained HTML page.

    Parameters
    ----------
    title : str
        Page title and top heading.
    intro : sequence of str
        Paragraphs under the title.
    sections : sequence of Section

    Returns
    -------
    str
        HTML5 text; figures are ``<img>`` with the relative ``FigureFile.path``.
    """
    toc = "".join(
        f'<li><a href="#{s.anchor}">{html.escape(s.title)}</a></li>' for s in sections if s.level == 2
    )
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        f"<title>{html.escape(title)}</title>",
        f"<style>{_CSS}</style></head><body>",
        f"<h1>{html.escape(title)}</h1>",
        *(f"<p>{html.escape(p)}</p>" for p in intro),
        f"<nav><ul>{toc}</ul></nav>",
    ]
    for s in sections:
        parts.append(f'<h{s.level} id="{s.anchor}">{html.escape(s.title)}</h{s.level}>')
        parts.extend(_html_block(b) for b in s.blocks)
    parts.append("</body></html>")
    return "\n".join(parts) + "\n"


#: Characters of text from the inputs (run names, messages, config strings) that markdown
#: would read as HTML, a code span, emphasis or a table cell's end: written as entities
#: (``&``, ``<``, ``>``) or escaped with a backslash, so that a page shows them as text.
_MD_ESCAPES = str.maketrans({
    "&": "&amp;", "<": "&lt;", ">": "&gt;", "\\": "\\\\", "`": "\\`", "|": "\\|", "*": "\\*",
    "\n": " ", "\r": " ",
})
#: A ``]`` that would close a link or image (``](``, ``][``) or define one (``]:``); a
#: bracket alone (a vector ``[1, 2, 3]``) stays as it is.
_MD_LINK = re.compile(r"\](?=[(\[:])")


#: What markdown would read as the start of raw HTML (a tag, a comment, a declaration) or
#: as an entity: only then are ``&``, ``<``, ``>`` written as entities; elsewhere (``v <=
#: 0.001 v(0)``, ``K_r > m g L``, ``it's``) the text stays plain, as a reader of the file
#: expects.
_MD_HTML = re.compile(r"<[A-Za-z/!?]|&(#\w+|[A-Za-z]\w*);")
_MD_PLAIN_ESCAPES = str.maketrans({
    "\\": "\\\\", "`": "\\`", "|": "\\|", "*": "\\*", "\n": " ", "\r": " ",
})


def _md_escape(text: str) -> str:
    """``text`` as literal markdown text (:data:`_MD_ESCAPES`, :data:`_MD_LINK`): plain
    where it holds nothing markdown would read as HTML (:data:`_MD_HTML`)."""
    text = str(text)
    if _MD_HTML.search(text):
        return _MD_LINK.sub(r"\\]", text.translate(_MD_ESCAPES))
    text = _MD_LINK.sub(r"\\]", text.translate(_MD_PLAIN_ESCAPES))
    return "\\" + text if text.startswith(">") else text


def _md_table(table: Table) -> str:
    lines = [f"**{_md_escape(table.title)}**", ""]
    lines.append("| " + " | ".join(_md_escape(c) for c in table.columns) + " |")
    lines.append("|" + "|".join("---" for _ in table.columns) + "|")
    lines.extend("| " + " | ".join(_md_escape(c) for c in row) + " |" for row in table.rows)
    if table.note:
        lines += ["", f"_{_md_escape(table.note)}_"]
    return "\n".join(lines)


def _md_block(block) -> str:
    if isinstance(block, Table):
        return _md_table(block)
    if isinstance(block, FigureFile):
        links = " ".join(f"[{_format_name(f)}]({_md_path(f)})" for f in block.files)
        files = f" Files: {links}" if block.files and block.files != (block.path,) else ""
        return (f"![{_md_escape(block.title)}]({_md_path(block.path)})\n\n"
                f"_{_md_escape(block.title)}._ {_md_escape(block.caption)}{files}")
    if isinstance(block, Animation):
        return f"_{_md_escape(block.title)}._ {_md_escape(block.caption)} (an animation: index.html plays it)"
    if isinstance(block, list):
        return "\n".join(f"- {_md_escape(item)}" for item in block)
    return _md_escape(str(block))


def render_markdown(title: str, intro: Sequence[str], sections: Sequence[Section]) -> str:
    """The page as markdown (``index.md``): same content as :func:`render_html`, every text
    escaped (:data:`_MD_ESCAPES`): no name or message from the inputs becomes HTML or a link."""
    parts = [f"# {_md_escape(title)}", *(_md_escape(p) for p in intro)]
    for s in sections:
        parts.append(f"{'#' * s.level} {_md_escape(s.title)}")
        parts.extend(_md_block(b) for b in s.blocks)
    return "\n\n".join(parts) + "\n"


def render_tables_markdown(title: str, intro: Sequence[str], sections: Sequence[Section]) -> str:
    """Only the tables (and paragraphs) of the page, as markdown (``summary.md``)."""
    kept = [
        Section(s.title, s.anchor, [b for b in s.blocks if not isinstance(b, (FigureFile, Animation))], s.level)
        for s in sections
    ]
    kept = [s for s in kept if s.blocks]
    return render_markdown(title, intro, kept)
