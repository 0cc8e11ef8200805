"""Small HTML building blocks for a report: tables (sortable when long, folded when very long), PNG figures —
embedded (:func:`img`) or linked as a file beside the page (:func:`img_file`) —, escaped text, and the page (its CSS
and the few lines of script that sort a table)."""

from __future__ import annotations

import base64
import html
import io
import math
import re
import urllib.parse
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from matplotlib.figure import Figure

#: Tables with more rows than this can be sorted by a click on a header; more than :data:`FOLD_ROWS` come folded.
SORT_ROWS = 8
FOLD_ROWS = 30
#: A text column (one of the first :data:`NOWRAP_COLUMNS`) whose cells are all at most this long is kept on one
#: line (labels such as a box or a method).
NOWRAP_CHARS = 24
NOWRAP_COLUMNS = 12
_TAG = re.compile(r"<[^>]*>")

CSS = """
body { font-family: system-ui, -apple-system, "Segoe UI", sans-serif; margin: 2em auto; max-width: 1100px;
       color: #222; line-height: 1.45; padding: 0 1em; }
h1 { border-bottom: 2px solid #1f77b4; padding-bottom: .2em; }
h2 { margin-top: 2em; border-bottom: 1px solid #ccc; }
table { border-collapse: collapse; margin: .8em 0; font-size: 13px; }
th, td { border: 1px solid #ccc; padding: 3px 6px; text-align: right; }
th { background: #f0f4f8; }
td.l, th.l { text-align: left; }
td:not(.l) { white-space: nowrap; }
tr.breach td { background: #fde8e8; }
img { max-width: 100%; border: 1px solid #eee; }
.note { background: #f7f7f7; border-left: 4px solid #1f77b4; padding: .5em 1em; }
.warn { background: #fff6e0; border-left: 4px solid #e0a000; padding: .5em 1em; }
.warn.banner { background: #fdecea; border-left-color: #c0392b; }
details pre { white-space: pre-wrap; font-size: 12px; background: #f7f7f7; padding: .5em; }
figcaption { font-size: 13px; color: #444; }
""" + "\n".join(f"tbody.nw-{j} td:nth-child({j}) {{ white-space: nowrap; }}" for j in range(1, NOWRAP_COLUMNS + 1)) + """
table.sortable th { cursor: pointer; }
table.sortable th:hover::after { content: " ⇅"; color: #888; font-size: 11px; }
table.sortable th[data-dir="asc"]::after { content: " ▲"; color: #555; font-size: 10px; }
table.sortable th[data-dir="desc"]::after { content: " ▼"; color: #555; font-size: 10px; }
table.headline { font-size: 15px; }
table.headline td, table.headline th { padding: 5px 10px; }
.legend { font-size: 13px; color: #444; }
details > summary { cursor: pointer; color: #1f4f7f; margin: .4em 0; }
.case { display: flex; flex-wrap: wrap; gap: 0 1.2em; align-items: flex-start; border-top: 1px solid #ddd;
        padding: .6em 0; }
.case figure { margin: 0; flex: 1 1 600px; max-width: 800px; min-width: 320px; }
.case .facts { flex: 1 1 300px; font-size: 14px; }
.case .facts h3 { margin: .2em 0 .4em; font-size: 16px; overflow-wrap: anywhere; }
.case .facts dl { display: grid; grid-template-columns: max-content 1fr; gap: .15em .8em; margin: 0; }
.case .facts dt { color: #555; }
.case .facts dd { margin: 0; overflow-wrap: anywhere; }
.kind-misleading { color: #b00; font-weight: 600; }
.kind-flagged { color: #a60; font-weight: 600; }
.cards { display: grid; grid-template-columns: repeat(auto-fill, minmax(440px, 1fr)); gap: 1em; }
.card { border: 1px solid #ccd; border-radius: 6px; padding: .6em .8em; background: #fcfcfe; }
.card h2 { margin: 0 0 .3em; font-size: 18px; border: 0; }
.card img { display: block; margin: .4em auto; max-height: 300px; }
.card .claim { font-size: 13px; margin: .5em 0 0; }
section.claims td { vertical-align: top; }
section.claims td:first-child { white-space: nowrap; }
section.claims dl { display: grid; grid-template-columns: max-content 1fr; gap: .2em .8em; font-size: 12px; }
section.claims dd { margin: 0; }
.verdict { display: inline-block; white-space: nowrap; padding: 0 .5em; border-radius: 4px; font-size: 13px; font-weight: 600; }
.verdict-holds { background: #dff3df; color: #135f13; }
.verdict-partly, .verdict-tie { background: #fff1cc; color: #6b4e00; }
.verdict-contradicted, .verdict-does-not-hold { background: #fde2e2; color: #8a1010; }
.verdict-not-run-yet { background: #eee; color: #555; }
.tw { max-width: 100%; overflow-x: auto; }
ul.verdicts { padding-left: 1.2em; font-size: 16px; }
ul.verdicts li { margin: .35em 0; }
.vw { padding: 0 .35em; border-radius: 3px; white-space: nowrap; }
.vw-not-safe { background: #fde2e2; color: #8a1010; }
.vw-not-shown { background: #fff1cc; color: #6b4e00; }
.vw-safe { background: #dff3df; color: #135f13; }
.vw-none { background: #eee; color: #555; }
p.audited { font-size: 14px; background: #f4f6f9; padding: .4em .8em; border-radius: 4px; }
.nominal-warn { color: #8a4b00; font-weight: 600; }
@media (max-width: 900px) {
  body { margin: 1em auto; }
  table.headline { font-size: 12px; }
  table.headline td, table.headline th { padding: 3px 5px; }
}
@media print {
  body { max-width: none; margin: 0; font-size: 11pt; }
  .tw { overflow: visible; }
  table { font-size: 9pt; }
  td:not(.l), tbody[class] td { white-space: normal !important; }
  .case, figure, tr { break-inside: avoid; }
  h2 { break-after: avoid; }
  .warn.banner, .vw, p.audited { -webkit-print-color-adjust: exact; print-color-adjust: exact; }
}
"""


