"""The report's first screen and its worst-case gallery: breached images most severe first (misleading before
flagged only, then the larger error), capped; the predicted corners stored with each job and drawn; an older store
without them still reports; every id escaped."""

import html
import json
import re
import sqlite3
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from vbl_robust.campaigns.audit import audit_spec
from vbl_robust.campaigns.runner import run_campaign
from vbl_robust.detect.shipped import DetectorSpec
from vbl_robust.perturb.compose import Perturbation
from vbl_robust.report.build import build_report
from vbl_robust.report.evidence import WORST_CASES, worst_cases
from vbl_robust.report.html import fmt_num
from vbl_robust.specs.budget import Budget
from vbl_robust.specs.campaign import roll_contrast_box
from vbl_robust.stats import Rate
from vbl_robust.store import schema
from vbl_robust.store.core import ResultStore
from vbl_robust.store.digest import reseal
from vbl_robust.store.rows import JobRow, Points

EVIL = '<img src=x onerror=alert(1)>&"'
SOURCE = {"kind": "synthetic", "n": 3, "seed": 5, "width": 128, "height": 128}


@pytest.fixture(scope="module")
def samples():
    from vbl_robust.scenes.generate import generate

    return list(generate(3, seed=5, width=128, height=128))


@pytest.fixture(scope="module")
def run(tmp_path_factory, samples):
    """An audit where every image breaches (ε_safe = 1 m; the oracle's corners off by 0.5 px)."""
    out = tmp_path_factory.mktemp("gallery")
    spec = audit_spec(roll_contrast_box(10, (0.7, 1.4)), methods=("random",),
                      budget=Budget(max_evals=6)).with_settings(eps_safe_m=1.0)
    with ResultStore(out / "results.sqlite") as st:
        run_campaign(spec, samples, st, detector=DetectorSpec("oracle", options={"noise_px": 0.5}),
                     dataset_source=SOURCE)
    return out


def copy_store(run, to):
    """A copy of ``run``'s store in the new directory ``to``; returns a connection to the copy."""
    to.mkdir()
    src, dst = sqlite3.connect(run / "results.sqlite"), sqlite3.connect(to / "results.sqlite")
    src.backup(dst)
    src.close()
    return dst


def test_the_predicted_corners_are_stored_where_the_detector_put_them(run, samples):
    from vbl_robust.campaigns.work import build_objective

    with ResultStore.open_existing(run) as st:
        rows = {r.sample_id: r for r in st.jobs(role="main")}
        spec = st.spec()
    detector = DetectorSpec("oracle", options={"noise_px": 0.5}).build()
    for s in samples[:2]:
        r = rows[s.id]
        theta = np.array([[r.worst_x[n] for n in r.box.box.names]])
        again = build_objective(s, detector, r.box.box, spec.settings).evaluate(theta)
        assert np.allclose(np.asarray(r.worst_corners), again.keypoints[0], atol=1e-6)
        # the oracle's corners: the true ones moved by the perturbation, off by its noise
        moved = Perturbation(r.box.box).points(s.corners_2d, theta, K=s.K)[0]
        assert np.abs(np.asarray(r.worst_corners) - moved).max() < 3.0
        assert r.payload["worst"]["conf"] == pytest.approx(float(again.conf[0]))
        # L(0): one evaluation at the identity θ (roll 0, contrast 1), stored with the job
        nominal = build_objective(s, detector, r.box.box, spec.settings).evaluate(
            np.array([[0.0, 1.0]]))
        stored = r.payload["nominal"]
        assert stored["error_m"] == pytest.approx(float(nominal.loss[0])) and stored["reason"] == nominal.reason[0]
        assert np.allclose(stored["corners"], nominal.keypoints[0], atol=1e-6)


