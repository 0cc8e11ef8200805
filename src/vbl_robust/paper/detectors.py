"""Which of the paper's findings belong to the search methods and the geometry, and which to the detector: the
claims of :mod:`.claims` computed on the same experiments run with several detectors, side by side.

Each detector's runs sit under their own root, one run directory per experiment, as ``vbl-robust reproduce EXP
--out ROOT/EXP`` writes them (or a bundle of them): same images, seeds, boxes and budgets, only the detector
changes. :func:`detectors_markdown` writes

1. **the detectors** — what each is (its design, weights, input size: the identity stored with its runs) and what
   it does on the unperturbed images of the PnP validation (the same 1000 images for each): nominal survival (the
   detector's corners through ``ippe_lm`` within ε_safe, every failure counting as a breach) overall and on far
   approaches (slant distance ≥ :data:`FAR_M`), each with its exact 95 % interval, the median corner error in
   pixels, and each detector's nominal survival against the first's by the exact McNemar test on the same images;
2. **the claims** — per claim of :data:`CLAIMS_BY_DETECTOR`, each detector's verdict (:mod:`.claims`' rules,
   with their tests) and, where the claim is about survival, the share of images no method breached at the
   largest box, paired against the first detector (exact McNemar on the images both completed);
3. **what changes** — per claim, whether its verdict is the same on every detector that measured it (a property
   of the method or the geometry) or changes with the detector (then the detector properties above say with
   what).

Everything is read from the stores; nothing is evaluated, nothing is typed by hand. A run not there, or partial,
says so (the claims' own "not run yet" / "partial: n of N images").
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import quote

import numpy as np

from ..analysis.breach import survived
from ..analysis.readoff import main_rows
from ..constants import EPS_SAFE_M
from ..report.html import esc
from ..report.markdown import esc_md
from ..stats import Paired, Rate, paired
from ..store.core import ResultStore
from .claim_rules import Claim
from .claims import claims_of

__all__ = ["CLAIMS_BY_DETECTOR", "FAR_M", "DetectorProfile", "Table", "Tables", "detector_profile", "detectors_html",
           "detectors_markdown", "detectors_tables", "largest_box_survivors"]

#: The claims compared across detectors: the two the paper's authors could not tell apart from their detector
#: (spatial-2d: GeoRobust drives survival to ≈ 0 %; the distance profile) and spatial-1d, whose tie is the other
#: finding about methods.
CLAIMS_BY_DETECTOR: tuple[str, ...] = ("spatial-1d", "spatial-2d", "distance-profile")

#: Slant distance from which an approach counts as far (m): LARD's far envelope starts about there.
FAR_M = 4000.0

PNP = "pnp-validation"


@dataclass(frozen=True)
class DetectorProfile:
    """One detector on the unperturbed images of its PnP validation run (``None`` fields: no such run)."""

    label: str
    identity: str
    nominal: Rate | None
    far: Rate | None
    corner_px_median: float | None
    survivors: tuple[str, ...]  #: sample ids that survive nominally (for the paired test)
    ids: tuple[str, ...]  #: sample ids of the run


def _describe(detector: Mapping[str, object]) -> str:
    """The stored detector identity in a few words: name, design, input size (what the store says, nothing more)."""
    parts = [str(detector.get("name") or detector.get("kind") or "?")]
    parts += [str(detector[k]) for k in ("design",) if detector.get(k)]
    if detector.get("input_size"):
        parts.append(f"input {detector['input_size']} px")
    sha = str(detector.get("sha256") or "")
    if sha:
        parts.append(f"weights {sha[:12]}")
    return ", ".join(parts)


def detector_profile(label: str, root: str | Path) -> DetectorProfile:
    """:class:`DetectorProfile` from ``root/pnp-validation`` (a run directory or a bundle's packed store)."""
    run = Path(root) / PNP
    try:
        store = ResultStore.open_existing(run)
    except FileNotFoundError:
        return DetectorProfile(label, "no PnP validation run", None, None, None, (), ())
    with store:
        camp = store.require_campaign()
        rows = [r for r in store.jobs(kind="pnp", with_trace=False) if r.measured]
    ids, alive, far, corner = [], [], [], []
    for r in sorted(rows, key=lambda r: r.sample_id):
        det = r.payload.get("errors", {}).get("detector", {}).get("ippe_lm", {})
        ok = not det.get("reason") and math.isfinite(det.get("abs_m", math.inf)) and det["abs_m"] <= EPS_SAFE_M
        ids.append(r.sample_id)
        alive.append(bool(ok))
        far.append(float(r.payload.get("slant_distance_m", math.nan)) >= FAR_M)
        px = r.payload.get("detector", {}).get("corner_error_px")
        corner.append(math.nan if px is None else float(px))
    alive_a, far_a = np.asarray(alive, bool), np.asarray(far, bool)
    finite = np.asarray(corner, float)
    finite = finite[np.isfinite(finite)]
    return DetectorProfile(
        label, _describe(camp.detector or {}), Rate(int(alive_a.sum()), len(ids)),
        Rate(int((alive_a & far_a).sum()), int(far_a.sum())),
        float(np.median(finite)) if finite.size else None,
        tuple(i for i, a in zip(ids, alive, strict=True) if a), tuple(ids))


def _paired_ids(a_ids: Sequence[str], a_yes: set[str], b_ids: Sequence[str], b_yes: set[str]) -> Paired | None:
    shared = sorted(set(a_ids) & set(b_ids))
    if not shared:
        return None
    return paired([s in a_yes for s in shared], [s in b_yes for s in shared])


def _p_text(p: Paired | None, first: str) -> str:
    if p is None:
        return "–"
    word = "tie with" if p.p_value >= 0.05 else ("more than" if p.gain > 0 else "fewer than")
    return f"{word} {first}: {p.only_a} vs {p.only_b} discordant of {p.n}, McNemar p = {p.p_value:.2g}"


def largest_box_survivors(root: str | Path, experiment: str) -> tuple[str, tuple[str, ...], tuple[str, ...]] | None:
    """(the largest box's label, the images every method completed there, those no method breached) of
    ``root/experiment``'s main search rows; None when there is no such store or no row."""
    try:
        store = ResultStore.open_existing(Path(root) / experiment)
    except FileNotFoundError:
        return None
    with store:
        if not store.holds_campaign():
            return None
        spec = store.spec()
        rows = main_rows(store, spec, with_trace=False)
    rows = [r for r in rows if r.box_level is not None and (r.budget is None or r.budget.max_seconds is None)]
    if not rows:
        return None
    top = max(r.box_level for r in rows)
    rows = [r for r in rows if r.box_level == top]
    methods = {r.method for r in rows}
    by_image: dict[str, dict[str, bool]] = {}
    for r in rows:
        by_image.setdefault(r.sample_id, {})[r.method] = survived(r, spec.settings.eps_safe_m)
    done = sorted(s for s, m in by_image.items() if set(m) == methods)
    alive = tuple(s for s in done if all(by_image[s].values()))
    return rows[0].box_label or "", tuple(done), alive


@dataclass(frozen=True)
class Table:
    """A titled table: its lead sentence, header and rows of plain text (escaped by whoever renders them)."""

    title: str
    lead: str
    head: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]