#: Sorts a ``table.sortable`` by the clicked column (numbers by their ``data-v``, text otherwise); a second click
#: reverses the order.
SCRIPT = """
document.querySelectorAll("table.sortable").forEach(function (t) {
  t.querySelectorAll("thead th").forEach(function (th, i) {
    th.title = "sort by this column";
    th.addEventListener("click", function () {
      var body = t.tBodies[0], rows = Array.prototype.slice.call(body.rows);
      var dir = th.dataset.dir === "asc" ? -1 : 1;
      th.dataset.dir = dir === 1 ? "asc" : "desc";
      function key(r) { var c = r.cells[i]; return c.dataset.v !== undefined ? parseFloat(c.dataset.v) : c.textContent; }
      rows.sort(function (a, b) {
        var x = key(a), y = key(b);
        if (typeof x === "number" && typeof y === "number") { return dir * (x - y); }
        return dir * String(x).localeCompare(String(y), undefined, {numeric: true});
      });
      rows.forEach(function (r) { body.appendChild(r); });
    });
  });
});
"""


def esc(v: Any) -> str:
    return html.escape(str(v))


def fmt_num(v: Any) -> str:
    """Numbers for tables: integers as is, floats rounded to their useful digits, None/NaN as "–"."""
    if v is None:
        return "–"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "–"
        if math.isinf(v):
            return "∞" if v > 0 else "−∞"
        a = abs(v)
        return f"{v:.0f}" if a >= 1000 else f"{v:.1f}" if a >= 10 else f"{v:.2f}" if a >= 1 else f"{v:.3g}"
    return esc(v)


Column = tuple[str, str, Callable[[Any], str] | None]


def _sort_value(v: Any) -> str:
    """The ``data-v`` attribute of a cell holding a finite number (what the sorting script compares)."""
    if isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v):
        return f' data-v="{float(v)!r}"'
    return ""


