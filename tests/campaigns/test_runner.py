import dataclasses

import numpy as np
import pytest

from vbl_robust.campaigns.runner import plan, run_campaign
from vbl_robust.constants import FAILURE_REASONS, NotMeasured, Verdict
from vbl_robust.data.sample import Sample
from vbl_robust.detect.shipped import DetectorSpec
from vbl_robust.specs.budget import Budget
from vbl_robust.specs.campaign import Block, CampaignSpec, roll_box
from vbl_robust.specs.kinds import JobStatus, RunStatus
from vbl_robust.store.core import ResultStore


def small_spec(name="t", methods=("georobust", "random"), **kw):
    blk = Block(boxes=(roll_box(10),), methods=methods, budgets=(Budget(max_evals=12),))
    return CampaignSpec(name, (blk,), seed=1, **kw)


def test_local_run_records_rows_and_a_rerun_skips_them(tmp_path, small_samples, oracle):
    samples = small_samples[:3]
    events = []
    with ResultStore(tmp_path / "r.sqlite") as st:
        s1 = run_campaign(small_spec(), samples, st, detector=oracle, progress=events.append,
                          dataset_source={"kind": "test"}, config={"x": 1})
        rows = st.jobs(with_points=True)
        s2 = run_campaign(small_spec(), samples, st, detector=oracle)
        runs = st.runs()
        assert st.count() == 6
    assert (s1.total, s1.done, s1.skipped, s1.status) == (6, 6, 0, "finished")
    assert (s2.done, s2.skipped, s2.status) == (0, 6, "finished")
    assert [e.done for e in events] == list(range(7)) and events[-1].total == 6
    assert {r.key for r in rows} == {j.key for j in plan(small_spec(), samples, oracle)}
    for r in rows:
        assert r.status == "done" and 1 <= r.nfev <= 12 and len(r.points) == r.nfev
        assert r.worst_m == pytest.approx(max(r.points.fs))
        assert r.verdict == ("breach" if r.worst_m > 1000 else "no breach found")
        assert r.trace and r.trace[-1].nfev == r.nfev
        assert set(r.worst_x) == {"roll_deg"} and abs(r.worst_x["roll_deg"]) <= 10
        assert r.payload["worst"]["error_m"] is None or r.payload["worst"]["error_m"] == pytest.approx(r.worst_m)
        # every evaluation carries its failure reason (the oracle fails outside the image): counted, not re-derived
        assert r.n_failed == sum(map(bool, r.points.reasons)) and sum(r.failures.values()) == r.n_failed
        assert set(r.failures) <= set(FAILURE_REASONS)
        i = int(np.argmax(r.points.fs))
        assert r.worst_reason == r.points.reasons[i]
    assert [r.status for r in runs] == [RunStatus.FINISHED, RunStatus.FINISHED]
    assert runs[0].provenance.dataset["source"] == {"kind": "test"} and runs[0].provenance.config["user"] == {"x": 1}
    from importlib.metadata import version

    libraries = runs[0].provenance.config["libraries"]  # the versions that can move a result's last digits
    assert libraries["torch"] == version("torch") and libraries["opencv-python"] == version("opencv-python")
    assert runs[0].provenance.code_version and runs[1].provenance.jobs_skipped == 6


def test_same_seed_same_results(tmp_path, small_samples, oracle):
    out = []
    for d in ("a", "b"):
        with ResultStore(tmp_path / d / "r.sqlite") as st:
            run_campaign(small_spec(), small_samples[:2], st, detector=oracle)
            out.append([(r.key, r.worst_m, r.nfev) for r in st.jobs(with_trace=False)])
    assert out[0] == out[1]