def test_the_csv_carries_each_images_nominal_error(run, tmp_path):
    import csv

    from vbl_robust.analysis.tables import export

    with ResultStore.open_existing(run) as st:
        stored = {r.sample_id: r.payload["nominal"]["error_m"] for r in st.jobs(role="main")}
        lines = list(csv.DictReader(export(st, tmp_path / "jobs.csv").open()))
    assert lines and all(float(ln["nominal_m"]) == pytest.approx(stored[ln["sample_id"]]) for ln in lines)


def test_the_first_screen_is_survival_per_box_with_its_interval(run):
    page = build_report(run).read_text()
    headings = re.findall(r"<h2[^>]*>(.*?)</h2>", page)
    assert headings[:3] == ["Safe where, and how sure", "Summary", "Worst cases: the 3 most severe of 3 breached images"]
    first = page.split("<h2", 2)[1]
    ci = Rate(0, 3).ci
    assert "survival, 95 % CI (%)" in first and f"[{ci.low:.1f}, {ci.high:.1f}]" in first
    assert "Not safe</b> on <b>±10°, c∈[0.7, 1.4]</b>: 3 of 3 images breached" in first
    assert "misleading" in first and "flagged only" in first and "breached share of Θ" in first


def test_the_gallery_draws_each_rebuilt_image_beside_its_facts(run):
    page = build_report(run).read_text()
    gallery = page.split("<h2", 4)[3]
    assert gallery.count('<div class="case">') == 3 and gallery.count("<img") == 3
    assert gallery.count("drawn (red)") == 3 and "misleading" in gallery and "θ*" in gallery
    # L(0), each corner's shift on both sides and what a pixel is worth
    with ResultStore.open_existing(run) as st:
        nominal = {r.sample_id: r.payload["nominal"]["error_m"] for r in st.jobs(role="main")}
    for sid, l0 in nominal.items():
        case = gallery[gallery.index(f"image {sid}</h3>"):]
        case = case[:case.index("</dl>")]
        assert f"<dt>unperturbed, L(0)</dt><dd>{fmt_num(l0)} m (a pose" in case
        assert "fails unperturbed" in case  # ε_safe = 1 m: every image is already above ε_safe / 2
        assert re.search(r"corner shift at θ\*</dt><dd>TR \d+\.\d, TL [\d.]+, BL [\d.]+, BR [\d.]+ px", case)
        assert re.search(r"corner shift unperturbed</dt><dd>TR \d+\.\d", case)
        assert "m per pixel (pinhole model)" in case
    pngs = sorted((run / "figures").glob("gallery_*.png"))
    assert [p.name for p in pngs] == ["gallery_01.png", "gallery_02.png", "gallery_03.png"]
    assert all(p.stat().st_size < 200_000 for p in pngs)
    # the run's headline figure (an index card's), one of its figures, never a gallery picture
    figures = {p.read_bytes() for p in (run / "figures").glob("*.png") if not p.name.startswith("gallery_")}
    assert (run / "headline.png").read_bytes() in figures


def test_a_page_without_embedding_shows_every_figure_from_its_file_beside_it(run, tmp_path):
    """build_report(embed=False), what a committed bundle writes: no base64 in the page, each <img> a relative path
    to a file of figures/ (the gallery's pictures among them), each file there shown; the default embeds them."""
    out = tmp_path / "linked"
    page = build_report(run, out, embed=False).read_text()
    assert "data:image" not in page
    shown = re.findall(r'<img alt="[^"]*" src="([^"]*)"', page)
    assert shown and len(shown) == page.count("<img")
    assert {f"figures/gallery_{i:02d}.png" for i in (1, 2, 3)} <= set(shown)
    assert sorted(shown) == sorted(p.relative_to(out).as_posix() for p in (out / "figures").glob("*.png"))
    embedded = build_report(run, tmp_path / "embedded").read_text()
    assert embedded.count('src="data:image/png;base64,') == len(shown) and 'src="figures/' not in embedded
    assert len(page) < len(embedded) / 5


