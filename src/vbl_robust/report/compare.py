"""Two runs of the same experiment, seed and images paired per image — a model before and after
``vbl-robust harden`` (``vbl-robust report BEFORE --compare AFTER``).

Read from the two stores, nothing evaluated. An image *survives* a (method, box) when the worst error found is
≤ ε_safe; the union "any of them" survives a box when no method found a breach there (on the images every method
of both runs completed). Per method and box: survival before and after on the images both runs completed, the
images only one run survives — *fixed* (breached before, not after) and *new breaches* (the other way) — and the
exact McNemar p-value of that difference (:func:`vbl_robust.stats.paired`). Per image: the
union's changes with the worst error over the methods before and after. The union is also given per approach
envelope (far / medium / close, where the images carry one): far approaches fail more often without any
perturbation, so a change there reads differently.

:func:`paired_comparison` computes it; :func:`compare_html` draws it (survival per box before and after
overlaid, the table, the per-image changes) and :func:`vbl_robust.report.markdown.compare_markdown` prints it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..analysis.breach import survived
from ..analysis.readoff import main_rows
from ..analysis.summary import columns
from ..atomic import atomic_write
from ..specs.campaign import CampaignSpec
from ..stats import Paired, Rate, paired
from ..store.core import ResultStore
from ..store.rows import JobRow

__all__ = ["ALL", "ANY", "Change", "Comparison", "PairedLine", "check_alike", "compare_html", "line_order",
           "paired_comparison"]

#: The union of the methods.
ANY = "any of them"
#: ``PairedLine.envelope`` of a line over every image.
ALL = "all"


@dataclass(frozen=True)
class PairedLine:
    """One method (or :data:`ANY`) at one box: ``n`` images both runs completed, survival % before and after,
    images fixed and newly breached, exact McNemar p; ``envelope`` the approach envelope the line is restricted to
    (:data:`ALL`: every image)."""

    method: str
    box: str
    level: float
    n: int
    before_pct: float
    after_pct: float
    fixed: int
    new: int
    p_value: float
    envelope: str = "all"

    @property
    def before(self) -> Rate:
        """Survivors before, of n, with the exact interval."""
        return Rate(round(self.before_pct * self.n / 100.0), self.n)

    @property
    def after(self) -> Rate:
        return Rate(round(self.after_pct * self.n / 100.0), self.n)


@dataclass(frozen=True)
class Change:
    """An image whose union verdict at a box changed: the worst error over the methods before and after (metres;
    None when no method evaluated anything) and ``change`` "fixed" or "new breach"."""

    sample_id: str
    box: str
    before_m: float | None
    after_m: float | None
    change: str


@dataclass(frozen=True)
class Comparison:
    before: str
    after: str
    spec: CampaignSpec
    detectors: tuple[str, str]
    lines: tuple[PairedLine, ...]
    changes: tuple[Change, ...]


def _read(run: str | Path) -> tuple[CampaignSpec, list[JobRow], str, dict[str, str]]:
    with ResultStore.open_existing(run) as store:
        spec = store.spec()
        runs = store.runs()
        det = str(((runs[-1].provenance.detector if runs else None) or {}).get("name", "?"))
        envelopes = {sid: str(rec.envelope) for sid, rec in store.samples().items() if rec.envelope}
        return spec, main_rows(store, spec, with_trace=False), det, envelopes


def check_alike(run: str | Path, spec: CampaignSpec, rows: Sequence[JobRow], other: str | Path,
                other_spec: CampaignSpec, other_rows: Sequence[JobRow]) -> None:
    """``ValueError`` unless ``other`` is ``run``'s experiment and seed on its images (the same id at every
    image index both hold)."""
    if (other_spec.name, other_spec.seed) != (spec.name, spec.seed):
        raise ValueError(f"{other}: experiment {other_spec.name} seed {other_spec.seed}, not {spec.name} seed "
                         f"{spec.seed}")
    index = {r.sample_index: r.sample_id for r in rows}
    clash = sorted({r.sample_index for r in other_rows if index.get(r.sample_index, r.sample_id) != r.sample_id})
    if clash:
        raise ValueError(f"{other}: images {clash[:5]} differ from {run}'s (another image set)")


def paired_comparison(before: str | Path, after: str | Path) -> Comparison:
    """The comparison of the module docstring; ``ValueError`` when the runs are not the same experiment and seed,
    their images differ, or no method and box has images both runs completed."""
    spec, rows_a, det_a, envelope = _read(before)
    spec_b, rows_b, det_b, _ = _read(after)
    check_alike(before, spec, rows_a, after, spec_b, rows_b)
    with ResultStore.open_existing(before) as a, ResultStore.open_existing(after) as b:
        pixels = a.differing_pixels(b)
    if pixels:
        raise ValueError(f"{after}: the image files of {pixels[:5]} differ from those {before} read (other pixels "
                         "under the same names): no paired comparison")
    eps = spec.settings.eps_safe_m
    _, where = columns(rows_a)  # the box, and the budget where the run has several

    def index_rows(rows: Sequence[JobRow]) -> dict[tuple[str, str, str], JobRow]:
        return {(r.method, where(r), r.sample_id): r for r in rows}

    def ok(r: JobRow) -> bool:
        return survived(r, eps)

    ia, ib = index_rows(rows_a), index_rows(rows_b)
    level = {where(r): float(r.box_level or 0.0) for r in rows_a}
    keys = [k for k in dict.fromkeys((r.method, where(r)) for r in rows_a) if any(j[:2] == k for j in ib)]
    lines: list[PairedLine] = []
    for m, b in keys:
        shared = sorted(j[2] for j in ia if j[:2] == (m, b) and j in ib)
        if shared:
            a = [ok(ia[(m, b, s)]) for s in shared]
            z = [ok(ib[(m, b, s)]) for s in shared]
            lines.append(_line(m, b, level[b], a, z, paired(z, a)))
    if not lines:
        raise ValueError(f"{before} and {after}: no method and box with images both runs completed")
    changes: list[Change] = []
    for b in dict.fromkeys(b for _, b in keys):
        ms = [m for m, bb in keys if bb == b]
        shared = sorted(s for s in {j[2] for j in ia} if all((m, b, s) in ia and (m, b, s) in ib for m in ms))
        if not shared:
            continue
        a = [all(ok(ia[(m, b, s)]) for m in ms) for s in shared]
        z = [all(ok(ib[(m, b, s)]) for m in ms) for s in shared]
        if len(ms) > 1:  # one method's own line is already there
            lines.append(_line(ANY, b, level[b], a, z, paired(z, a)))
        for env in sorted({envelope[s] for s in shared if s in envelope}):
            idx = [i for i, s in enumerate(shared) if envelope.get(s) == env]
            ae, ze = [a[i] for i in idx], [z[i] for i in idx]
            lines.append(_line(ANY if len(ms) > 1 else ms[0], b, level[b], ae, ze, paired(ze, ae), env))
        for s, x, y in zip(shared, a, z, strict=True):
            if x != y:
                changes.append(Change(s, b, _worst(ia, ms, b, s), _worst(ib, ms, b, s),
                                      "fixed" if y else "new breach"))
    return Comparison(str(before), str(after), spec, (det_a, det_b), tuple(lines), tuple(changes))


def _line(method: str, box: str, level: float, a: Sequence[bool], z: Sequence[bool], c: Paired,
          envelope: str = ALL) -> PairedLine:
    return PairedLine(method, box, level, len(a), 100.0 * float(np.mean(a)), 100.0 * float(np.mean(z)),
                      c.only_a, c.only_b, c.p_value, envelope)


def _worst(rows: dict, methods: Sequence[str], box: str, sid: str) -> float | None:
    vals = [rows[(m, box, sid)].worst_m for m in methods if rows[(m, box, sid)].worst_m is not None]
    return max(vals) if vals else None


def compare_html(before: str | Path, after: str | Path, out: str | Path | None = None) -> Path:
    """Write ``compare.html`` (self-contained) and ``figures/compare_survival.png`` into ``out`` (default: the
    ``after`` run's directory); returns the HTML path."""
    import matplotlib.pyplot as plt

    from . import figures as F
    from .figure_style import style
    from .html import esc, figure_png, img, page, table

    c = paired_comparison(before, after)
    after_dir = Path(after) if Path(after).is_dir() else Path(after).parent
    out_dir = Path(out) if out is not None else after_dir
    fig = F.survival_before_after([ln for ln in c.lines if ln.envelope == ALL], title=f"{c.spec.name}: survival before and after")
    png = figure_png(fig)
    plt.close(fig)
    (out_dir / "figures").mkdir(parents=True, exist_ok=True)
    atomic_write(out_dir / "figures" / "compare_survival.png", png)
    rows = [{"method": ln.method if ln.method == ANY else style(ln.method)["label"], "box": ln.box,
             "envelope": ln.envelope, "n": ln.n,
             "before": ln.before.text(1, percent=False), "after": ln.after.text(1, percent=False),
             "gain": ln.after_pct - ln.before_pct, "fixed": ln.fixed,
             "new": ln.new, "p": f"{ln.p_value:.4f}"} for ln in sorted(c.lines, key=line_order)]
    changes = [{"sample_id": ch.sample_id, "box": ch.box, "before": ch.before_m, "after": ch.after_m,
                "change": ch.change} for ch in c.changes]
    eps = c.spec.settings.eps_safe_m
    body = [
        f"<h1>vbl-robust — before and after <small>({esc(c.spec.name)}, seed {c.spec.seed})</small></h1>",
        f"<p>Before: <b>{esc(c.detectors[0])}</b> (<code>{esc(c.before)}</code>); after: <b>{esc(c.detectors[1])}"
        f"</b> (<code>{esc(c.after)}</code>). Paired per image on the images both runs completed; ε_safe = "
        f"{eps:g} m. <i>Fixed</i>: breached before, not after; <i>new</i>: the other way; p: exact McNemar.</p>",
        img(png, "compare_survival", "Survival per box, before (dashed, open markers) and after (solid); black: "
            "the union of the methods (an image survives when no method breaches it)."),
        "<h2>Paired survival</h2>",
        table(rows, [("method", "method", None), ("box", "box", None), ("envelope", "envelope", None),
                     ("n", "images", None),
                     ("before", "survival before % [95 % CI]", esc), ("after", "survival after % [95 % CI]", esc),
                     ("gain", "change (points)", None), ("fixed", "fixed", None), ("new", "new breaches", None),
                     ("p", "p", None)], left=("method", "box", "envelope")),
        f"<h2>Images whose verdict changed (any method), {len(changes)}</h2>",
        table(changes, [("sample_id", "image", None), ("box", "box", None), ("before", "worst before (m)", None),
                        ("after", "worst after (m)", None), ("change", "change", None)],
              row_class=lambda r: "breach" if r["change"] == "new breach" else "",
              left=("sample_id", "box", "change")) if changes else "<p>None.</p>",
    ]
    path = out_dir / "compare.html"
    atomic_write(path, page(f"vbl-robust compare {c.spec.name}", "\n".join(body)))
    return path


def line_order(ln: PairedLine) -> tuple[Any, ...]:
    """Table order: each method's lines, then the union's over every image, then the union's per envelope."""
    return (ln.method == ANY, ln.envelope != ALL, ln.envelope, ln.method, ln.level, ln.box)
