"""SequenceObjective on the oracle with injected failures (exact answers), every search method, the torch path,
and frame batching through a pixel detector."""

import numpy as np
import pytest
import torch

import vbl_robust as vr
from vbl_robust.detect.base import Detections
from vbl_robust.scenes.sequences import generate_sequences
from vbl_robust.search.api import METHODS, maximize
from vbl_robust.sequences.objective import SequenceObjective, nominal_theta

BOX = vr.ParameterBox({"roll_deg": (-15.0, 15.0), "contrast": (0.7, 1.4)})


@pytest.fixture(scope="module")
def sequence():
    return generate_sequences(1, 8, 10.0, seed=3, width=256, height=256)[0]


class FailingOracle(vr.OracleDetector):
    """The exact oracle, but no detection on the frames of ``fail`` while the roll is in their interval."""

    def __init__(self, fail: dict[str, tuple[float, float]], **kwargs):
        super().__init__(**kwargs)
        self.fail = fail

    def _failing(self, ctx) -> np.ndarray:
        roll = np.asarray(ctx.theta.detach() if isinstance(ctx.theta, torch.Tensor) else ctx.theta)[:, 0]
        lo, hi = self.fail.get(ctx.sample.id, (np.inf, -np.inf))
        return (roll >= lo) & (roll <= hi)

    def detect(self, context):
        dets = super().detect(context)
        return [Detections.empty() if f else d for d, f in zip(dets, self._failing(context), strict=True)]

    def detect_top(self, context):
        conf, kp = super().detect_top(context)
        return torch.where(torch.as_tensor(self._failing(context)), torch.zeros_like(conf), conf), kp


def _failing(sequence):
    ids = [s.id for s in sequence]
    # frames 2-4 lose the runway for roll in [5, 10]; frame 6 alone for roll in [-10, -5]
    return FailingOracle({ids[2]: (5.0, 10.0), ids[3]: (5.0, 10.0), ids[4]: (5.0, 10.0), ids[6]: (-10.0, -5.0)})


def test_injected_failures_give_the_exact_sustained_error_runs_and_distance(sequence):
    f3 = SequenceObjective(sequence, _failing(sequence), BOX, sustain=3)
    f1 = SequenceObjective(sequence, _failing(sequence), BOX, sustain=1)
    theta = np.array([[0.0, 1.0], [7.0, 1.2], [-7.0, 0.9], [12.0, 1.0]])
    rec = f3.evaluate(theta)
    assert rec.loss.shape == (8, 4)
    assert np.all(rec.loss[:, [0, 3]] < 1e-6)  # the exact oracle: no error without a failure
    assert rec.value[1] == 5000.0 and rec.window_start[1] == 2 and rec.reason[1] == "no_detection"
    assert rec.value[2] < 1.0 and rec.reason[2] == ""  # one bad frame is ridden out over 3 frames
    ev1 = f1(theta)
    assert ev1.values[2] == 5000.0 and ev1.reasons[2] == "no_detection"
    d = sequence.distances_m
    s = rec.summary(1)
    assert (s["sustained_m"], s["longest_run_frames"], s["longest_run_start"], s["breach_start_frame"]) == (
        5000.0, 3, 2, 2)
    assert s["breach_start_m"] == d[2] and s["first_breach_m"] == d[2] and s["failed_frames"] == 3
    assert s["longest_run_s"] == pytest.approx(0.2) and s["roll_deg"] == 7.0
    s = rec.summary(2)
    assert s["longest_run_frames"] == 1 and s["breach_start_m"] is None and s["first_breach_m"] == d[6]
    assert f3.evaluate(nominal_theta(BOX)).summary(0)["breached_frames"] == 0


def test_grid_search_finds_the_failure_interval(sequence):
    f = SequenceObjective(sequence, _failing(sequence), BOX, sustain=3)
    r = maximize(f, BOX, "grid", max_evals=62, counts=(31, 2))
    assert r.fun == 5000.0 and 5.0 <= r.x[0] <= 10.0
    assert r.failures.get("no_detection") == 6 * 2  # roll 5..10 at 1° spacing, two contrasts


@pytest.mark.parametrize("method", sorted(METHODS))
def test_every_search_method_runs_on_the_sequence_objective(sequence, method):
    f = SequenceObjective(sequence, _failing(sequence), BOX, sustain=3)
    r = maximize(f, BOX, method, max_evals=12, seed=1)
    assert r.nfev <= 12 and r.x is not None
    assert np.all(BOX.lower <= r.x) and np.all(r.x <= BOX.upper)
    assert f(r.x[None]).values[0] == pytest.approx(r.fun, rel=1e-9, abs=1e-9)


