"""What is written as a document: report.md and report.html from one list of blocks.

A report is a list of blocks (:class:`Heading`, :class:`Paragraph`,
:class:`Bullets`, :class:`Table`, :class:`Figure`); :func:`render_markdown` and
:func:`render_html` turn the same list into either format, so both files always
say the same thing.  Inline markup is limited to ```code``` and ``**bold**``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import html
import re

__all__ = [
    "Document",
    "Heading",
    "Paragraph",
    "Bullets",
    "Table",
    "Figure",
    "render_markdown",
    "render_html",
]


@dataclass(frozen=True)
class Heading:
    text: str
    level: int = 2

    @property
    def anchor(self):
        return re.sub(r"[^a-z0-9]+", "-", self.text.lower()).strip("-")


@dataclass(frozen=True)
class Paragraph:
    text: str


@dataclass(frozen=True)
class Bullets:
    items: tuple
    title: str = ""


@dataclass(frozen=True)
class Table:
    head: tuple
    rows: tuple
    caption: str = ""


@dataclass(frozen=True)
class Figure:
    """A figure embedded by its file names (relative to the report)."""

    png: str
    svg: str
    caption: str
    alt: str = ""


@dataclass
class Document:
    """A titled list of blocks."""

    title: str
    blocks: list = field(default_factory=list)

    def add(self, *blocks):
        self.blocks.extend(blocks)
        return self



# ---------------------------------------------------------------------------
# Markdown
# ---------------------------------------------------------------------------

def _md_cell(text):
    return str(text).replace("|", "\\|")


def render_markdown(doc):
    """The document as GitHub-flavoured Markdown."""
    out = [f"# {doc.title}", ""]
    for b in doc.blocks:
        if isinstance(b, Heading):
            out += ["#" * b.level + " " + b.text, ""]
        elif isinstance(b, Paragraph):
            out += [b.text, ""]
        elif isinstance(b, Bullets):
            if b.title:
                out += [b.title, ""]
            out += [f"- {item}" for item in b.items] + [""]
        elif isinstance(b, Table):
            if b.caption:
                out += [b.caption, ""]
            out.append("| " + " | ".join(_md_cell(h) for h in b.head) + " |")
            out.append("|" + "|".join("---" for _ in b.head) + "|")
            out += ["| " + " | ".join(_md_cell(c) for c in row) + " |" for row in b.rows]
            out.append("")
        elif isinstance(b, Figure):
            out += [f"![{b.alt or b.caption}]({b.png})", "",
                    f"*{b.caption}* (vector: [{b.svg}]({b.svg}))", ""]
        else:
            raise TypeError(f"unknown block {b!r}")
    return "\n".join(out).rstrip() + "\n"


# ---------------------------------------------------------------------------
# HTML
# ---------------------------------------------------------------------------

_CSS = """
body { font-family: system-ui, -apple-system, "Segoe UI", sans-serif; max-width: 64rem;
       margin: 2rem auto; padding: 0 1rem; line-height: 1.45; color: #222; }
h1 { font-size: 1.6rem; } h2 { font-size: 1.3rem; margin-top: 2.2rem;
     border-bottom: 1px solid #ddd; } h3 { font-size: 1.1rem; }
table { border-collapse: collapse; margin: 0.6rem 0 1rem; font-size: 0.9rem; }
th, td { border: 1px solid #ccc; padding: 0.2rem 0.55rem; }
td { text-align: right; font-variant-numeric: tabular-nums; }
td:first-child, th:first-child { text-align: left; }
th { background: #f3f3f3; }
figure { margin: 1rem 0 1.6rem; } figure img { max-width: 100%; border: 1px solid #eee; }
figcaption { font-size: 0.9rem; color: #444; }
code { background: #f4f4f4; padding: 0 0.2rem; }
"""


def _inline(text):
    """Escape, then turn `code` and **bold** into HTML."""
    s = html.escape(str(text), quote=False)
    s = re.sub(r"`([^`]+)`", r"<code>\1</code>", s)
    s = re.sub(r"\*\*([^*]+)\*\*", r"<strong>\1</strong>", s)
    return s


def render_html(doc):
    """The document as one self-contained HTML page (figures linked by relative path)."""
    out = ["<!DOCTYPE html>", '<html lang="en">', "<head>", '<meta charset="utf-8">',
           f"<title>{html.escape(doc.title)}</title>", f"<style>{_CSS}</style>", "</head>",
           "<body>", f"<h1>{html.escape(doc.title)}</h1>"]
    for b in doc.blocks:
        if isinstance(b, Heading):
            out.append(f'<h{b.level} id="{b.anchor}">{_inline(b.text)}</h{b.level}>')
        elif isinstance(b, Paragraph):
            out.append(f"<p>{_inline(b.text)}</p>")
        elif isinstance(b, Bullets):
            if b.title:
                out.append(f"<p>{_inline(b.title)}</p>")
            out.append("<ul>" + "".join(f"<li>{_inline(i)}</li>" for i in b.items) + "</ul>")
        elif isinstance(b, Table):
            if b.caption:
                out.append(f"<p>{_inline(b.caption)}</p>")
            head = "".join(f"<th>{_inline(h)}</th>" for h in b.head)
            body = "".join("<tr>" + "".join(f"<td>{_inline(c)}</td>" for c in row) + "</tr>"
                           for row in b.rows)
            out.append(f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>")
        elif isinstance(b, Figure):
            alt = html.escape(b.alt or b.caption)
            out.append(f'<figure><a href="{html.escape(b.svg)}"><img src="{html.escape(b.png)}" '
                       f'alt="{alt}"></a><figcaption>{_inline(b.caption)}</figcaption></figure>')
        else:
            raise TypeError(f"unknown block {b!r}")
    out += ["</body>", "</html>"]
    return "\n".join(out) + "\n"
