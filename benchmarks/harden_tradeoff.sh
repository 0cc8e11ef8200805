#!/usr/bin/env bash
# Issue 29: the trade-off of each hardening try (each round's weights): nominal survival on the validation seeds
# paired with v9, against a quick roll screen on the before/after audit's 50 images (seed 0), paired with v9 too.
#
#   nominal  benchmarks/detector_protocol.py --split validation --compare v9 (2040 approaches, exact McNemar)
#   screen   reproduce spatial-1d --methods georobust-av --max-evals 30 --grid-step 1 (the roll boxes ±2…±30°, 30
#            evaluations per box and a 1° reference grid over ±30°): far fewer evaluations than the full before/after
#            audit (benchmarks/measure_harden.sh), so it finds fewer breaches — a ranking of the tries, not their
#            robustness figures. v9 is screened the same way.
# The tries (their training commands):
#   try1  vbl-robust harden --perturb roll_deg=-30,30 --rounds 2 --k 8 --epochs 2 --n-train 300 --n-val 60
#         --threads 1 --out train_runs/harden_roll30                        (benchmarks/measure_harden.sh)
#   try2  the same with --data shipped --threads 2 --out train_runs/harden_roll30_shipped
# Resumable (finished steps are skipped); run it alone on the machine: bash benchmarks/harden_tradeoff.sh
set -euo pipefail
export OMP_NUM_THREADS=1 YOLO_OFFLINE=1 YOLO_VERBOSE=False MPLBACKEND=Agg
VR=${VR:-.venv/bin/vbl-robust}
PY=${PY:-.venv/bin/python}
OUT=${OUT:-runs/harden/tradeoff}
mkdir -p "$OUT"
SCREEN=(spatial-1d --images 50 --methods georobust-av --max-evals 30 --grid-step 1 --workers 2 -q)
V9_PROTOCOL=results/detector_candidates/protocol_v9_validation.json

$VR reproduce "${SCREEN[@]}" --model default --out "$OUT/screen_v9"
for try in try2:train_runs/harden_roll30_shipped try1:train_runs/harden_roll30; do
  name=${try%%:*}; dir=${try#*:}
  for r in 1 0; do
    tag=${name}_r$r
    W=$($PY -c "import json, os, sys; print(os.path.abspath(json.load(open(sys.argv[1]))['weights']))" "$dir/round0$r/round.json")
    [ -f "$OUT/${tag}_validation.json" ] || (cd benchmarks && ../$PY detector_protocol.py --model "$W" --split validation \
      --json "../$OUT/${tag}_validation.json" --compare "../$V9_PROTOCOL") > "$OUT/${tag}_nominal.txt"
    $VR reproduce "${SCREEN[@]}" --model "$W" --trust-model --detector twostage --out "$OUT/screen_$tag"
    $VR report "$OUT/screen_v9" --format md --compare "$OUT/screen_$tag" > "$OUT/screen_${tag}_compare.md"
    echo "$tag: $(grep '^| pooled' "$OUT/${tag}_nominal.txt")"
    grep -E '^\| georobust-av \| ±(2|15|30)° \| all ' "$OUT/screen_${tag}_compare.md" || true
  done
done
