"""The bundle's index (issue 57): the overall verdict and the data first, then the claims table, then the cards in the
paper's order with figures shown where their text reads; names from the runs escaped in every file the bundle
writes, Markdown included (issue 59)."""

from __future__ import annotations

import json
import re
import struct
from pathlib import Path

from vbl_robust.campaigns.runner import run_campaign
from vbl_robust.detect.shipped import DetectorSpec
from vbl_robust.paper.bundle import BEGIN, END, refresh_bundle, write_bundle
from vbl_robust.paper.claim_rules import CONTRADICTED, HOLDS, TIE, Claim
from vbl_robust.paper.claims_page import (
    FIGURE_PX,
    SYNTHETIC,
    claims_html,
    paper_order,
    verdict_sentence,
    write_index,
)
from vbl_robust.scenes.generate import generate
from vbl_robust.specs.budget import Budget
from vbl_robust.specs.campaign import Block, CampaignSpec, roll_box
from vbl_robust.store.core import ResultStore

PAPER_ORDER = ["pnp-validation", "spatial-1d", "runtime-1d", "spatial-2d", "runtime-2d", "distance-profile",
               "convergence"]


def _png(path: Path, width: int, height: int) -> None:
    """A file with a PNG header of the given size (all the index reads of it)."""
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + b"\x00\x00\x00\rIHDR" + struct.pack(">II", width, height) + b"\0" * 16)


def test_cards_follow_the_papers_order_then_the_truth_runs():
    shuffled = ["spatial-2d-truth", "convergence", "zzz", "runtime-2d", "pnp-validation", "distance-profile",
                "runtime-2d-truth", "spatial-1d", "spatial-2d", "runtime-1d", "aaa"]
    assert paper_order(shuffled) == [*PAPER_ORDER, "spatial-2d-truth", "runtime-2d-truth", "aaa", "zzz"]


def _claims():
    return [Claim("spatial-1d", "claim A", "", "", HOLDS, "", 3),
            Claim("spatial-1d + spatial-2d", "(ours) claim B & more", "", "", TIE, "", 3),
            Claim("runtime-1d", "claim C", "", "", CONTRADICTED, "p = 0.01", 3)]


def test_the_index_says_the_verdict_and_the_data_first_then_the_claims_then_the_cards(tmp_path):
    for name in ("spatial-1d", "pnp-validation", "x<y>"):
        (tmp_path / name).mkdir()
    (tmp_path / "spatial-1d" / "report.html").write_text("x")
    _png(tmp_path / "spatial-1d" / "headline.png", 1265, 528)
    _png(tmp_path / "pnp-validation" / "headline.png", 704, 440)
    run = {"dataset": {"source": {"kind": "synthetic", "n": 100, "width": 1024, "height": 1024}},
           "detector": {"name": "shipped model v9", "sha256": "ab" * 32}, "code_version": "0.1.0+git.abc",
           "started_at": "2026-12-01T10:00:00+00:00", "finished_at": "2026-12-02T10:00:00+00:00"}
    for name, n in (("spatial-1d", 100), ("pnp-validation", 1000)):
        (tmp_path / name / "provenance.json").write_text(json.dumps({"runs": [run], "totals": {"images": n}}))
    claims = _claims()
    page = write_index(tmp_path, ["x<y>", "spatial-1d", "pnp-validation"], claims_html(claims, "results/paper"),
                       {"spatial-1d": "3 of 3 jobs"}, claims=claims).read_text()
    verdict, data = page.index("Verdict."), page.index(SYNTHETIC.replace("'", "&#x27;")[1:])
    table, cards = page.index('<section class="claims">'), page.index('<div class="cards">')
    assert verdict < data < table < cards  # the first screen: the verdict and the data, then the claims
    assert "Of the paper&#x27;s 2 claims: 1 holds, 1 contradicted; of our 1: 1 tie." in page
    assert "100 images per experiment (1000 for pnp-validation)" in page and "SHA-256 abababababab…" in page
    assert "2026-12-01 to 2026-12-02" in page
    # the cards in the paper's order, the unknown run last, escaped
    order = [page.index(f'<h3 id="{n}">') for n in ("pnp-validation", "spatial-1d", "x%3Cy%3E")]
    assert order == sorted(order) and "x&lt;y&gt;" in page and "x<y>" not in page
    spatial = page[order[1]:order[2]]
    assert '<a href="spatial-1d/report.html">spatial-1d</a>' in spatial and "3 of 3 jobs" in spatial
    assert 'verdict-holds">holds</span> claim A' in spatial and 'verdict-tie">tie</span> (ours) claim B &amp; more' in spatial
    assert "claim C" not in spatial and "no report yet" in page[order[2]:]
    # figures at a width where their text reads (≥ 9 px up to FIGURE_PX), never wider; a narrow window scrolls
    widths = [int(w) for w in re.findall(r'<img [^>]*width="(\d+)"', page)]
    assert widths == [704, FIGURE_PX]
    assert ".card .fig { overflow-x: auto;" in page and "max-width: none" in page
    # the footer's Markdown rendered: code spans, no raw backticks
    assert "<code>vbl_robust.paper.claims.write_claims</code>" in page and "<code>results/paper</code>" in page
    assert "`" not in re.sub(r"<script>.*?</script>", "", page, flags=re.S)
    assert "bootstrap" in page


