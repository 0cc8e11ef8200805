#!/usr/bin/env bash
# Issue 16 measurement: sustained-breach survival vs per-frame survival on the same approach frames and box.
# 10 generated sequences x 20 frames at 1 Hz (seed 7), shipped detector, roll ±10°, GeoRobust, 24 evaluations
# per sequence / image, early stop at the first breach. One torch thread. Each audit resumes when rerun.
#   bash benchmarks/measure_sequences.sh            (≈ 1 h on one core of this 2-core CPU)
set -euo pipefail
export OMP_NUM_THREADS=1 YOLO_OFFLINE=1 YOLO_VERBOSE=False MPLBACKEND=Agg
VR=${VR:-.venv/bin/vbl-robust}
DATA=${DATA:-data/seq10}
[ -f "$DATA/metadata.csv" ] || $VR scenes --sequences 10 --frames 20 --rate 1 --seed 7 --out "$DATA"
COMMON=(--roll 10 --methods georobust --max-evals 24 --quiet)
for k in 1 5; do
  $VR audit --sequences "$DATA" --sustain "$k" "${COMMON[@]}" --out "runs/seq_sustain$k"
done
$VR audit --lard "$DATA" --n 200 "${COMMON[@]}" --out runs/seq_frames --no-report
