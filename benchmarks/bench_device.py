"""The pipeline on a GPU against the CPU: evaluations/s and agreement, or a plain statement that it was skipped.

When ``torch.cuda.is_available()``: the shipped model, single pass and two-stage, the objective at batch 32 and
256 on the CPU (``auto`` engine, one thread) and on ``cuda`` (torch engine; ONNX Runtime's CUDA provider when
installed too), evaluations/s, and the largest keypoint difference between the devices on the same θ (the
budget is 1e-2 px: cuDNN's convolutions are not bit-identical to oneDNN's) and the largest difference of L.
Without a GPU it says so and measures nothing.

``python benchmarks/bench_device.py [--quick]``
"""

from __future__ import annotations

import sys
import time

import numpy as np
import torch

KEYPOINT_BUDGET_PX = 1e-2


def _rate(fn, n: int, reps: int) -> float:
    fn()
    if torch.cuda.is_available():
        torch.cuda.synchronize()
    t = time.perf_counter()
    for _ in range(reps):
        fn()
    if torch.cuda.is_available():
        torch.cuda.synchronize()
    return n * reps / (time.perf_counter() - t)


def main(quick: bool = False) -> str:
    head = ["## Device: the pipeline on a GPU", ""]
    if not torch.cuda.is_available():
        return "\n".join([*head, "Skipped: no CUDA device on this machine (`torch.cuda.is_available()` is False); "
                          "nothing was measured. Run `python benchmarks/bench_device.py` where a GPU is present.", ""])
    from vbl_robust.detect.engines import installed_engines
    from vbl_robust.detect.offline import setup_offline
    from vbl_robust.detect.shipped import default_detector
    from vbl_robust.pipeline import Objective
    from vbl_robust.scenes.generate import generate
    from vbl_robust.space import ParameterBox

    setup_offline()
    torch.set_num_threads(1)
    reps = 2 if quick else 5
    sample = generate(1, seed=4)[0]
    box = ParameterBox({"roll_deg": (-10, 10), "contrast": (0.7, 1.3)})
    rng = np.random.default_rng(0)
    theta = {b: box.from_unit(rng.random((b, 2))) for b in (32, 256)}
    gpu = torch.cuda.get_device_name(0)
    configs = [("cpu", "auto"), ("cuda", "torch")]
    if "onnxruntime" in installed_engines():
        import onnxruntime as ort

        if "CUDAExecutionProvider" in ort.get_available_providers():
            configs.append(("cuda", "onnxruntime"))
    lines = [f"GPU: {gpu}. One CPU thread for the CPU rows.", "",
             "| design | device | engine | evals/s b32 | evals/s b256 | × CPU (b256) | max keypoint diff to CPU (px) | "
             "max |ΔL| to CPU (m) |", "|---|---|---|---:|---:|---:|---:|---:|"]
    worst = 0.0
    for design in ("single", "twostage"):
        ref_kp = ref_loss = cpu_rate = None
        for device, engine in configs:
            det = default_detector(design=design, engine=engine, device=device)
            obj = Objective(sample, det, box, batch_size=256, device=device)
            rates = [_rate(lambda obj=obj, t=t: obj(t), len(t), reps) for t in theta.values()]
            rec = obj.evaluate(theta[256])
            kp, loss = np.asarray(rec.keypoints, np.float64), np.asarray(rec.loss, np.float64)
            if device == "cpu":
                ref_kp, ref_loss, cpu_rate = kp, loss, rates[1]
                dkp = dl = 0.0
            else:
                dkp = float(np.nanmax(np.abs(kp - ref_kp)))
                dl = float(np.nanmax(np.abs(loss - ref_loss)))
                worst = max(worst, dkp)
            lines.append(f"| {design} | {device} | {engine} | {rates[0]:.1f} | {rates[1]:.1f} | "
                         f"{rates[1] / cpu_rate:.2f} | {dkp:.1e} | {dl:.2g} |")
    verdict = "within" if worst <= KEYPOINT_BUDGET_PX else "**outside**"
    lines += ["", f"Largest keypoint difference GPU vs CPU: {worst:.1e} px, {verdict} the {KEYPOINT_BUDGET_PX:g} px "
              "budget.", ""]
    return "\n".join([*head, *lines])


if __name__ == "__main__":
    print(main("--quick" in sys.argv))