def test_a_linked_figure_names_a_file_below_the_page_and_nothing_else():
    from vbl_robust.report.html import img_file

    assert 'src="figures/gallery_01.png"' in img_file("figures/gallery_01.png", "gallery_01")
    odd = img_file('figures/javascript:alert(1) "x<y>#.png', EVIL)
    assert 'src="figures/javascript%3Aalert%281%29%20%22x%3Cy%3E%23.png"' in odd and EVIL not in odd
    for bad in ("/etc/passwd", "../x.png", "figures/../../x.png", "figures//x.png", ""):
        with pytest.raises(ValueError, match="relative"):
            img_file(bad, "x")


def test_every_id_is_escaped_and_a_sample_missing_from_the_rebuilt_dataset_is_said(run, tmp_path):
    con = copy_store(run, tmp_path / "evil")
    for table in ("jobs", "samples", "contents"):
        con.execute(f"UPDATE {table} SET sample_id = ? WHERE sample_id = 'synth_s5_000002'", (EVIL,))
    with con:  # as a run on an image of that name would have committed them (else: rows changed, not used)
        reseal(con)
    con.close()
    page = build_report(tmp_path / "evil").read_text()
    assert EVIL not in page and f"image {html.escape(EVIL)}</h3>" in page
    assert "No pictures: the images cannot be rebuilt here" in page and "are not in its rebuilt dataset" in page


def test_a_corner_shift_of_a_pixel_moves_the_position_by_what_the_gallery_says(samples):
    """The gallery's geometry line, D · δ / f · (D / W) per pixel, against PnP: one near corner moved 1 px
    sideways (the near edge's width changes by 1 px) moves the position by 0.5–1.5 × that, on 1024 px images."""
    from vbl_robust.pnp.solvers import solve
    from vbl_robust.report.gallery import geometry_text, metres_per_pixel
    from vbl_robust.scenes.generate import generate

    for s in generate(4, seed=0, width=1024, height=1024):
        m, D, W, f = metres_per_pixel(s)
        p0 = solve(s.corners_2d, s.corners_3d, s.K).position[0]
        moved = s.corners_2d.copy()
        moved[2, 0] += np.sign(moved[2, 0] - moved[3, 0])  # BL outwards, away from BR
        shift = np.linalg.norm(solve(moved, s.corners_3d, s.K).position[0] - p0)
        assert 0.5 * m < shift < 1.5 * m, (s.id, m, shift)
        assert f"≈ {fmt_num(m)} m per pixel" in geometry_text(s) and f"D = {D / 1000:.1f} km" in geometry_text(s)


def test_an_old_store_without_corners_still_reports(run, tmp_path):
    old = tmp_path / "old"
    con = copy_store(run, old)
    kept = ", ".join(c for c in schema.JOB_COLUMNS if c != "worst_corners_json")
    con.executescript(f"CREATE TABLE old_jobs AS SELECT {kept} FROM jobs; DROP TABLE jobs; "
                      "ALTER TABLE old_jobs RENAME TO jobs; DROP TABLE digests;")  # a store of schema 4 has none
    con.execute(f"PRAGMA user_version = {schema.SCHEMA_VERSION - 1}")
    for rowid, payload in con.execute("SELECT rowid, payload_json FROM jobs WHERE payload_json LIKE '%nominal%'").fetchall():
        data = json.loads(payload)
        del data["nominal"]  # a store from before L(0) was stored
        con.execute("UPDATE jobs SET payload_json = ? WHERE rowid = ?", (json.dumps(data), rowid))
    con.commit()
    con.close()
    page = build_report(old).read_text()
    assert "Safe where, and how sure" in page and "not stored (a row written before schema 4" in page
    assert page.count("– (not stored: a run from before L(0) was)") == 3 and "unperturbed: L(0) = –" not in page
    assert "drawn (red)" not in page and page.count('<div class="case">') == 3