def test_unreadable_image_is_not_measured_and_the_campaign_goes_on(tmp_path, small_samples, oracle):
    good = small_samples[0]
    bad = dataclasses.replace(small_samples[1], id="missing", image_path=tmp_path / "nope.png", _image=None, _loader=None)
    assert isinstance(bad, Sample)
    with ResultStore(tmp_path / "r.sqlite") as st:
        # checked before the first job: refused in one line, nothing stored
        with pytest.raises(ValueError, match=r"^input unavailable: 1 of 2 image\(s\) cannot be used: .*nope.png: "
                                             r"image file not found"):
            run_campaign(small_spec(), [bad, good], st, detector=oracle)
        assert st.campaign() is None and st.count() == 0
        # an image lost during the run (here: the check skipped) is not measured, the campaign goes on
        s = run_campaign(small_spec(), [bad, good], st, detector=oracle, precheck=False)
        rows = st.jobs()
    assert s.not_measured == 2 and s.status == "finished"
    failed = [r for r in rows if r.sample_id == "missing"]
    assert {r.status for r in failed} == {JobStatus.NOT_MEASURED}
    assert {r.verdict for r in failed} == {Verdict.NOT_MEASURED}
    # no worst error (never the 5000 m penalty), the typed reason, and no absolute path in what a user reads
    assert all(r.worst_m is None and r.not_measured is NotMeasured.INPUT_UNAVAILABLE for r in failed)
    assert all(r.reason.startswith("input unavailable: missing: image file not found") and str(tmp_path) not in r.reason
               for r in failed)
    assert {r.status for r in rows if r.sample_id != "missing"} == {"done"}

    # the image comes back: a plain rerun skips the failed jobs, --retry-failed runs them (and only them) again
    from PIL import Image

    Image.fromarray(good.image).save(tmp_path / "nope.png")
    with ResultStore(tmp_path / "r.sqlite") as st:
        # a retry with other settings is refused before anything is forgotten (issue 48 item 7)
        with pytest.raises(ValueError, match="other settings"):
            run_campaign(small_spec(methods=("random",)), [bad, good], st, detector=oracle, retry_failed=True,
                         precheck=False)
        assert sum(r.status is JobStatus.NOT_MEASURED for r in st.jobs()) == 2
        assert run_campaign(small_spec(), [bad, good], st, detector=oracle).done == 0
        again = run_campaign(small_spec(), [bad, good], st, detector=oracle, retry_failed=True)
        rows = st.jobs()
    assert again.done == 2 and again.not_measured == 0 and again.skipped == 2
    assert {r.status for r in rows} == {"done"} and len(rows) == 4


def test_pipeline_exception_is_recorded_with_its_reason(tmp_path, small_samples):
    det = DetectorSpec("factory", "campaign_helpers:BrokenDetector")
    with ResultStore(tmp_path / "r.sqlite") as st:
        s = run_campaign(small_spec(methods=("random",)), small_samples[:2], st, detector=det)
        rows = st.jobs()
    assert s.not_measured == 2 and len(rows) == 2
    assert all(r.status is JobStatus.NOT_MEASURED and r.reason == "detector error: RuntimeError: detector exploded"
               for r in rows)


def test_chain_stops_at_the_first_breach_and_records_implied_rows(tmp_path, small_samples):
    # a detector 40 px off: every image breaches at the smallest box already
    det = DetectorSpec("oracle", options={"noise_px": 40.0})
    blk = Block(boxes=(roll_box(5), roll_box(10), roll_box(20)), methods=("random",), budgets=(Budget(max_evals=8),),
                chain=True)
    with ResultStore(tmp_path / "r.sqlite") as st:
        run_campaign(CampaignSpec("chain", (blk,)), small_samples[:2], st, detector=det)
        rows = st.jobs(with_trace=False)
    assert len(rows) == 6
    for sid in {r.sample_id for r in rows}:
        mine = sorted((r for r in rows if r.sample_id == sid), key=lambda r: r.box_level)
        assert [r.status for r in mine] == ["done", "implied", "implied"]
        assert all(r.verdict is Verdict.BREACH for r in mine)
        assert mine[1].nfev == 0 and mine[1].worst_m == mine[0].worst_m and mine[1].worst_x == mine[0].worst_x


def test_store_refuses_another_campaign(tmp_path, small_samples, oracle):
    with ResultStore(tmp_path / "r.sqlite") as st:
        run_campaign(small_spec(methods=("random",)), small_samples[:1], st, detector=oracle)
        with pytest.raises(ValueError, match="other settings"):
            run_campaign(small_spec(methods=("random",)).with_settings(eps_safe_m=10.0), small_samples[:1], st, detector=oracle)
        with pytest.raises(ValueError, match="executor"):
            run_campaign(small_spec(methods=("random",)), small_samples[:1], st, detector=oracle, executor="gpu")


def test_a_run_that_fails_before_its_first_job_does_not_bind_the_store(tmp_path, small_samples, oracle):
    # issue 12, item 8: a refused model must not lock the run directory to itself
    refused = DetectorSpec("factory", "campaign_helpers:RefusedDetector")
    with ResultStore(tmp_path / "r.sqlite") as st:
        with pytest.raises(ValueError, match="refused model"):
            run_campaign(small_spec(), small_samples[:2], st, detector=refused)
        assert st.count() == 0
        s = run_campaign(small_spec(methods=("random",)), small_samples[:1], st, detector=oracle)  # other settings too
        assert s.done == 1 and set(st.samples()) == {small_samples[0].id}
        assert st.campaign().detector["kind"] == "oracle"
        with pytest.raises(ValueError, match="holds results of detector"):  # now bound: a job row was computed
            run_campaign(small_spec(methods=("random",)), small_samples[:1], st, detector=refused)