def test_torch_path_equals_the_black_box_and_its_gradient_is_the_setting_frame(sequence):
    det = vr.OracleDetector(noise_px=1.0, seed=2)  # fixed corner noise: a smooth error in roll
    f = SequenceObjective(sequence, det, BOX, sustain=3)
    theta = np.array([[4.0, 1.1], [-9.0, 0.8]])
    rec = f.evaluate(theta)
    x = torch.tensor(theta, requires_grad=True)
    ev = f(x)
    np.testing.assert_allclose(ev.values.detach().numpy(), rec.value, rtol=1e-6)
    assert ev.reasons == rec.reason
    (g,) = torch.autograd.grad(ev.values.sum(), x)
    for i in range(2):  # the frame that sets S_3: the window's minimum
        j = int(rec.window_start[i])
        frame = j + int(np.argmin(rec.loss[j:j + 3, i]))
        xi = torch.tensor(theta[i:i + 1], requires_grad=True)
        (gi,) = torch.autograd.grad(f.frames[frame](xi).values.sum(), xi)
        np.testing.assert_allclose(g[i].numpy(), gi[0].numpy(), rtol=1e-6, atol=1e-9)
    assert torch.all(torch.isfinite(g))


def test_failed_rows_have_zero_gradient(sequence):
    f = SequenceObjective(sequence, _failing(sequence), BOX, sustain=3)
    x = torch.tensor([[7.0, 1.0]], dtype=torch.float64, requires_grad=True)
    ev = f(x)
    (g,) = torch.autograd.grad(ev.values.sum(), x)
    # the differentiable path sees a zero confidence: low_confidence
    assert ev.values.item() == 5000.0 and ev.reasons == ("low_confidence",) and g.abs().max() == 0.0


class ProbeDetector:
    """A pixel detector without a network: fixed corners (in source pixels) shifted by the mean of the
    letterboxed view, which also sets the confidence."""

    input_size = 64
    uses_pixels = True
    differentiable = True

    def __init__(self, corners):
        self.calls = 0
        self.corners = torch.as_tensor(corners, dtype=torch.float64)

    def detect_top(self, context):
        self.calls += 1
        from vbl_robust.detect.windows import letterbox_window

        # as PoseDetector.letterbox: windows are made on the context's device (every sampler must say which)
        win = torch.tensor(letterbox_window(context.height, context.width), dtype=torch.float32,
                           device=context.device)
        m = context.views(win, 32).mean(dim=(1, 2, 3)).to(torch.float64)
        return 0.3 + 0.5 * m, self.corners[None] + 2.0 * m[:, None, None]

    def detect(self, context):
        with torch.no_grad():
            conf, kp = self.detect_top(context)
        return [Detections(torch.cat([k.min(0).values, k.max(0).values])[None], c[None], k[None])
                for c, k in zip(conf, kp, strict=True)]


def test_frames_are_batched_through_a_pixel_detector_with_the_same_results():
    seq = generate_sequences(1, 5, 5.0, seed=0, width=96, height=96)[0]
    theta = np.array([[0.0, 1.0], [5.0, 0.8], [-3.0, 1.3]])
    corners = seq[0].corners_2d * 64 / 96  # frame 0's corners, in the resized source: PnP finds frame 0's position
    batched, single = ProbeDetector(corners), ProbeDetector(corners)
    fb = SequenceObjective(seq, batched, BOX, sustain=2, batch_size=4)
    fs = SequenceObjective(seq, single, BOX, sustain=2, batch_size=4, batch_frames=False)
    assert fb.batched and not fs.batched
    assert not SequenceObjective(seq, vr.OracleDetector(), BOX).batched  # reads the sample: per frame
    rb, rs = fb.evaluate(theta), fs.evaluate(theta)
    assert (batched.calls, single.calls) == (4, 5)  # ceil(5 frames x 3 rows / 4) vs one call per frame
    np.testing.assert_allclose(rb.loss, rs.loss, rtol=1e-6)
    assert rb.reasons == rs.reasons and not any(r for f in rb.reasons for r in f)
    assert len(set(np.round(rb.loss[:, 0], 6))) == 5 and len(set(np.round(rb.loss[1], 6))) == 3
    xb, xs = (torch.tensor(theta, requires_grad=True) for _ in range(2))
    vb, vs = fb(xb).values, fs(xs).values
    np.testing.assert_allclose(vb.detach().numpy(), vs.detach().numpy(), rtol=1e-6)
    (gb,), (gs,) = torch.autograd.grad(vb.sum(), xb), torch.autograd.grad(vs.sum(), xs)
    np.testing.assert_allclose(gb.numpy(), gs.numpy(), rtol=1e-5, atol=1e-8)


def test_bad_arguments(sequence):
    with pytest.raises(ValueError, match="sustain: need an integer k with 1 <= k <= 8"):
        SequenceObjective(sequence, vr.OracleDetector(), BOX, sustain=9)
    with pytest.raises(ValueError, match="batch_frames must be True or False"):
        SequenceObjective(sequence, vr.OracleDetector(), BOX, batch_frames="yes")
    f = SequenceObjective(sequence, vr.OracleDetector(), BOX)
    with pytest.raises(ValueError, match=r"theta must have shape \(N, 2\)"):
        f(np.zeros((2, 3)))
    assert f(np.zeros((0, 2))).values.shape == (0,)