def test_a_detector_that_says_how_sure_it_is_has_its_position_sigma_in_the_gallery(run, tmp_path):
    """Issue 49: a job's worst payload keeps the corners' σ propagated to the position; the gallery says it."""
    import json

    sure = tmp_path / "sure"
    con = copy_store(run, sure)
    assert "position σ" not in build_report(run).read_text()  # the oracle gives no σ
    for rowid, payload in con.execute("SELECT rowid, payload_json FROM jobs WHERE payload_json LIKE '%worst%'").fetchall():
        data = json.loads(payload)
        data["worst"]["position_sigma_m"] = 1234.5
        con.execute("UPDATE jobs SET payload_json = ? WHERE rowid = ?", (json.dumps(data), rowid))
    with con:  # as that detector's run would have committed them (else: rows changed since committed, not used)
        reseal(con)
    con.close()
    page = build_report(sure).read_text()
    assert page.count("position σ") == 3 and "1234 m (the corners' σ through PnP)" in page


def test_a_run_whose_images_cannot_be_rebuilt_shows_the_cases_without_pictures(run, tmp_path):
    moved = tmp_path / "elsewhere"
    con = copy_store(run, moved)
    con.execute("UPDATE runs SET dataset_json = ?", ('{"source": {"kind": "lard", "csv": "/nowhere/x.csv"}}',))
    con.commit()
    con.close()
    page = build_report(moved).read_text()
    gallery = page.split("<h2", 4)[3]
    assert "No pictures: the images cannot be rebuilt here" in gallery and "<img" not in gallery
    assert gallery.count('<div class="case">') == 3 and gallery.count("drawn (red)") == 3
    # a source no one can rebuild, or a truth run's (the images of the run it checks): said without the store's
    # path (a packed store's is a temporary copy's: a committed page would change at each rebuild)
    for name, source, said in (("other", '{"source": {"kind": "camera"}}', "its dataset source {'kind': 'camera'}"),
                               ("truth", '{"source": {"kind": "truth", "run": "runs/x", "samples": ["a"]}}',
                                "a truth run grids images of the run it checks (runs/x); their pictures are in")):
        con = copy_store(run, tmp_path / name)
        con.execute("UPDATE runs SET dataset_json = ?", (source,))
        con.commit()
        con.close()
        page = build_report(tmp_path / name).read_text()
        assert html.escape(said) in page and str(tmp_path) not in page


# -- the order of the cases, on rows made by hand ------------------------------------------------------------
def _row(sid, worst, reasons_fs, level=5.0):
    from vbl_robust.space import ParameterBox
    from vbl_robust.specs.campaign import BoxSpec

    fs = [f for _, f in reasons_fs]
    return JobRow(key=f"{sid}{level}", experiment="t", kind="search", role="main", method="random", sample_id=sid,
                  sample_index=0, status="done", worst_m=worst, verdict="breach" if worst > 1000 else "no breach found",
                  worst_x={"roll_deg": 1.0}, worst_reason="" if reasons_fs[-1][0] == "" else reasons_fs[-1][0],
                  box=BoxSpec(ParameterBox({"roll_deg": (-level, level)}), f"±{level:g}°", level),
                  points=Points([[0.0]] * len(fs), fs, tuple(r for r, _ in reasons_fs)))


def test_cases_are_the_breached_images_misleading_first_then_by_error_and_capped():
    rows = [
        _row("flagged", 5000.0, [("no_detection", 5000.0)]),
        _row("safe", 300.0, [("", 300.0)]),
        _row("mis-small", 1500.0, [("", 1500.0)]),
        _row("mis-large", 9000.0, [("", 9000.0)]),
        # its worst point is a flagged failure, but a confident pose 2500 m off lies elsewhere: misleading, 2500 m
        _row("mis-hidden", 5000.0, [("", 2500.0), ("low_confidence", 5000.0)]),
        # breached at two boxes: it stands by its misleading one
        _row("two", 5000.0, [("pnp_failed", 5000.0)], level=2.0), _row("two", 1200.0, [("", 1200.0)], level=10.0),
    ]
    cases, breached = worst_cases(rows, 1000.0, 5000.0)
    assert breached == 5
    assert [c.sample_id for c in cases] == ["mis-large", "mis-hidden", "mis-small", "two", "flagged"]
    assert [c.kind for c in cases] == ["misleading"] * 4 + ["flagged"]
    hidden = cases[1]
    assert (hidden.worst_m, hidden.reason, hidden.confident_m) == (5000.0, "low_confidence", 2500.0)
    many = [_row(f"s{i:02d}", 1001.0 + i, [("", 1001.0 + i)]) for i in range(20)]
    cases, breached = worst_cases(many, 1000.0, 5000.0)
    assert breached == 20 and len(cases) == WORST_CASES
    assert [c.worst_m for c in cases] == sorted((c.worst_m for c in cases), reverse=True)


