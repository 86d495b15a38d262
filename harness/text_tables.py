"""Plain tables shared by every job: aligned text for the terminal, Markdown for the
reports, and the cell formats (a rounded number, or full precision for a CSV cell)."""

from __future__ import annotations

import math

__all__ = ["fmt", "num", "text_table", "markdown_table", "titled_table"]


def fmt(x, spec):
    """A number for a table cell; 'n/a' when missing or not finite."""
    return "n/a" if x is None or not math.isfinite(x) else format(x, spec)


def text_table(head, rows):
    """Aligned text: first column left, the others right."""
    widths = [max(len(str(c)) for c in col) for col in zip(head, *rows)]
    lines = ["  ".join(str(c).rjust(w) if i else str(c).ljust(w)
                       for i, (c, w) in enumerate(zip(row, widths))).rstrip()
             for row in [head] + rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def markdown_table(head, rows):
    """A Markdown table: a header row, the separator, one line per row."""
    out = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    out += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(out)


def titled_table(head, rows, title=None, markdown=False):
    """:func:`text_table` (or :func:`markdown_table`) under its title, if one is given: a
    line of text, or a level-3 Markdown heading."""
    table = markdown_table(head, rows) if markdown else text_table(head, rows)
    if title:
        table = (f"### {title}\n\n" if markdown else f"{title}\n") + table
    return table


def num(x):
    """Full precision for a CSV cell; empty when missing or not finite."""
    return "" if x is None or (isinstance(x, float) and not math.isfinite(x)) else repr(float(x))
