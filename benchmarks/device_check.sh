#!/usr/bin/env bash
# The GPU check as one short prepared script for a lent device machine (the workplace's `device` tool), ≈ 5 min
# there; --device cuda has never run on a GPU before it.
#
#   here, once (needs the package registry):  bash benchmarks/device_check.sh --fetch
#       downloads into .whl/ (kept out of git by .git/info/exclude) the wheels the device image lacks for Python
#       3.12: ultralytics, ultralytics-thop, kornia, kornia_rs, pymap3d, onnxslim (the image has torch, torchvision, opencv,
#       onnxruntime, scipy, typer, rich, matplotlib, pyarrow, pyyaml; polars, httpx and pynvml are not needed);
#   there:  device run: command "bash benchmarks/device_check.sh", carry [".whl"], timeout_s 540
#       installs them into /tmp/site, then (1) benchmarks/bench_device.py --quick: evaluations/s on the CPU and on
#       cuda, the largest keypoint and error differences between them; (2) the same small audit (2 images, roll
#       ±10° × contrast [0.7, 1.4], georobust / random / apgd, 40 evaluations each, no early stop) on cuda and on
#       the CPU (torch engine, one worker, wall clock), and whether their rows agree
#       (vbl_robust.paper.bundle.compare_runs). Logs and both stores come back in $OUT.
#   there, once the check passed:  device run: command "bash benchmarks/device_check.sh --paper 480", carry [".whl"]
#       resumes the paper run's experiments without time budgets (spatial-2d, distance-profile, convergence, then
#       spatial-1d: the ones the CPU run reaches last first) from the committed bundle on cuda, 12 workers, for
#       480 s, with the run's own CPU-process clock setting (part of the job keys), and sends each store back packed
#       ($OUT/<experiment>.sqlite.xz); here, with the CPU run stopped:
#       vbl-robust merge /work/.device/…/<experiment>.sqlite.xz --into runs/paper/<experiment>
#       (each run's provenance records its device and library versions).
set -uo pipefail
if [ "${1:-}" = "--fetch" ]; then
  grep -qx '/.whl/' .git/info/exclude 2>/dev/null || echo '/.whl/' >> .git/info/exclude
  PIP=${PIP:-.venv/bin/pip}
  plat=(--platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64)
  $PIP download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp "${plat[@]}" -d .whl \
    ultralytics==8.4.190 ultralytics-thop==2.2.3 kornia==0.9.0 kornia_rs==0.2.0 pymap3d==3.2.0 onnxslim==0.1.98 \
    && ls -l .whl
  exit
fi
OUT=${OUT:-/tmp/device_check}
VR=(python3 -c "from vbl_robust.cli import main; main()")
mkdir -p "$OUT"
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl \
  || exit 1
export PYTHONPATH=/tmp/site:$PWD/src PYTHONUNBUFFERED=1 YOLO_OFFLINE=1 YOLO_CONFIG_DIR=/tmp/yolo MPLBACKEND=Agg
export OMP_NUM_THREADS=1
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv | tee "$OUT/gpu.txt"
python3 -c "import torch, cv2; print('torch', torch.__version__, 'cuda', torch.cuda.is_available(), 'opencv', cv2.__version__)" \
  | tee -a "$OUT/gpu.txt"
if [ "${1:-}" = "--paper" ]; then
  end=$((SECONDS + ${2:-480}))
  for e in spatial-2d distance-profile convergence spatial-1d; do
    left=$((end - SECONDS)); [ "$left" -gt 30 ] || break
    timeout -s INT "$left" "${VR[@]}" reproduce "$e" --out "/tmp/paper/$e" --resume-from results/paper \
      --device cuda --clock process --workers "${WORKERS:-12}" --no-report -q 2>&1 | tail -3 | tee -a "$OUT/paper.txt"
    [ -f "/tmp/paper/$e/results.sqlite" ] && python3 -c "
import sys; from pathlib import Path
from vbl_robust.store.core import ResultStore
from vbl_robust.store.pack import pack_store
with ResultStore.open_existing(sys.argv[1]) as st: print(pack_store(st, Path(sys.argv[2])), st.count(), 'jobs')
" "/tmp/paper/$e" "$OUT/$e.sqlite.xz" | tee -a "$OUT/paper.txt"
  done
  exit
fi
timeout 240 python3 benchmarks/bench_device.py --quick 2>&1 | tee "$OUT/bench_device.txt"
AUDIT=(audit --model default --images 2 --roll 10 --contrast 0.7,1.4 --methods georobust,random,apgd --max-evals 40
       --no-early-stop --no-landscape --workers 1 --clock wall -q)
timeout 120 "${VR[@]}" "${AUDIT[@]}" --device cuda --out "$OUT/audit_cuda" 2>&1 | tee "$OUT/audit_cuda.txt"
timeout 150 "${VR[@]}" "${AUDIT[@]}" --engine torch --out "$OUT/audit_cpu" 2>&1 | tee "$OUT/audit_cpu.txt"
python3 -c "
from vbl_robust.paper.bundle import compare_runs
print('cuda rows against cpu rows:', compare_runs('$OUT/audit_cuda', '$OUT/audit_cpu'))" 2>&1 | tee "$OUT/agree.txt"
rm -f "$OUT"/audit_*/results.sqlite.lock