def test_a_row_read_off_a_longer_run_takes_its_corners_only_where_its_worst_point_is_the_runs():
    from vbl_robust.specs.budget import Budget as B

    corners = ((1.0, 2.0), (3.0, 4.0), (5.0, 6.0), (7.0, 8.0))
    run = _row("a", 2000.0, [("", 2000.0)]).replace(key="k", worst_corners=corners, payload={"worst": {"conf": 0.7}})
    same = run.replace(key="k@1 evals", budget=B(max_evals=1), read_from="5 s", worst_corners=None, payload=None)
    moved = same.replace(sample_id="b", worst_x={"roll_deg": 2.0})
    cases, _ = worst_cases([same, moved], 1000.0, 5000.0, stored={"k": run})
    assert [(c.sample_id, c.corners, c.conf) for c in cases] == [("a", corners, 0.7), ("b", None, None)]


def test_a_risk_runs_first_screen_gives_its_pooled_failure_probability(tmp_path, samples):
    from vbl_robust.analysis.risk import pooled_risk
    from vbl_robust.campaigns.audit import risk_spec
    from vbl_robust.specs.campaign import roll_box

    spec = risk_spec(roll_box(20), methods=("mc",), max_evals=16, guide_evals=4)
    with ResultStore(tmp_path / "results.sqlite") as st:
        run_campaign(spec, samples[:2], st, detector=DetectorSpec("oracle", options={"noise_px": 1.0}),
                     dataset_source=SOURCE)
        (p,) = pooled_risk(st.jobs(kind="risk", with_points=True))
    first = build_report(tmp_path).read_text().split("<h2", 2)[1]
    assert first.startswith(">Safe where, and how sure")
    assert f"p_fail {100 * p.p_fail:.3g} % [{100 * p.ci.low:.3g}, {100 * p.ci.high:.3g}] (mc, 95 %)" in first


def test_only_the_gallerys_pictures_load_torch_and_the_rows_are_gone_by_then(run, tmp_path):
    """A large store's rows and torch are never held at once (a 1 GB store reported within 1 GB, BENCHMARKS.md):
    nothing the report imports loads torch, no section before the gallery does, and the rows are released before
    the gallery, drawn last but shown in its place."""
    code = textwrap.dedent("""
        import sys
        import vbl_robust.cli.report
        from vbl_robust.report import build as B
        from vbl_robust.report.rows import Context
        seen = {"torch on import": "torch" in sys.modules}
        release = Context.release
        def spy(self):
            seen["torch at release"] = "torch" in sys.modules
            release(self)
            seen["rows after release"] = len(self.main) + len(self.__dict__.get("runs", ()))
        Context.release = spy
        B.build_report(sys.argv[1], sys.argv[2])
        seen["torch at the end"] = "torch" in sys.modules
        print(seen)
    """)
    out = subprocess.run([sys.executable, "-c", code, str(run), str(tmp_path)], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == str({"torch on import": False, "torch at release": False, "rows after release": 0,
                               "torch at the end": True})
    page = (tmp_path / "report.html").read_text()
    assert re.findall(r"<h2>([^<]+)</h2>", page)[2].startswith("Worst cases: the 3 most severe")
