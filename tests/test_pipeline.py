import math

import cv2
import numpy as np
import pytest
import torch

from vbl_robust.constants import NotMeasured, NotMeasuredError
from vbl_robust.data.sample import Sample
from vbl_robust.detect.base import Detections
from vbl_robust.detect.oracle import OracleDetector
from vbl_robust.geometry.camera import intrinsics, lard_rotation, project, runway_corners
from vbl_robust.perturb.resample import PixelScale, resize_image
from vbl_robust.pipeline import FAILURE_REASONS, EvalRecord, Objective
from vbl_robust.space import ParameterBox

BOX = ParameterBox({"roll_deg": (-30, 30), "contrast": (0.4, 2.5)})

#: (name, horizontal distance m, lateral offset m, yaw offset deg, aeronautical pitch deg, roll deg)
POSES = [
    ("close", 700.0, 12.0, 6.0, -4.0, 9.0),
    ("medium", 2600.0, -60.0, -10.0, -2.0, -14.0),
    ("far", 6500.0, 150.0, 15.0, 1.0, 25.0),
]


def make_sample(distance_m, lateral_m, yaw_deg, pitch_deg, roll_deg, *, sid="s", size=(1024, 1024), seed=0):
    """A LARD-like sample: 3° glide path, 3000 × 45 m runway drawn on smooth noise, exact float labels."""
    w, h = size
    K = intrinsics(w, h, 60.0)
    C = np.array([-distance_m, lateral_m, math.tan(math.radians(3.0)) * (distance_m + 305.0)])
    R = lard_rotation(yaw_deg, 90.0 + pitch_deg, roll_deg, 0.0)
    corners = runway_corners(3000.0, 45.0)
    c2 = project(corners, R, C, K)
    rng = np.random.default_rng(seed)
    img = cv2.GaussianBlur(rng.random((h // 4, w // 4, 3)).astype(np.float32), (0, 0), 1.0)
    img = cv2.resize(0.3 + 0.4 * img, (w, h), interpolation=cv2.INTER_LINEAR)
    cv2.fillPoly(img, [np.round(c2 * 16).astype(np.int32)], (0.15, 0.15, 0.17), lineType=cv2.LINE_AA, shift=4)
    s = Sample(sid, K, corners, c2, C, w, h, R=R)
    s.image = np.round(img * 255).astype(np.uint8)
    return s


@pytest.fixture(scope="module")
def samples():
    return [make_sample(*p[1:], sid=p[0], seed=i) for i, p in enumerate(POSES)]


def grid(n_roll=13, contrasts=(0.4, 1.0, 2.5)):
    r, c = np.meshgrid(np.linspace(-30.0, 30.0, n_roll), contrasts, indexing="ij")
    return np.stack([r.ravel(), c.ravel()], axis=1)


# -- the key property ------------------------------------------------------------------------------------------
def test_oracle_ippe_lm_is_roll_and_contrast_invariant(samples):
    """Camera roll about the optical axis does not move the camera: L < 1e-6 m over roll ±30°, contrast [0.4, 2.5]
    (PnP on exact corners is exact to float precision)."""
    theta = grid()
    for s in samples:
        rec = Objective(s, OracleDetector(), BOX, pnp="ippe_lm").evaluate(theta)
        assert not rec.failed.any(), (s.id, set(rec.reason))
        assert rec.loss.max() < 1e-6, (s.id, rec.loss.max())


def test_oracle_on_generated_scenes_of_every_envelope():
    from vbl_robust.scenes.generate import generate

    theta = grid(n_roll=5)
    for env in ("close", "medium", "far"):
        for s in generate(1, seed=7, width=512, height=512, envelopes=(env,)):
            assert Objective(s, OracleDetector(), BOX)(theta).values.max() < 1e-6, (env, s.id)


def test_iterative_is_never_better_than_ippe_lm(samples):
    """ITERATIVE without a start (the paper's solver) can fall into wrong minima; ippe_lm is the reference."""
    theta = grid(n_roll=7, contrasts=(1.0,))
    for s in samples:
        lm = Objective(s, OracleDetector(), BOX, pnp="ippe_lm")(theta).values
        it = Objective(s, OracleDetector(), BOX, pnp="iterative")(theta).values
        assert np.all(it >= lm - 1e-3)


# -- failures ---------------------------------------------------------------------------------------------------
class StubDetector:
    """A scripted detector: fixed keypoints/confidence per call, for failure paths."""

    input_size = None

    def __init__(self, keypoints, conf=0.9, *, empty=False):
        self.keypoints, self.conf, self.empty = np.asarray(keypoints, float), conf, empty
        self.calls = []

    def detect(self, context):
        self.calls.append(tuple(context.frames().shape))
        if self.empty:
            return [Detections.empty() for _ in range(len(context))]
        return [Detections(np.zeros((1, 4)), [self.conf], self.keypoints[None]) for _ in range(len(context))]


def test_every_failure_is_penalised_with_its_reason(samples):
    s = samples[1]
    theta = np.array([[0.0, 1.0], [5.0, 1.2]])
    collinear = np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [3.0, 3.0]])
    cases = {
        "no_detection": StubDetector(s.corners_2d, empty=True),
        "low_confidence": StubDetector(s.corners_2d, conf=0.2),
        "non_finite_keypoints": StubDetector(np.full((4, 2), np.nan)),
        "pnp_failed": StubDetector(collinear),
    }
    for reason, det in cases.items():
        rec = Objective(s, det, BOX).evaluate(theta)
        assert rec.reason == (reason, reason) and rec.failed.all()
        np.testing.assert_array_equal(rec.loss, [5000.0, 5000.0])
        assert np.isnan(rec.error_m).all()
    assert set(FAILURE_REASONS) >= set(cases)
    assert Objective(s, StubDetector(s.corners_2d, conf=0.2), BOX, conf_threshold=0.1)(theta).values.max() < 1.0
    assert Objective(s, StubDetector(s.corners_2d, empty=True), BOX, penalty_m=123.0)(theta).values.tolist() == [123.0, 123.0]


def test_a_search_for_misleading_poses_counts_flagged_failures_as_safe(samples):
    """--target misleading: a failure the system sees (here no detection) evaluates to 0 m with its reason kept, so a
    search maximises only the confident poses' errors; the audit spec carries that penalty and says so."""
    from vbl_robust.campaigns.audit import audit_spec
    from vbl_robust.constants import TARGETS
    from vbl_robust.specs.budget import Budget
    from vbl_robust.specs.campaign import BoxSpec

    s, theta = samples[1], np.array([[0.0, 1.0], [5.0, 1.2]])
    ev = Objective(s, StubDetector(s.corners_2d, empty=True), BOX, penalty_m=TARGETS["misleading"])(theta)
    assert ev.values.tolist() == [0.0, 0.0] and ev.reasons == ("no_detection", "no_detection")
    spec = audit_spec(BoxSpec(BOX, "b", 1.0), methods=("random",), budget=Budget(max_evals=4), target="misleading")
    assert spec.settings.penalty_m == 0.0 and "misleading poses only" in spec.notes
    assert audit_spec(BoxSpec(BOX, "b", 1.0), methods=("random",), budget=Budget(max_evals=4)).settings.penalty_m == 5000.0
    with pytest.raises(ValueError, match="--target must be one of any, misleading"):
        audit_spec(BoxSpec(BOX, "b", 1.0), methods=("random",), budget=Budget(max_evals=4), target="flagged")
    with pytest.raises(ValueError, match="penalty_m must be finite and >= 0"):
        Objective(s, StubDetector(s.corners_2d), BOX, penalty_m=-1.0)


def test_oracle_fail_outside_penalises_only_the_rows_that_lose_a_corner():
    s = make_sample(900.0, 5.0, -20.0, -3.0, 0.0, sid="edge", size=(320, 192))  # 90° roll: a corner leaves
    theta = np.array([[0.0, 1.0], [90.0, 1.0]])
    rec = Objective(s, OracleDetector(fail_outside=True), ParameterBox({"roll_deg": (-90, 90), "contrast": (0.5, 2)}))
    r = rec.evaluate(theta)
    assert r.reason == ("", "no_detection") and r.loss[1] == 5000.0 and r.loss[0] < 1e-6


def test_unloadable_pixels_are_not_measured_never_a_penalty(tmp_path):
    """Pixels that cannot be loaded are the tool's failure, not the pipeline's: no value is scored (not the 5000 m
    penalty), both paths raise NotMeasuredError (INPUT_UNAVAILABLE), and the message names the sample, not the
    absolute path."""
    s = make_sample(*POSES[0][1:], size=(128, 128))
    broken = Sample("runway/nope.png", s.K, s.corners_3d, s.corners_2d, s.position, 128, 128, R=s.R,
                    image_path=tmp_path / "runway" / "nope.png")
    obj = Objective(broken, OracleDetector(), BOX)
    with pytest.raises(NotMeasuredError, match=r"^runway/nope.png: image file not found$") as e:
        obj.evaluate(np.array([[0.0, 1.0], [3.0, 0.5]]))
    assert e.value.reason is NotMeasured.INPUT_UNAVAILABLE and str(tmp_path) not in obj.image_error
    theta = torch.tensor([[0.0, 1.0]], dtype=torch.float64, requires_grad=True)
    with pytest.raises(NotMeasuredError):
        obj(theta)
    assert "image_unavailable" not in FAILURE_REASONS  # no evaluation of the pipeline carries it


def test_user_errors_are_value_errors_at_construction(samples):
    s = samples[0]
    with pytest.raises(ValueError, match="unknown parameter 'fog'; known perturbations: roll_deg, pitch_deg, "):
        Objective(s, OracleDetector(), ParameterBox({"fog": (0.5, 1.5)}))
    with pytest.raises(ValueError, match="pnp='epnp'"):
        Objective(s, OracleDetector(), BOX, pnp="epnp")
    with pytest.raises(ValueError, match="batch_size"):
        Objective(s, OracleDetector(), BOX, batch_size=0)
    with pytest.raises(ValueError, match="penalty_m"):
        Objective(s, OracleDetector(), BOX, penalty_m=float("nan"))
    with pytest.raises(ValueError, match="conf_threshold"):
        Objective(s, OracleDetector(), BOX, conf_threshold=2.0)
    with pytest.raises(ValueError, match="resolution"):
        Objective(s, OracleDetector(), BOX, resolution="half")
    with pytest.raises(ValueError, match="no detect"):
        Objective(s, object(), BOX)
    with pytest.raises(ValueError, match="box must be"):
        Objective(s, OracleDetector(), {"roll_deg": (-1, 1)})
    obj = Objective(s, OracleDetector(), BOX)
    with pytest.raises(ValueError, match=r"theta must have shape \(N, 2\)"):
        obj(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="not differentiable"):
        Objective(s, StubDetector(s.corners_2d), BOX)(torch.zeros(1, 2))


# -- batching, resolution, records --------------------------------------------------------------------------------
def test_user_detectors_with_tensor_containers(samples):
    """A user's detector declares its capabilities and may return tensors in its own container type."""
    s = samples[1]

    class Candidates:  # duck-typed: conf and keypoints as tensors
        def __init__(self, kp):
            self.conf, self.keypoints = torch.tensor([0.1, 0.8]), torch.stack([kp + 50.0, kp])

        def __len__(self):
            return 2

    class Plain:
        differentiable = True

        def detect(self, context):
            return [Candidates(torch.from_numpy(s.corners_2d)) for _ in range(len(context))]

        def detect_top(self, context):
            n = len(context)
            return torch.full((n,), 0.8), torch.from_numpy(s.corners_2d).expand(n, 4, 2)

    obj = Objective(s, Plain(), BOX)
    theta = np.array([[0.0, 1.0], [0.0, 2.0]])
    assert obj(theta).values.max() < 1e-3 and obj(torch.tensor(theta)).values.max() < 1e-3


def test_chunks_bound_the_detector_batch_and_do_not_change_results(samples):
    s = samples[0]
    theta = grid(n_roll=5)
    det = StubDetector(s.corners_2d)
    a = Objective(s, det, BOX, batch_size=4).evaluate(theta)
    assert [c[0] for c in det.calls] == [4, 4, 4, 3] and all(c[1:] == (3, 1024, 1024) for c in det.calls)
    b = Objective(s, StubDetector(s.corners_2d), BOX, batch_size=64).evaluate(theta)
    np.testing.assert_array_equal(a.loss, b.loss)
    assert a.theta.shape == (15, 2) and len(a.to_rows()) == 15 and a.to_rows()[3]["roll_deg"] == theta[3, 0]
    assert EvalRecord.concat([a, b]).loss.shape == (30,)
    assert Objective(s, det, BOX)(np.zeros((0, 2))).values.shape == (0,)


class RecordingOracle(OracleDetector):
    """Oracle with an input resolution that keeps the images it is given."""

    uses_pixels = True

    def __init__(self, input_size):
        super().__init__()
        self.input_size = input_size
        self.images = []

    def detect(self, context):
        self.images.append(context.frames())
        return super().detect(context)


def test_perturbing_at_the_detector_resolution(samples):
    s = samples[2]
    theta = np.array([[-17.0, 0.7], [23.0, 2.1]])
    det = RecordingOracle(256)
    obj = Objective(s, det, BOX)
    rec = obj.evaluate(theta)
    assert det.images[0].shape == (2, 3, 256, 256) and obj.scale == PixelScale(0.25, 0.25)
    full = Objective(s, OracleDetector(), BOX).evaluate(theta)
    np.testing.assert_allclose(rec.keypoints, full.keypoints, atol=1e-9)  # mapped back to the sample's pixels
    assert rec.loss.max() < 1e-3
    # the detector sees the sample resized first, then perturbed about the mapped principal point
    expected = obj.perturbation.images(resize_image(s.image.astype(np.float32) / 255, (256, 256)), theta,
                                       center=obj.scale.to_scaled(s.K[:2, 2]))
    np.testing.assert_allclose(det.images[0].permute(0, 2, 3, 1).numpy(), expected, atol=1e-6)
    assert Objective(s, RecordingOracle(256), BOX, resolution="full").scale.is_identity
    assert Objective(s, RecordingOracle(None), BOX, resolution=512).scale == PixelScale(0.5, 0.5)


# -- the differentiable path ---------------------------------------------------------------------------------------
def _fd_grad(f, theta, h):  # f returns Evaluations
    g = np.zeros_like(theta)
    for j in range(theta.shape[1]):
        e = np.zeros(theta.shape[1])
        e[j] = h[j]
        g[:, j] = (f(theta + e).values - f(theta - e).values) / (2 * h[j])
    return g


def test_torch_matches_numpy_and_finite_differences_with_a_noisy_oracle(samples):
    s = samples[1]
    det = OracleDetector(noise_px=1.5, seed=1)
    obj = Objective(s, det, BOX)
    theta = np.array([[-12.0, 0.8], [4.0, 1.0], [21.0, 2.0]])
    t = torch.tensor(theta, requires_grad=True)
    loss = obj(t).values
    np.testing.assert_allclose(loss.detach().numpy(), obj(theta).values, rtol=1e-7)
    assert loss.min() > 1.0  # the noise makes L non-trivial and roll-dependent
    loss.sum().backward()
    fd = _fd_grad(obj, theta, h=(1e-3, 1e-3))
    np.testing.assert_allclose(t.grad[:, 0].numpy(), fd[:, 0], rtol=1e-3)
    assert np.abs(t.grad[:, 0].numpy()).min() > 1e-2  # metres per degree: not trivially zero
    np.testing.assert_array_equal(t.grad[:, 1].numpy(), 0.0)  # the oracle ignores pixels: contrast has no effect


def test_exact_oracle_gradient_is_zero_for_roll(samples):
    obj = Objective(samples[0], OracleDetector(), BOX)
    t = torch.tensor([[-8.0, 1.3], [17.0, 0.6]], dtype=torch.float64, requires_grad=True)
    obj(t).values.sum().backward()
    assert torch.isfinite(t.grad).all() and t.grad.abs().max() < 1e-3


class ContrastBiasedOracle(OracleDetector):
    """Oracle whose keypoints drift with the image's standard deviation (so contrast matters, through pixels)."""

    GAIN_PX = 8.0
    uses_pixels = True

    def detect(self, context):
        dets = super().detect(context)
        images = context.frames()
        std = images.reshape(images.shape[0], -1).std(dim=1).numpy()
        return [Detections(d.boxes, d.conf, d.keypoints + self.GAIN_PX * sd) for d, sd in zip(dets, std, strict=True)]

    def detect_top(self, context):
        conf, kp = super().detect_top(context)
        images = context.frames()
        std = images.reshape(images.shape[0], -1).std(dim=1)
        return conf, kp + self.GAIN_PX * std.to(kp.dtype)[:, None, None]


def test_gradient_through_pixels_matches_finite_differences():
    s = make_sample(*POSES[1][1:], size=(256, 256), seed=3)
    obj = Objective(s, ContrastBiasedOracle(), BOX)
    theta = np.array([[-9.0, 0.7], [14.0, 1.6]])
    t = torch.tensor(theta, requires_grad=True)
    loss = obj(t).values
    np.testing.assert_allclose(loss.detach().numpy(), obj(theta).values, rtol=1e-5)  # kornia vs OpenCV warps (measured 4e-7)
    loss.sum().backward()
    fd = _fd_grad(obj, theta, h=(0.05, 0.005))
    assert np.abs(fd[:, 1]).min() > 0.3  # contrast now moves the keypoints, hence the position
    np.testing.assert_allclose(t.grad.numpy(), fd, rtol=5e-3, atol=1e-3)  # measured: within 1e-4 m/unit


def test_penalised_rows_have_zero_not_nan_gradients():
    s = make_sample(900.0, 5.0, -20.0, -3.0, 0.0, sid="edge", size=(320, 192))
    box = ParameterBox({"roll_deg": (-90, 90), "contrast": (0.5, 2)})
    obj = Objective(s, OracleDetector(fail_outside=True, noise_px=1.0), box)
    t = torch.tensor([[0.0, 1.0], [90.0, 1.0], [5.0, 1.2]], dtype=torch.float64, requires_grad=True)
    loss = obj(t).values
    assert loss[1].item() == 5000.0 and loss[0] < 5000 and loss[2] < 5000
    loss.sum().backward()
    assert torch.isfinite(t.grad).all() and t.grad[1].abs().max() == 0 and t.grad[[0, 2], 0].abs().min() > 0
    # every row penalised: backward still works and gives zeros
    t2 = torch.tensor([[90.0, 1.0]], dtype=torch.float64, requires_grad=True)
    obj(t2).values.sum().backward()
    assert t2.grad.abs().max() == 0


def test_pnp_failures_in_the_differentiable_path_do_not_leak_nan(samples):
    s = samples[0]
    collinear = torch.tensor([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [3.0, 3.0]], dtype=torch.float64)

    class HalfBroken(OracleDetector):
        def detect_top(self, context):
            conf, kp = super().detect_top(context)
            kp = torch.cat([kp[:1], collinear[None] + 0.0 * kp[1:2], kp[2:]])
            return conf, kp

    obj = Objective(s, HalfBroken(noise_px=1.0), BOX)
    t = torch.tensor([[3.0, 1.0], [6.0, 1.0], [-4.0, 1.0]], dtype=torch.float64, requires_grad=True)
    loss = obj(t).values
    assert loss[1].item() == 5000.0
    loss.sum().backward()
    assert torch.isfinite(t.grad).all() and t.grad[1].abs().max() == 0


def test_nfev_counts_rows(samples):
    obj = Objective(samples[0], OracleDetector(), BOX)
    obj(grid(n_roll=3, contrasts=(1.0,)))
    obj(torch.zeros(2, 2) + torch.tensor([0.0, 1.0]))
    assert obj.nfev == 5


def test_a_residual_monitor_turns_an_inconsistent_pose_into_a_flagged_failure(samples):
    """--monitor-residual: exact corners pass (residual ≈ 0); one corner moved 15 px off the rectangle's geometry
    gives a PnP residual above 2 px, which the monitor flags ("monitor_rejected", the penalty) instead of a pose."""
    s = samples[1]
    theta = np.array([[0.0, 1.0]])
    moved = s.corners_2d.copy()
    moved[0] += 15.0
    plain = Objective(s, StubDetector(moved), BOX).evaluate(theta)
    assert plain.reason == ("",) and plain.reproj_error_px[0] > 2.0
    watched = Objective(s, StubDetector(moved), BOX, max_reproj_px=2.0).evaluate(theta)
    assert watched.reason == ("monitor_rejected",) and watched.loss[0] == 5000.0 and np.isnan(watched.error_m[0])
    exact = Objective(s, StubDetector(s.corners_2d), BOX, max_reproj_px=2.0).evaluate(theta)
    assert exact.reason == ("",) and exact.reproj_error_px[0] < 0.01
    with pytest.raises(ValueError, match="max_reproj_px"):
        Objective(s, StubDetector(s.corners_2d), BOX, max_reproj_px=0.0)