def test_the_verdict_sentence_counts_the_papers_claims_apart_from_ours():
    assert verdict_sentence(_claims()) == "Of the paper's 2 claims: 1 holds, 1 contradicted; of our 1: 1 tie."
    assert verdict_sentence([]) == ""


EVIL = "x|<svg onload=alert(1)>"


def _evil_runs(root: Path) -> None:
    spec = CampaignSpec("evil", (Block(boxes=(roll_box(5),), methods=("random",), budgets=(Budget(max_evals=4),)),),
                        seed=1)
    with ResultStore(root / EVIL / "results.sqlite") as store:
        run_campaign(spec, list(generate(1, seed=0, width=96, height=96)), store, detector=DetectorSpec.oracle(1.0))


def _check_escaped(path: Path) -> None:
    text = path.read_text()
    assert "<svg" not in text, path
    if path.suffix == ".md":
        for line in text.splitlines():
            if EVIL.split("|")[0] + "\\|" in line:
                assert "x\\|&lt;svg onload=alert(1)&gt;" in line, line
        table = [ln for ln in text.splitlines() if ln.startswith("| experiment | jobs done")]
        if table:  # every status row has the header's number of cells
            rows = [ln for ln in text.splitlines() if ln.startswith("| ") and "jobs done" not in ln
                    and ln.count("|") - ln.count("\\|") >= 9]
            assert rows and {ln.count("|") - ln.count("\\|") for ln in rows} == {9}, rows


def test_a_run_directory_named_as_markup_is_escaped_in_every_file_written(tmp_path):
    root, out = tmp_path / "runs", tmp_path / "bundle"
    _evil_runs(root)
    repro = tmp_path / "REPRODUCTION.md"
    repro.write_text(f"# prose\n\n{BEGIN}\nold\n{END}\nafter\n")
    write_bundle(root, out, reproduction=repro)
    written = [p for p in out.rglob("*") if p.is_file() and p.suffix in (".md", ".html")] + [repro]
    assert {p.name for p in written} >= {"status.md", "claims.md", "index.html", "report.html", "REPRODUCTION.md"}
    for path in written:
        _check_escaped(path)
    assert "x\\|&lt;svg onload=alert(1)&gt;" in (out / "status.md").read_text()
    assert "x\\|&lt;svg onload=alert(1)&gt;" in repro.read_text()
    assert "x|&lt;svg onload=alert(1)&gt;" in (out / "index.html").read_text()
    assert repro.read_text().startswith("# prose") and repro.read_text().endswith(f"{END}\nafter\n")

    # refreshed from the bundle alone (its provenance and packed stores): the same escaping, the experiments as
    # they were
    before = {p: p.read_bytes() for p in (out / EVIL).rglob("*") if p.is_file()}
    totals = refresh_bundle(out, repro)
    assert list(totals) == [EVIL]
    for path in (out / "status.md", out / "claims.md", out / "index.html", repro):
        _check_escaped(path)
    assert {p: p.read_bytes() for p in (out / EVIL).rglob("*") if p.is_file()} == before
    assert f"under `{out}`" in (out / "claims.md").read_text()