def test_worker_processes_give_the_rows_of_one_process(tmp_path, small_samples, oracle):
    """workers=2 (two spawned processes, this process the only writer) stores the same results as workers=1,
    and the worker count is in the run's provenance."""
    samples = small_samples[:3]
    spec = small_spec(methods=("georobust", "random", "apgd"))
    got = {}
    for workers in (1, 2):
        with ResultStore(tmp_path / str(workers) / "r.sqlite") as st:
            s = run_campaign(spec, samples, st, detector=oracle, workers=workers)
            assert (s.total, s.done, s.status) == (9, 9, "finished")
            got[workers] = {r.key: (r.nfev, r.nit, r.verdict, r.worst_x, r.worst_m, tuple(r.points.fs))
                            for r in st.jobs(with_points=True)}
            assert st.runs()[0].provenance.config["workers"] == workers
    assert got[1] == got[2]


def test_bad_worker_count_is_refused(tmp_path, small_samples, oracle):
    with ResultStore(tmp_path / "r.sqlite") as st, pytest.raises(ValueError, match="workers must be an integer >= 1"):
        run_campaign(small_spec(), small_samples[:1], st, detector=oracle, workers=0)


def test_one_writer_per_store(tmp_path, small_samples, oracle):
    """A second run on a store that another process is writing is refused with the writer's PID, not mixed in."""
    import os

    from vbl_robust.store.lock import WriterLock

    with ResultStore(tmp_path / "r.sqlite") as st:
        with WriterLock(st.path):  # another writer (a lock taken on its own file descriptor)
            with pytest.raises(ValueError, match=f"in use by PID {os.getpid()}"):
                run_campaign(small_spec(), small_samples[:1], st, detector=oracle)
            assert st.count() == 0 and st.runs() == []
        s = run_campaign(small_spec(), small_samples[:1], st, detector=oracle)  # free again
        assert s.status == "finished" and st.count() == 2


def test_changed_pixels_are_refused_not_reused(tmp_path, small_samples, oracle):
    """The store identifies an image file by its bytes too: after the file changes, a rerun names the sample
    instead of reusing results computed on the old pixels; rewriting the same bytes is not a change."""
    import os

    from PIL import Image

    path = tmp_path / "img.png"
    Image.fromarray(small_samples[0].image).save(path)
    on_file = dataclasses.replace(small_samples[0], id="on_file", image_path=path, _image=None, _loader=None)
    spec = small_spec(methods=("random",))
    with ResultStore(tmp_path / "r.sqlite") as st:
        assert run_campaign(spec, [on_file], st, detector=oracle).done == 1
        Image.fromarray(small_samples[0].image).save(path)  # the same pixels, a new mtime
        os.utime(path, ns=(1, 1))
        assert run_campaign(spec, [on_file], st, detector=oracle).skipped == 1
        Image.fromarray(small_samples[1].image).save(path)  # other pixels
        with pytest.raises(ValueError, match=r"pixels of 1 sample\(s\) changed .*on_file"):
            run_campaign(spec, [on_file], st, detector=oracle)
        # other bytes with the stored size and mtime (what cp -p, tar x, rsync -a keep): still refused (issue 48 item 6)
        Image.fromarray(small_samples[0].image).save(path)
        data = bytearray(path.read_bytes())
        data[-20] ^= 0xFF  # the same length, other bytes
        path.write_bytes(bytes(data))
        stored_mtime = next(iter(st._con.execute("SELECT mtime_ns, size FROM contents")))
        os.utime(path, ns=(stored_mtime[0], stored_mtime[0]))
        assert (path.stat().st_size, path.stat().st_mtime_ns) == (stored_mtime[1], stored_mtime[0])
        with pytest.raises(ValueError, match=r"pixels of 1 sample\(s\) changed .*on_file"):
            run_campaign(spec, [on_file], st, detector=oracle)
        assert st.count() == 1


def test_deleting_the_lock_file_does_not_let_a_second_writer_in(tmp_path):
    """Issue 48 item 8: the writer also holds a lock on the store file, so a lock file deleted during a run (and
    created anew by the second writer) does not make a second, free lock."""
    import os

    from vbl_robust.store.lock import WriterLock

    store = tmp_path / "results.sqlite"
    with WriterLock(store):
        os.unlink(f"{store}.lock")
        with pytest.raises(ValueError, match="in use by"):
            WriterLock(store).acquire()
    WriterLock(store).acquire().release()  # free once the first writer has let go


def test_a_worker_computes_on_one_core():
    """torch and OpenCV each on one thread in a worker (OpenCV's warps make the black-box views since issue 50: left
    at its default, every worker would spread over every core)."""
    import cv2
    import torch

    from vbl_robust.campaigns.work import one_core

    before = torch.get_num_threads(), cv2.getNumThreads()
    try:
        cv2.setNumThreads(2)
        one_core()
        assert (torch.get_num_threads(), cv2.getNumThreads()) == (1, 1)
    finally:
        torch.set_num_threads(before[0])
        cv2.setNumThreads(before[1])
