"""What a report says about the rows it could not use (:mod:`vbl_robust.campaigns.verify`): the first screen's
banner of the rows inconsistent with their own evaluations or their digests (:func:`banner_html`), and the store's
head digest in the provenance (:func:`provenance_html`), so that anyone holding the report can check the filed store
with ``vbl-robust verify RUN --head HEAD``."""

from __future__ import annotations

from ..campaigns.verify import banner_lines, screen
from ..store.schema import DIGESTS_SINCE
from .html import esc
from .rows import Context


def banner_html(ctx: Context) -> list[str]:
    """The first-screen banner: the rows found inconsistent and not used (named, up to
    :data:`~vbl_robust.campaigns.verify.LISTED`), committed rows missing; empty when the store checks clean."""
    check = screen(ctx.store, ctx.spec)
    if check.ok:
        return []
    names = {v["key"]: {"sample_id": v["sample_id"], "method": v["method"], "box": v["box_label"]}
             for v in ctx.store.job_columns() if v["key"] in check.inconsistent}
    lines = banner_lines(check, names)
    items = "".join(f"<li>{esc(line)}</li>" for line in lines[1:])
    return [f'<div class="warn banner" role="alert"><p><b>{esc(lines[0])}.</b> <code>vbl-robust verify</code> names '
            f"every finding.</p><ul>{items}</ul></div>"]


def provenance_html(ctx: Context) -> str:
    """One line of the provenance: the store's head digest (over every run's chain) and what the check found."""
    check = screen(ctx.store, ctx.spec)
    used = f"{check.rows - len(check.inconsistent)} of {check.rows} job rows consistent with their own evaluations"
    if check.head is None or not check.covered:
        return (f"<p>Content digests: none (rows written before schema {DIGESTS_SINCE}); {used} "
                "(<code>vbl-robust verify</code>).</p>")
    state = "every row matches" if check.ok else f"<b>{len(check.findings)} finding(s)</b>"
    return (f"<p>Content digest, head over {len(check.heads)} run(s) and {check.covered} rows: "
            f"<code>{esc(check.head)}</code> ({state}; {used}) — check the filed store with "
            f"<code>vbl-robust verify RUN --head {esc(check.head)}</code>.</p>")
