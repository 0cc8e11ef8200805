"""Small HTML building blocks for a self-contained report: tables, embedded PNG figures, escaped text."""

from __future__ import annotations

import base64
import html
import io
import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from matplotlib.figure import Figure

CSS = """
body { font-family: system-ui, -apple-system, "Segoe UI", sans-serif; margin: 2em auto; max-width: 1100px;
       color: #222; line-height: 1.45; padding: 0 1em; }
h1 { border-bottom: 2px solid #1f77b4; padding-bottom: .2em; }
h2 { margin-top: 2em; border-bottom: 1px solid #ccc; }
table { border-collapse: collapse; margin: .8em 0; font-size: 13px; }
th, td { border: 1px solid #ccc; padding: 3px 8px; text-align: right; }
th { background: #f0f4f8; }
td.l, th.l { text-align: left; }
td:not(.l) { white-space: nowrap; }
tr.breach td { background: #fde8e8; }
img { max-width: 100%; border: 1px solid #eee; }
.note { background: #f7f7f7; border-left: 4px solid #1f77b4; padding: .5em 1em; }
.warn { background: #fff6e0; border-left: 4px solid #e0a000; padding: .5em 1em; }
details pre { white-space: pre-wrap; font-size: 12px; background: #f7f7f7; padding: .5em; }
figcaption { font-size: 13px; color: #444; }
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


def table(rows: Sequence[Mapping[str, Any]], columns: Sequence[Column], *, row_class: Callable[[Mapping], str] | None = None,
          left: Sequence[str] = ()) -> str:
    """An HTML table; ``columns`` = (key, header, formatter or None for :func:`fmt_num`)."""
    head = "".join(f'<th class="{"l" if k in left else ""}">{esc(h)}</th>' for k, h, _ in columns)
    body = []
    for r in rows:
        cls = f' class="{row_class(r)}"' if row_class else ""
        cells = "".join(
            f'<td class="{"l" if k in left else ""}">{(f or fmt_num)(r.get(k))}</td>' for k, _, f in columns)
        body.append(f"<tr{cls}>{cells}</tr>")
    return f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"


def figure_png(fig: Figure, dpi: int = 110) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return buf.getvalue()


def img(png: bytes, alt: str, caption: str = "") -> str:
    data = base64.b64encode(png).decode()
    cap = f"<figcaption>{caption}</figcaption>" if caption else ""
    return f'<figure><img alt="{esc(alt)}" src="data:image/png;base64,{data}">{cap}</figure>'


def page(title: str, body: str) -> str:
    return (f"<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{esc(title)}</title>"
            f"<style>{CSS}</style></head><body>\n{body}\n</body></html>\n")
