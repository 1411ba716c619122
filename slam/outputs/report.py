"""``report.html``: one self-contained page of a comparison or a sweep.

Tables and figures of ``gslam compare`` (the comparison table, the
trajectories, the yaw trends and observer timelines after the paper's
Figs. 2 and 3, each variant's map) and of ``gslam ablate`` (the summary
tables and plots), in one HTML file that needs nothing else: the PNGs are
embedded as base64 data URIs, the style is inline, there is no script.
It opens in any browser, from a mail or a CI artefact, without its folder.
Under the title, where it is given, the page's provenance
(:mod:`slam.outputs.provenance`): the command line, the version, the git
commit, the input and the config's hash.
"""

from __future__ import annotations

import base64
import html
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from slam.results.atomic import write_text

_STYLE = """
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 1200px; padding: 0 1em; color: #222; }
h1 { font-size: 1.5em; } h2 { font-size: 1.2em; margin-top: 2em; border-bottom: 1px solid #ccc; }
table { border-collapse: collapse; font-size: 0.9em; margin: 1em 0; }
th, td { border: 1px solid #ccc; padding: 0.3em 0.6em; text-align: right; }
th { background: #f3f3f3; } td:first-child, th:first-child { text-align: left; }
figure { display: inline-block; margin: 0.5em; vertical-align: top; }
figure img { max-width: 100%; border: 1px solid #eee; }
figcaption { font-size: 0.85em; color: #555; }
.grid figure { max-width: 380px; }
p.note { color: #555; font-size: 0.9em; }
table.provenance th, table.provenance td { text-align: left; } table.provenance code { word-break: break-all; }
""".strip()


@dataclass
class Table:
    """A table: column headers and rows of cell texts."""

    headers: Sequence[str]
    rows: Sequence[Sequence[str]]
    caption: str = ""


@dataclass
class Figure:
    """A PNG on disk and its caption."""

    path: Path
    caption: str


@dataclass
class Section:
    """A heading and what stands under it, in order: a note, tables, figures
    (``small``: side by side, as thumbnails)."""

    heading: str
    note: str = ""
    tables: list[Table] = field(default_factory=list)
    figures: list[Figure] = field(default_factory=list)
    small: bool = False


def render(title: str, sections: Sequence[Section], intro: str = "",
           provenance: Sequence[tuple[str, str]] = ()) -> str:
    """The page: every figure that exists embedded, the ones missing left
    out; ``provenance``: (label, value) pairs shown under the title."""
    parts = [
        "<!DOCTYPE html>", '<html lang="en">', "<head>", '<meta charset="utf-8">',
        f"<title>{html.escape(title)}</title>", f"<style>\n{_STYLE}\n</style>", "</head>", "<body>",
        f"<h1>{html.escape(title)}</h1>",
    ]
    if intro:
        parts.append(f'<p class="note">{html.escape(intro)}</p>')
    if provenance:
        parts.append(_provenance(provenance))
    for section in sections:
        figures = [f for f in section.figures if f.path.is_file()]
        if not (section.tables or figures or section.note):
            continue
        parts.append(f"<h2>{html.escape(section.heading)}</h2>")
        if section.note:
            parts.append(f'<p class="note">{html.escape(section.note)}</p>')
        parts += [_table(t) for t in section.tables]
        if figures:
            parts.append('<div class="grid">' if section.small else "<div>")
            parts += [_figure(f) for f in figures]
            parts.append("</div>")
    parts += ["</body>", "</html>", ""]
    return "\n".join(parts)


def write_report(path: str | Path, title: str, sections: Sequence[Section], intro: str = "",
                 provenance: Sequence[tuple[str, str]] = ()) -> None:
    """Write the page to ``path``, atomically."""
    write_text(path, render(title, sections, intro, provenance))


def _provenance(rows: Sequence[tuple[str, str]]) -> str:
    body = "\n".join(f"<tr><th>{html.escape(label)}</th><td><code>{html.escape(value)}</code></td></tr>"
                     for label, value in rows)
    return f'<table class="provenance">\n<tbody>\n{body}\n</tbody>\n</table>'


def _table(table: Table) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in table.headers)
    body = "\n".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in row) + "</tr>" for row in table.rows)
    caption = f"<caption>{html.escape(table.caption)}</caption>" if table.caption else ""
    return f"<table>{caption}\n<thead><tr>{head}</tr></thead>\n<tbody>\n{body}\n</tbody>\n</table>"


def _figure(figure: Figure) -> str:
    data = base64.b64encode(figure.path.read_bytes()).decode("ascii")
    caption = html.escape(figure.caption)
    return (f'<figure><img src="data:image/png;base64,{data}" alt="{caption}">'
            f"<figcaption>{caption}</figcaption></figure>")