def table(rows: Sequence[Mapping[str, Any]], columns: Sequence[Column], *, row_class: Callable[[Mapping], str] | None = None,
          left: Sequence[str] = (), cls: str = "", fold: str = "") -> str:
    """An HTML table; ``columns`` = (key, header, formatter or None for :func:`fmt_num`). More than
    :data:`SORT_ROWS` rows: sortable by a click on a header; more than :data:`FOLD_ROWS`: folded (``<details>``,
    its summary ``fold`` or "the table") so the page stays short; ``cls``: more classes."""
    sortable = len(rows) > SORT_ROWS
    head = "".join(f'<th class="{"l" if k in left else ""}">{esc(h)}</th>' for k, h, _ in columns)
    text = [[(f or fmt_num)(r.get(k)) for k, _, f in columns] for r in rows]
    short = [f"nw-{j + 1}" for j, (k, _, _) in enumerate(columns[:NOWRAP_COLUMNS]) if k in left
             and max((len(_TAG.sub("", line[j])) for line in text), default=0) <= NOWRAP_CHARS]
    classes = " ".join(filter(None, (cls, "sortable" if sortable else "")))
    body = []
    for r, line in zip(rows, text, strict=True):
        rc = f' class="{row_class(r)}"' if row_class else ""
        cells = "".join(f'<td class="{"l" if k in left else ""}"{_sort_value(r.get(k)) if sortable else ""}>{v}</td>'
                        for (k, _, _), v in zip(columns, line, strict=True))
        body.append(f"<tr{rc}>{cells}</tr>")
    attr = f' class="{classes}"' if classes else ""
    nowrap = f' class="{" ".join(short)}"' if short else ""
    # in a scrolling box: a wide table scrolls inside the page instead of running off it (a narrow window)
    out = f'<div class="tw"><table{attr}><thead><tr>{head}</tr></thead><tbody{nowrap}>{"".join(body)}</tbody></table></div>'

    if len(rows) > FOLD_ROWS:
        out = folded(f"{esc(fold or 'The table')} ({len(rows)} rows)", out)
    return out


def folded(summary: str, inner: str) -> str:
    """``inner`` HTML folded under the line ``summary`` (HTML, escaped by the caller)."""
    return f"<details><summary>{summary}</summary>{inner}</details>"


def figure_png(fig: Figure, dpi: int = 110, colors: int | None = None) -> bytes:
    """The figure as PNG bytes; with ``colors``, reduced to a palette of that many colours (a photograph-like
    figure, e.g. the gallery's, shrinks about 5× at 256 colours)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    if colors is None:
        return buf.getvalue()
    from PIL import Image

    small = io.BytesIO()
    # fast octree keeps small saturated marks (a figure's red crosses) that median cut merges into their background
    Image.open(buf).convert("RGB").quantize(colors=colors, method=Image.Quantize.FASTOCTREE).save(
        small, format="PNG", optimize=True)
    return small.getvalue()


def _figure(src: str, alt: str, caption: str) -> str:
    cap = f"<figcaption>{caption}</figcaption>" if caption else ""
    return f'<figure><img alt="{esc(alt)}" src="{esc(src)}">{cap}</figure>'


def img(png: bytes, alt: str, caption: str = "") -> str:
    """A ``<figure>`` holding ``png`` itself (base64): the page carries its picture wherever it is copied.
    ``caption`` is HTML, escaped by the caller."""
    return _figure(f"data:image/png;base64,{base64.b64encode(png).decode()}", alt, caption)


def img_file(path: str, alt: str, caption: str = "") -> str:
    """A ``<figure>`` showing the picture at ``path``, relative to the page with ``/`` between its parts (e.g.
    ``figures/gallery_01.png``); each part is percent-encoded, so a name can neither leave the attribute nor become
    another URL (``javascript:…``, ``//host``). ``caption`` is HTML, escaped by the caller."""
    parts = path.split("/")
    if path.startswith("/") or any(part in ("", ".", "..") for part in parts):
        raise ValueError(f"img_file: path {path!r} must be relative, below the page's directory")
    return _figure("/".join(urllib.parse.quote(part, safe="") for part in parts), alt, caption)


def page(title: str, body: str) -> str:
    script = f"<script>{SCRIPT}</script>" if re.search(r'<table class="[^"]*\bsortable\b', body) else ""
    return (f"<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\"><title>{esc(title)}</title>"
            f"<style>{CSS}</style></head><body>\n{body}\n{script}</body></html>\n")