def detectors_tables(roots: Mapping[str, str | Path]) -> tuple[Table, Table, tuple[str, ...]]:
    """The detectors' table, the claims' table and each claim's numbers per detector (the module docstring) for
    ``roots`` (label → root directory of one detector's runs; the first is the reference)."""
    if not roots:
        raise ValueError("no detector roots given")
    labels = list(roots)
    first = labels[0]
    profiles = {k: detector_profile(k, roots[k]) for k in labels}
    ref = profiles[first]
    rows = []
    for k in labels:
        p = profiles[k]
        against = "reference" if k == first else _p_text(
            _paired_ids(p.ids, set(p.survivors), ref.ids, set(ref.survivors)), first)
        rows.append((k, p.identity, p.nominal.text(1, percent=False) if p.nominal else "–",
                     p.far.text(1, percent=False) if p.far else "–",
                     "–" if p.corner_px_median is None else f"{p.corner_px_median:.2f}", against))
    detectors = Table(
        "The detectors",
        "On the unperturbed images of the PnP validation (the same images for each): nominal survival = the "
        f"detector's corners through ippe_lm within ε_safe = {EPS_SAFE_M:g} m (a failure counts as a breach); "
        f"far: slant distance ≥ {FAR_M:g} m; each rate with its exact 95 % interval.",
        ("detector", "what it is", "nominal survival %", "far approaches %", "median corner error (px)",
         f"nominal survivors against {first}"), tuple(rows))
    claims = {k: {c.experiment: c for c in claims_of(roots[k])} for k in labels}
    rows, details = [], []
    for name in CLAIMS_BY_DETECTOR:
        got: dict[str, Claim] = {k: claims[k][name] for k in labels if name in claims[k]}
        boxes = {k: largest_box_survivors(roots[k], name) for k in labels}
        cells = []
        for k in labels:
            c = got.get(k)
            cell = c.verdict if c else "–"
            b = boxes[k]
            if b is not None and b[1]:
                cell += f"; {b[0]}: {Rate(len(b[2]), len(b[1])).text(1)} of {len(b[1])} images survive every method"
                if k != first and boxes[first] is not None:
                    cell += "; " + _p_text(_paired_ids(b[1], set(b[2]), boxes[first][1], set(boxes[first][2])),
                                           first)
            cells.append(cell)
        rows.append((name, *cells, _across(got)))
        details += [f"{name}, {k} ({c.images} images): {c.ours} — {c.reason}" for k, c in got.items()]
    table = Table(
        "The claims on each detector",
        "Per claim, each detector's verdict by the claims' own rules and the share of images no method breached at "
        f"the largest box (exact 95 % interval), paired against {first} on the images both completed (exact "
        "McNemar).", ("claim", *labels, "on every detector"), tuple(rows))
    return detectors, table, tuple(details)


Tables = tuple[Table, Table, tuple[str, ...]]  #: what :func:`detectors_tables` returns


def detectors_markdown(roots: Mapping[str, str | Path], tables: Tables | None = None) -> str:
    """:func:`detectors_tables` of ``roots`` (or ``tables``, computed already) as Markdown (every cell escaped)."""
    detectors, claims, details = tables or detectors_tables(roots)
    lines: list[str] = []
    for t in (detectors, claims):
        lines += [f"### {esc_md(t.title)}", "", esc_md(t.lead), "",
                  "| " + " | ".join(map(esc_md, t.head)) + " |", "|" + "---|" * len(t.head),
                  *("| " + " | ".join(map(esc_md, r)) + " |" for r in t.rows), ""]
    lines += ["### Each claim's numbers per detector", "", *(f"- {esc_md(d)}" for d in details), ""]
    return "\n".join(lines)


def detectors_html(roots: Mapping[str, str | Path], page_dir: str | Path | None = None,
                   tables: Tables | None = None) -> str:
    """:func:`detectors_tables` of ``roots`` (or ``tables``, computed already) as an HTML ``<section>`` (every text
    escaped) for a page in ``page_dir``: it links each other detector's own index (``ROOT/index.html``, a bundle's)
    that lies under ``page_dir``."""
    detectors, claims, details = tables or detectors_tables(roots)
    parts = [f'<section id="detectors"><h2>The claims on {len(roots)} detectors</h2>']
    links = []
    if page_dir is not None:
        base = Path(page_dir).resolve()
        for label, root in roots.items():
            index = (Path(root) / "index.html").resolve()
            if index.is_file() and index.parent != base and index.is_relative_to(base):
                href = "/".join(quote(part) for part in index.relative_to(base).parts)
                links.append(f'<a href="{esc(href)}">{esc(label)}</a>')
    if links:
        parts.append(f"<p>Each detector's own runs, reports and claims: {', '.join(links)}.</p>")
    for t in (detectors, claims):  # class l: left-aligned cells that wrap (the report's table style)
        parts += [f"<h3>{esc(t.title)}</h3><p>{esc(t.lead)}</p><table><tr>",
                  *(f'<th class="l">{esc(h)}</th>' for h in t.head), "</tr>",
                  *("<tr>" + "".join(f'<td class="l">{esc(c)}</td>' for c in r) + "</tr>" for r in t.rows),
                  "</table>"]
    parts += ["<details><summary>Each claim's numbers per detector</summary><ul>",
              *(f"<li>{esc(d)}</li>" for d in details), "</ul></details></section>"]
    return "".join(parts)


def _across(got: Mapping[str, Claim]) -> str:
    """Whether a claim's verdict is the same on every detector that measured it."""
    measured = {k: c.verdict for k, c in got.items() if c.images}
    if len(measured) < 2:
        return "measured on fewer than two detectors"
    partial = [k for k, c in got.items() if c.images and " partial: " in c.reason]
    if partial:
        return f"not comparable yet: partial on {', '.join(partial)}"
    verdicts = set(measured.values())
    if len(verdicts) == 1:
        return f"the same on all {len(measured)}: {next(iter(verdicts))} (a property of the method or the geometry)"
    return "changes with the detector: " + ", ".join(f"{k} {v}" for k, v in measured.items())
